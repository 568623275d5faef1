#version 430 core
// Decal placement of the first bake pass: each face is drawn through the projector's
// orthographic camera (u_projection: mesh -> clip, x = image right, y = image up, z -1 at the
// projector's near face .. +1 at its far face) instead of at its UVs; the depth test keeps the
// surface nearest to the projector and clipping drops what lies outside the box's depth range.
// The same band tiling and row order as crack_bake.vert: image row 0 is the top (clip y = +1).

in vec3 in_pos;    // world position, mesh units

uniform mat4 u_projection;  // mesh -> clip
uniform float u_res;        // full image size in texels (square)
uniform vec4 u_tile;        // band origin (x, y) and size (w, h), texels, image rows top-down

out vec3 v_world;

void main() {
    vec4 clip = u_projection * vec4(in_pos, 1.0);
    vec2 px = vec2(0.5 + 0.5 * clip.x, 0.5 - 0.5 * clip.y) * u_res;
    vec2 ndc = (px - u_tile.xy) / u_tile.zw * 2.0 - 1.0;
    v_world = in_pos;
    gl_Position = vec4(ndc, clip.z, 1.0);
}
