#version 430 core
// Decal check pass: records, per texel of the UV layout (crack_bake.vert places the faces), the
// surface point drawn there and its face, so crackbake/decals/apply.py can project a
// written decal back onto the mesh through its written transform.
in vec3 v_world;
layout(location = 0) out vec4 o_point;  // xyz world position, w = face + 1 (0 = no face)
void main() {
    o_point = vec4(v_world, float(gl_PrimitiveID + 1));
}
