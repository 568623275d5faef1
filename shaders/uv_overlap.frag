#version 430 core
// One per covering triangle; additive blending turns the target into a per-texel count.
// GL's rasterisation rules give each texel centre on a shared edge to exactly one of the two
// triangles, so neighbouring faces never count twice.

out float count;

void main() {
    count = 1.0;
}
