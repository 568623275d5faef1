#version 430 core
// A face copy at its UV position (shifted by whole tiles on the CPU), carrying its copy id.

in vec2 in_uv;
in float in_id;   // copy index + 1 (0 stays "none")

flat out float v_id;

void main() {
    v_id = in_id;
    gl_Position = vec4(in_uv * 2.0 - 1.0, 0.0, 1.0);
}
