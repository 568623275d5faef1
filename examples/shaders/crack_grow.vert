#version 330 core
// Example vertex shader for crack_grow.frag (glTF-style attributes: POSITION, NORMAL,
// TEXCOORD_0 with v down as glTF stores it, TANGENT with w the bitangent sign).
in vec3 a_position;
in vec3 a_normal;
in vec2 a_uv;
in vec4 a_tangent;

uniform mat4 u_model;
uniform mat4 u_view_proj;

out vec3 v_normal;
out vec4 v_tangent;
out vec2 v_uv;

void main() {
    mat3 m = mat3(u_model);  // uniform scale assumed; use the inverse transpose otherwise
    v_normal = m * a_normal;
    v_tangent = vec4(m * a_tangent.xyz, a_tangent.w);
    v_uv = a_uv;
    gl_Position = u_view_proj * u_model * vec4(a_position, 1.0);
}
