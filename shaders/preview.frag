#version 430 core
// Two-light Lambert shading of the base colour; enough to judge where the cracks run.
in vec3 v_normal;
in vec2 v_uv;

uniform sampler2D u_color;   // sRGB base colour, v up (row 0 of the upload is v = 0)
uniform vec3 u_key;          // unit directions towards the lights, world space
uniform vec3 u_fill;

out vec4 o_color;

vec3 to_linear(vec3 c) { return pow(c, vec3(2.2)); }
vec3 to_srgb(vec3 c) { return pow(clamp(c, 0.0, 1.0), vec3(1.0 / 2.2)); }

void main() {
    vec3 n = normalize(v_normal);
    if (!gl_FrontFacing) n = -n;
    vec3 albedo = to_linear(texture(u_color, v_uv).rgb);
    float light = 0.15 + 0.75 * max(dot(n, u_key), 0.0) + 0.25 * max(dot(n, u_fill), 0.0);
    o_color = vec4(to_srgb(albedo * light), 1.0);
}
