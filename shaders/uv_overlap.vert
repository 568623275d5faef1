#version 430 core
// Draw a triangle at its UV position so the render target is the UV page.
// uv in [0, 1] maps to clip space [-1, 1]; GL row 0 is v = 0 (bottom).

in vec2 in_uv;

void main() {
    gl_Position = vec4(in_uv * 2.0 - 1.0, 0.0, 1.0);
}
