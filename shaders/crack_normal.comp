#version 430 core
// Depth-normal and occlusion at the crack texels of one band (those whose depth term a segment
// wins, listed by crackbake/bake/raster.py from the crack pass's output), one invocation each.
// Reads the records the crack pass appended (crack_bake.frag), so p, the footprint, the face and
// the segment are exactly the ones the crack pass measured.
layout(local_size_x = 64) in;

struct Segment {
    vec4 a;      // xyz start, w = width at start
    vec4 b;      // xyz end,   w = width at end
    vec4 dt;     // depth at start, depth at end, time at start, time at end
    vec4 id;     // x = crack id
};
// The baked mesh's triangles and per-vertex frames, to interpolate N and T at a texel's point.
struct Frame {
    vec4 pos;      // xyz world position
    vec4 normal;   // xyz vertex normal
    vec4 tangent;  // xyz tangent, w bitangent sign (B = w cross(N, T) points to +v)
};

layout(std430, binding = 0) readonly buffer Segments { Segment seg[]; };
layout(std430, binding = 5) readonly buffer Faces { uint face_vertex[]; };  // 3 per face
layout(std430, binding = 6) readonly buffer Frames { Frame frame[]; };
layout(std430, binding = 7) readonly buffer Texels { ivec4 job[]; };  // x, y in band, record
// Per crack texel: point xyz + face, footprint along x + segment, footprint along y.
layout(std430, binding = 10) readonly buffer Records { vec4 record[]; };
layout(std430, binding = 8) writeonly buffer Result { vec4 result[]; };  // normal xyz, occlusion

uniform float u_shape;   // depth profile exponent: 1 = V
uniform float u_min_px;  // least drawn width, texels (as crack_bake.frag)
uniform uint u_count;    // texels listed
uniform float u_normal_strength;  // slope scale of the normal (1 = the groove's true slope)

// @crack_look.glsl (inserted here by crackbake/bake/normal_map.py)
// @crack_normal.glsl (inserted here by crackbake/bake/normal_map.py)

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= u_count) return;
    ivec4 j = job[i];
    vec4 r0 = record[3 * j.z];
    vec4 r1 = record[3 * j.z + 1];
    vec3 dpy = record[3 * j.z + 2].xyz;
    float texel_iso = 0.5 * (length(r1.xyz) + length(dpy));
    result[i] = crack_normal(seg[int(r1.w)], r0.xyz, r1.xyz, dpy, texel_iso, uint(r0.w));
}
