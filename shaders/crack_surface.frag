#version 430 core
// First pass of a camera-placed bake (the decal bake; a UV placement measures in place,
// crackbake/bake/raster.py): records, per texel, the surface point of the face drawn there, its
// world footprint (the derivatives of the position across one texel) and the face's candidate
// bin (with the normal map, also the face index, from which the normal's compute pass
// interpolates the vertex normal and tangent at the texel's point only where a crack needs them).
// The second pass (crack_bake.frag) measures the cracks once per texel from these: measuring here
// would repeat the loop for every partly covered 2x2 quad of every small triangle.

// Each face's bin, face f at texel (f % 4096, f / 4096): a texture, as the crack pass's lists
// (crack_bake.frag: llvmpipe gathers texels for all lanes at once, buffer loads lane by lane).
layout(binding = 6) uniform usampler2D u_face_bin;

in vec3 v_world;

layout(location = 0) out vec4 o_point;   // xyz world position, w = bin (exact below 2^24)
layout(location = 1) out vec4 o_dpx;     // xyz d(world)/d(texel x), w = 1 on a face
layout(location = 2) out vec4 o_dpy;     // xyz d(world)/d(texel y), w = face (normal map only)

void main() {
    uint bin = texelFetch(u_face_bin, ivec2(gl_PrimitiveID & 4095, gl_PrimitiveID >> 12), 0).x;
    o_point = vec4(v_world, float(bin));
    o_dpx = vec4(dFdx(v_world), 1.0);
#ifdef CRACK_NORMALS
    o_dpy = vec4(dFdy(v_world), float(gl_PrimitiveID));  // exact below 2^24 faces
#else
    o_dpy = vec4(dFdy(v_world), 0.0);
#endif
}
