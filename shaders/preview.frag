#version 430 core
// Two-light Lambert shading of the base colour, the normal perturbed by the tangent-space map
// as engines decode it (MikkTSpace: T, N interpolated, not orthonormalised; B = w * N x T), so
// cracks read as grooves.
in vec3 v_normal;
in vec2 v_uv;
in vec4 v_tangent;

uniform sampler2D u_color;       // sRGB base colour, v up (row 0 of the upload is v = 0)
uniform sampler2D u_normal_map;  // tangent-space normal n * 0.5 + 0.5, OpenGL +Y
uniform int u_use_normal_map;
uniform vec3 u_key;              // unit directions towards the lights, world space
uniform vec3 u_fill;

out vec4 o_color;

vec3 to_linear(vec3 c) { return pow(c, vec3(2.2)); }
vec3 to_srgb(vec3 c) { return pow(clamp(c, 0.0, 1.0), vec3(1.0 / 2.2)); }

void main() {
    vec3 n = v_normal;
    if (u_use_normal_map != 0) {
        vec3 t = v_tangent.xyz;
        vec3 b = v_tangent.w * cross(v_normal, t);
        vec3 m = texture(u_normal_map, v_uv).xyz * 2.0 - 1.0;  // stored n * 0.5 + 0.5
        n = m.x * t + m.y * b + m.z * v_normal;
    }
    n = normalize(n);
    if (!gl_FrontFacing) n = -n;
    vec3 albedo = to_linear(texture(u_color, v_uv).rgb);
    float light = 0.15 + 0.75 * max(dot(n, u_key), 0.0) + 0.25 * max(dot(n, u_fill), 0.0);
    o_color = vec4(to_srgb(albedo * light), 1.0);
}
