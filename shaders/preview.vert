#version 430 core
// Preview: the output mesh seen from a camera, textured with the baked maps.
in vec3 in_pos;
in vec3 in_normal;
in vec2 in_uv;
in vec4 in_tangent;  // MikkTSpace: xyz tangent, w bitangent sign (zero when there are none)

uniform mat4 u_mvp;

out vec3 v_normal;
out vec2 v_uv;
out vec4 v_tangent;

void main() {
    v_normal = in_normal;
    v_uv = in_uv;
    v_tangent = in_tangent;
    gl_Position = u_mvp * vec4(in_pos, 1.0);
}
