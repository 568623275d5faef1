#version 430 core
// Depth-normal and occlusion at the crack texels of one band (those whose depth term a segment
// wins, listed by crackbake/bake/raster.py from the crack pass's output), one invocation each.
// Reads the surface pass's targets like crack_bake.frag does, so p, the footprint and the
// segment are exactly the ones the crack pass measured.
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
layout(std430, binding = 7) readonly buffer Texels { ivec4 job[]; };  // x, y in band, segment
layout(std430, binding = 8) writeonly buffer Result { vec4 result[]; };  // normal xyz, occlusion

uniform float u_shape;   // depth profile exponent: 1 = V
uniform float u_min_px;  // least drawn width, texels (as crack_bake.frag)
uniform uint u_count;    // texels listed
uniform float u_normal_strength;  // slope scale of the normal (1 = the groove's true slope)

layout(binding = 0) uniform sampler2D u_point;   // xyz position, w = bin
layout(binding = 1) uniform sampler2D u_dpx;     // xyz footprint along x, w = 1 on a face
layout(binding = 2) uniform sampler2D u_dpy;     // xyz footprint along y, w = face

// @crack_look.glsl (inserted here by crackbake/bake/normal_map.py)
// @crack_normal.glsl (inserted here by crackbake/bake/normal_map.py)

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= u_count) return;
    ivec4 j = job[i];
    ivec2 texel = j.xy;
    vec3 p = texelFetch(u_point, texel, 0).xyz;
    vec3 dpx = texelFetch(u_dpx, texel, 0).xyz;
    vec4 gy = texelFetch(u_dpy, texel, 0);
    float texel_iso = 0.5 * (length(dpx) + length(gy.xyz));
    result[i] = crack_normal(seg[j.z], p, dpx, gy.xyz, texel_iso, uint(gy.w));
}
