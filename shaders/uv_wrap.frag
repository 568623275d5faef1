#version 430 core
// The id of the face copy covering the texel (the last drawn wins: no blending).

flat in float v_id;
out float id;

void main() {
    id = v_id;
}
