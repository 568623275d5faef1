#version 430 core
// First pass of a UV-placed bake (crackbake/bake/raster.py): marks every face texel inside and
// records in the depth buffer whether the face drawn there (the last one, as without a depth
// test) has a candidate bin listing any segment (0.25) or none (0.75).  The crack pass then
// draws the listed faces only, depth-tested against it, so each texel is measured once, by the
// face that owns it, and faces whose list is empty cost nothing more (their texels keep the
// targets' clear: what crack_bake.frag writes for an empty list).

// Each face's bin, face f at texel (f % 4096, f / 4096); per bin its list's first, end entry.
layout(binding = 6) uniform usampler2D u_face_bin;
layout(binding = 5) uniform usampler2D u_bins;

layout(location = 0) out float o_inside;

void main() {
    uint bin = texelFetch(u_face_bin, ivec2(gl_PrimitiveID & 4095, gl_PrimitiveID >> 12), 0).x;
    uvec2 list = texelFetch(u_bins, ivec2(int(bin) & 4095, int(bin) >> 12), 0).xy;
    gl_FragDepth = list.x < list.y ? 0.25 : 0.75;
    o_inside = 1.0;
}
