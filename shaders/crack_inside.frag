#version 430 core
// The crack pass's inside target at the texels on faces whose bin lists no segment: the value
// crack_bake.frag writes there (1: on a face, no crack depth).  The other targets hold their
// clear, which is what crack_bake.frag writes for an empty list (crackbake/bake/raster.py).
layout(location = 0) out float o_inside;

void main() {
    o_inside = 1.0;
}
