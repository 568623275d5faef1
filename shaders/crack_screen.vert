#version 430 core
// One triangle covering the whole band: the second bake pass runs once per texel.
void main() {
    vec2 p = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));
    // At the far plane: the depth test (crackbake/bake/raster.py) passes only where the surface
    // pass drew a face.
    gl_Position = vec4(p * 2.0 - 1.0, 1.0, 1.0);
}
