#version 430 core
// The crack pass's inside target at every face texel: the value crack_bake.frag writes on a face
// with no crack depth (1).  The crack pass then overwrites the texels it measures; the other
// targets hold their clear, which is what crack_bake.frag writes for an empty list
// (crackbake/bake/raster.py).  A UV placement draws it as the class pass (the faces at the depth
// of their class, crack_bake.vert's CRACK_CLASS_Z), a camera's on a full-screen triangle.
layout(location = 0) out float o_inside;

void main() {
    o_inside = 1.0;
}
