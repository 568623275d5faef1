#version 430 core
// Places each asset triangle at its UV position in the current tile; carries world position.
// Image convention: pixel row 0 is the top of the image (v = 1), and GL row 0 is what
// read_into returns first, so v is flipped here and no flip is needed after readback.

in vec2 in_uv;     // asset UV, v up
in vec3 in_pos;    // world position, mesh units
#ifdef CRACK_CLASS_Z
in float in_z;     // NDC depth (the bake's class pass: crackbake/bake/raster.py)
#endif

uniform float u_res;    // full image size in texels (square)
uniform vec4 u_tile;    // band origin (x, y) and size (w, h), texels, image rows top-down

out vec3 v_world;

void main() {
    vec2 px = vec2(in_uv.x, 1.0 - in_uv.y) * u_res;
    vec2 ndc = (px - u_tile.xy) / u_tile.zw * 2.0 - 1.0;
    v_world = in_pos;
#ifdef CRACK_CLASS_Z
    gl_Position = vec4(ndc, in_z, 1.0);
#else
    gl_Position = vec4(ndc, 0.0, 1.0);
#endif
}
