#version 430 core
// Preview: the output mesh seen from a camera, textured with the baked maps.
in vec3 in_pos;
in vec3 in_normal;
in vec2 in_uv;

uniform mat4 u_mvp;

out vec3 v_normal;
out vec2 v_uv;

void main() {
    v_normal = in_normal;
    v_uv = in_uv;
    gl_Position = u_mvp * vec4(in_pos, 1.0);
}
