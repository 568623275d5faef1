#version 430 core
// One triangle covering the whole band: the second bake pass runs once per texel.
// At depth u_depth (NDC z): the depth test (crackbake/bake/raster.py) passes only where the
// surface pass left a nearer depth, i.e. on a face (1, the far plane), or on a face whose bin
// lists segments (0: crack_surface.frag's depth classes).
uniform float u_depth;

void main() {
    vec2 p = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));
    gl_Position = vec4(p * 2.0 - 1.0, u_depth, 1.0);
}
