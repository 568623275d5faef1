#version 330 core
// Cracks that grow over time, for glTF viewers / WebGL2 (three.js ShaderMaterial, Babylon),
// from crackbake's packed data map (<stem>_data.png: R mask, G width, B depth, A time) and the
// glTF normal map (<stem>_normal.png, OpenGL +Y).  u_progress runs 0 -> 1: a texel cracks when
// the crack front passes its time value; u_feather softens the front.
in vec3 v_normal;
in vec4 v_tangent;
in vec2 v_uv;

uniform sampler2D u_surface;   // the asset's own base colour (sRGB), without the cracks
uniform sampler2D u_normal;    // <stem>_normal.png, linear
uniform sampler2D u_data;      // <stem>_data.png, linear (16-bit)
uniform float u_progress;      // 0 = intact, 1 = every crack fully open
uniform float u_feather;       // width of the growing front in time units, e.g. 0.02
uniform vec3 u_crack_color;    // linear colour inside the cracks
uniform vec3 u_light_dir;      // unit, towards the light, world space

out vec4 o_color;

// --- crack_grow: shared verbatim by crack_grow.frag and crack_grow.gdshader ---
// data: R mask, G width / width scale, B depth / depth scale, A time.  Returns how open the
// crack is at this texel (0..1): the mask where the front has passed, faded in at the front.
float crack_grow(vec4 data, float progress, float feather) {
    float grown = clamp((progress - data.a) / max(feather, 1e-4), 0.0, 1.0);
    return data.r * grown;
}
// --- end crack_grow ---

void main() {
    vec4 data = texture(u_data, v_uv);
    float open = crack_grow(data, u_progress, u_feather);
    float grown = data.r > 0.0 ? open / data.r : 0.0;
    // Tangent-space normal, blended from flat to the baked groove as the crack opens.
    vec3 tn = mix(vec3(0.0, 0.0, 1.0), texture(u_normal, v_uv).xyz * 2.0 - 1.0, grown);
    vec3 b = v_tangent.w * cross(v_normal, v_tangent.xyz);
    vec3 n = normalize(tn.x * v_tangent.xyz + tn.y * b + tn.z * v_normal);
    vec3 surface = pow(texture(u_surface, v_uv).rgb, vec3(2.2));
    vec3 albedo = mix(surface, u_crack_color, open);
    float light = 0.2 + 0.8 * max(dot(n, u_light_dir), 0.0);
    o_color = vec4(pow(albedo * light * (1.0 - 0.5 * data.b * grown), vec3(1.0 / 2.2)), 1.0);
}
