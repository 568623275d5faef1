#version 430 core
// Stress bake: places each simulation triangle at its UV position in the current band (it lies
// inside one asset face, so its corners' UVs are that face's UVs at their barycentrics) and
// carries the asset's tangent frame and both fields' world stress tensors to the fragment
// shader (the initial field already carried onto the final mesh's nodes).
// Image convention as crack_bake.vert: row 0 is the top of the image (v = 1).

in vec2 in_uv;      // asset UV, v up
in vec3 in_t;       // asset tangent T (interpolated, not normalised)
in float in_w;      // bitangent sign w (+1 / -1)
in vec3 in_n;       // asset shading normal N (interpolated)
in vec3 in_sd0;     // initial field, world diagonal: xx, yy, zz (solver units)
in vec3 in_so0;     // initial field, world off-diagonal: xy, xz, yz
in float in_sep0;   // initial separation relative to the toughness
in vec3 in_sd;      // final field, the same
in vec3 in_so;
in float in_sep;

uniform float u_res;    // full image size in texels (square)
uniform vec4 u_tile;    // band origin (x, y) and size (w, h), texels, image rows top-down

out vec3 v_t;
out float v_w;
out vec3 v_n;
out vec3 v_sd0;
out vec3 v_so0;
out float v_sep0;
out vec3 v_sd;
out vec3 v_so;
out float v_sep;

void main() {
    vec2 px = vec2(in_uv.x, 1.0 - in_uv.y) * u_res;
    vec2 ndc = (px - u_tile.xy) / u_tile.zw * 2.0 - 1.0;
    v_t = in_t;
    v_w = in_w;
    v_n = in_n;
    v_sd0 = in_sd0;
    v_so0 = in_so0;
    v_sep0 = in_sep0;
    v_sd = in_sd;
    v_so = in_so;
    v_sep = in_sep;
    gl_Position = vec4(ndc, 0.0, 1.0);
}
