#version 430 core
// The crack pass, once per texel: measures, in world units, the distance from the texel's surface
// point to the crack segments listed for its face's bin (crackbake/bake/grid.py), and turns it
// into the crack channels.  Working in world space makes the width independent of UV stretch and
// continuous across UV seams.  The surface point and its footprint come either from the face
// itself (CRACK_FACES: a UV placement draws the listed faces, crackbake/bake/raster.py) or from
// the surface pass's targets (crack_surface.frag; this pass then one full-screen triangle).
// Compiled with CRACK_NORMALS defined it also records, at each texel whose depth a segment
// wins, that segment and the texel's point, footprint and face, for crack_normal.comp to
// compute the depth-normal and occlusion at the crack texels only (llvmpipe runs both sides of
// a branch, so doing it here cost every texel); the code the other channels run is the same in
// both variants, so they come out bit-identical.

struct Segment {
    vec4 a;      // xyz start, w = width at start
    vec4 b;      // xyz end,   w = width at end
    vec4 dt;     // depth at start, depth at end, time at start, time at end
    vec4 id;     // x = crack id
};

// The segments and the candidate lists are textures, not storage buffers: llvmpipe loads a
// storage buffer at per-texel indices one lane at a time, while texelFetch gathers all lanes at
// once (measured: the loop body cost ~4x less).  The values are the same float32/uint32 bits.
// Layouts (crackbake/bake/raster.py): segment i is the four texels x = 4 (i % SEG_ROW) + 0..3 of
// row i / SEG_ROW (a, b, dt, id); list entry k is texel (k % LIST_ROW, k / LIST_ROW), red the
// segment index, green the bits of its bound; bin b's texel in u_bins is laid out the same way.
const int SEG_ROW_LOG2 = 10;
const int LIST_ROW_LOG2 = 12;
layout(binding = 3) uniform sampler2D u_segments;
layout(binding = 4) uniform usampler2D u_lists;   // candidate lists, ascending bound per bin
layout(binding = 5) uniform usampler2D u_bins;    // per bin: its list's first, end entry

ivec2 table_texel(uint k) { return ivec2(int(k) & ((1 << LIST_ROW_LOG2) - 1), int(k) >> LIST_ROW_LOG2); }
#ifdef CRACK_CELLS
// A camera's image (the decal bake, crackbake/bake/cells.py): the lists belong to square cells
// of the image instead of the faces' bins.
uniform int u_cell;      // cell edge, texels
uniform int u_cells_x;   // cells per image row
uniform int u_row0;      // image row of the band's first row (image rows run top-down)
#endif

uniform float u_max_distance;   // distance channel clamp, mesh units
uniform float u_half_width;     // half the widest crack's width, mesh units
uniform float u_shape;          // depth profile exponent: 1 = V, < 1 fuller (U-like), > 1 sharper
uniform float u_min_px;         // least drawn width, texels (0 = the physical width only)

// @crack_look.glsl (inserted here by crackbake/bake/normal_map.py)

#ifdef CRACK_FACES
in vec3 v_world;  // crack_bake.vert
// Per drawn primitive p, at texel (p % 4096, p / 4096): its face, its face's bin.  Each slice of
// the crack pass draws its own run of the table (the faces reaching its rows), from u_prim_base.
layout(binding = 7) uniform usampler2D u_prim;
uniform int u_prim_base;
#else
layout(binding = 0) uniform sampler2D u_point;   // xyz position, w = bin
layout(binding = 1) uniform sampler2D u_dpx;     // xyz footprint along x, w = 1 on a face
layout(binding = 2) uniform sampler2D u_dpy;     // xyz footprint along y, w = face
#endif

#ifdef CRACK_NORMALS
// The crack texels' records, appended: point xyz + face, footprint x + segment, footprint y.
// The inside target says which record is the texel's (2 + its index): where faces overlap,
// the last face drawn wins the record as it wins the targets.  Records past u_capacity are
// counted but not stored (crackbake/bake/raster.py draws the band again with room for them).
layout(std430, binding = 9) buffer Count { uint n_records; };
layout(std430, binding = 10) writeonly buffer Records { vec4 record[]; };
uniform uint u_capacity;
#endif

// One single-channel target per map, so each reads back straight into its own image.
layout(location = 0) out float o_mask;      // R16F
layout(location = 1) out float o_width;     // R16F
layout(location = 2) out float o_time;      // R16F
layout(location = 3) out float o_depth;     // R32F
layout(location = 4) out float o_distance;  // R32F
layout(location = 5) out float o_id;        // R32F
layout(location = 6) out float o_inside;    // R8; with CRACK_NORMALS R32F: 2 + its record

void main() {
#ifdef CRACK_FACES
    // As crack_surface.frag records them: the same values, measured in place.
    vec3 p = v_world;
    // World-space footprint of one texel; the surface is affine inside a face.
    vec3 dpx = dFdx(v_world);
    vec3 dpy = dFdy(v_world);
    int drawn = u_prim_base + gl_PrimitiveID;
    uvec2 prim = texelFetch(u_prim, ivec2(drawn & 4095, drawn >> 12), 0).xy;
    uint bin = prim.y;
    float face = float(prim.x);  // exact below 2^24 faces
#else
    ivec2 texel = ivec2(gl_FragCoord.xy);
    vec4 point = texelFetch(u_point, texel, 0);
    vec4 gx = texelFetch(u_dpx, texel, 0);
    if (gx.w == 0.0) {
        // No face here: the background the gutter fill replaces.
        o_mask = 0.0; o_width = 0.0; o_time = 0.0; o_depth = 0.0;
        o_distance = 0.0; o_id = 0.0; o_inside = 0.0;
        return;
    }
#ifdef CRACK_CELLS
    uint bin = uint(((u_row0 + texel.y) / u_cell) * u_cells_x + texel.x / u_cell);
#else
    uint bin = uint(point.w);
#endif
    vec3 p = point.xyz;
    // World-space footprint of one texel; the surface is affine inside a face.
    vec3 dpx = gx.xyz;
    vec4 gy = texelFetch(u_dpy, texel, 0);
    vec3 dpy = gy.xyz;
    float face = gy.w;
#endif
    float texel_iso = 0.5 * (length(dpx) + length(dpy));

    float best_d = u_max_distance;
    float best_w = 0.0;
    float best_time = 0.0;
    float best_id = -1.0;
    float coverage = 0.0;
    float depth = 0.0;

    // Farther than this a segment adds no coverage or depth: the ramp ends within half a width
    // plus one footprint, and the footprint along any direction is at most |(|dpx|, |dpy|)|.
    // A crack drawn wider than it is (u_min_px) reaches min_px / 2 footprints.
    float foot = length(vec2(length(dpx), length(dpy)));
    // u_half_width already holds the widest chipped half width (and the curl's rim).
    float cover_reach = max(u_half_width, 0.5 * u_min_px * foot) + foot;
    int best_seg = -1;
#ifdef CRACK_CHIP
    float chip = chip_factor(p);
#endif
#ifdef CRACK_NORMALS
    int deepest_seg = -1;  // the segment whose depth term wins (the normal's profile)
#endif
#ifdef CRACK_CURL
    int rim_seg = -1;      // with no depth here: the segment whose curled rim the texel is on
    float rim_u = CURL_REACH;   // its distance beyond the edge, in half widths
    float rim_depth = 0.0;      // its depth there (the rim is u_curl times that high)
#endif
    uvec2 list = texelFetch(u_bins, table_texel(bin), 0).xy;
    // Two walks over the list (the same pixels as one walk doing everything, at a fraction of
    // its cost: most steps only measure a distance).  First the nearest segment: the walk stops
    // at the first entry whose bound exceeds both the nearest distance so far and the cover
    // reach, as a single walk measuring everything would; kend is where.  It also marks the
    // entries near enough to add coverage, depth or a rim.
    // Farther than add_reach a segment adds exactly nothing: beyond half the widest drawn width
    // (its rim with a curl) plus two footprints, a texel's ramp, or a thin crack's filtered
    // tent, has ended (they end within 1.5 footprints across).
    float floor_half = 0.5 * u_min_px * foot;
#ifdef CRACK_CURL
    floor_half *= 1.0 + CURL_REACH;
#endif
    float add_reach = max(u_half_width, floor_half) + 2.0 * foot;
    uvec2 near = uvec2(0u);  // bit j: entry list.x + j lies within add_reach of this texel
    uint kend = list.y;
    float best_t = 0.0;
    for (uint k = list.x; k < list.y; ++k) {
        // Segments come nearest-bound first: the rest cannot be nearer or add coverage.
        uvec2 entry = texelFetch(u_lists, table_texel(k), 0).xy;
        if (uintBitsToFloat(entry.y) > max(best_d, cover_reach)) { kend = k; break; }
        uint si = entry.x;
        ivec2 at = ivec2((int(si) & ((1 << SEG_ROW_LOG2) - 1)) << 2, int(si) >> SEG_ROW_LOG2);
        vec4 a = texelFetch(u_segments, at, 0);
        vec4 b = texelFetch(u_segments, at + ivec2(1, 0), 0);
        vec3 ab = b.xyz - a.xyz;
        float len2 = dot(ab, ab);
        float t = len2 > 0.0 ? clamp(dot(p - a.xyz, ab) / len2, 0.0, 1.0) : 0.0;
        vec3 g = p - (a.xyz + t * ab);
        float d = length(g);
        uint j = k - list.x;
        if (d <= add_reach && j < 64u) {
            if (j < 32u) near.x |= 1u << j; else near.y |= 1u << (j - 32u);
        }
        // Ties go to the lowest index, so the result does not depend on the list order.
        if (d < best_d || (d == best_d && best_seg >= 0 && int(si) < best_seg)) {
            best_seg = int(si);
            best_d = d;
            best_t = t;
        }
    }
    if (best_seg >= 0) {
        ivec2 at = ivec2((best_seg & ((1 << SEG_ROW_LOG2) - 1)) << 2, best_seg >> SEG_ROW_LOG2);
        Segment s = Segment(texelFetch(u_segments, at, 0),
                            texelFetch(u_segments, at + ivec2(1, 0), 0),
                            texelFetch(u_segments, at + ivec2(2, 0), 0),
                            texelFetch(u_segments, at + ivec2(3, 0), 0));
        best_w = mix(s.a.w, s.b.w, best_t);
        best_time = mix(s.dt.z, s.dt.w, best_t);
        best_id = s.id.x;
    }
    // Then the coverage, depth and rims over the same entries, but only those near enough to add
    // any: the first 64 by the texel's own distance (the walk above marked them), the rest by
    // their bound, in the list's order.
    uint masked_end = min(kend, list.x + 64u);
    uint tail = masked_end;
    for (;;) {
        uint k;
        if (near.x != 0u) {
            k = list.x + uint(findLSB(near.x));
            near.x &= near.x - 1u;
        } else if (near.y != 0u) {
            k = list.x + 32u + uint(findLSB(near.y));
            near.y &= near.y - 1u;
        } else {
            if (tail >= kend) break;
            k = tail++;
        }
        uvec2 entry = texelFetch(u_lists, table_texel(k), 0).xy;
        if (k >= masked_end && uintBitsToFloat(entry.y) > add_reach) break;
        uint si = entry.x;
        ivec2 at = ivec2((int(si) & ((1 << SEG_ROW_LOG2) - 1)) << 2, int(si) >> SEG_ROW_LOG2);
        Segment s = Segment(texelFetch(u_segments, at, 0),
                            texelFetch(u_segments, at + ivec2(1, 0), 0),
                            texelFetch(u_segments, at + ivec2(2, 0), 0),
                            texelFetch(u_segments, at + ivec2(3, 0), 0));
        vec3 ab = s.b.xyz - s.a.xyz;
        float len2 = dot(ab, ab);
        float t = len2 > 0.0 ? clamp(dot(p - s.a.xyz, ab) / len2, 0.0, 1.0) : 0.0;
        vec3 g = p - (s.a.xyz + t * ab);
        float d = length(g);
        float w_phys = mix(s.a.w, s.b.w, t);
#ifdef CRACK_CHIP
        float w_draw = w_phys * chip;  // chipped edges: the drawn width only
#else
        float w_draw = w_phys;
#endif

        // Texel size measured along the direction in which the distance grows, so the
        // anti-aliasing ramp is one texel wide whatever the UV stretch.
        float fw = texel_iso;
        if (d > 1e-6 * texel_iso) {
            vec3 gn = g / d;
            fw = length(vec2(dot(gn, dpx), dot(gn, dpy)));
        }
        fw = max(fw, 1e-30);
        // The drawn maps show at least u_min_px texels across (so a hairline still reads at
        // this resolution); the width channel keeps the physical width.
        float w = max(w_draw, u_min_px * fw);
        float hw = 0.5 * w;

        float c;
        float dd;
        float depth_here = mix(s.dt.x, s.dt.y, t);
        // A crack drawn exactly one footprint wide by the floor keeps the filtered (thin)
        // form: same mask as a one-texel V, but a two-texel tent of depth whose normal does not
        // alias; wider floors draw the V.  With u_min_px = 0 this is the physical test w >= fw.
        if (w_draw >= fw || w > fw) {
            c = clamp((hw - d) / fw + 0.5, 0.0, 1.0);
            float box = groove_box(w, fw);
            if (box > 0.0) {  // thin: the profile averaged over the box (crack_look.glsl)
                dd = depth_here * (groove_integral(d + 0.5 * box, hw)
                                   - groove_integral(d - 0.5 * box, hw)) / box;
            } else {
                float u = d / max(hw, 1e-30);
                dd = u < 1.0 ? depth_here * pow(1.0 - u, u_shape) : 0.0;
            }
        } else {
            // Thinner than a texel: draw it one texel wide and weight by the covered fraction,
            // so the mask and the depth keep the crack's area-averaged value (of the drawn
            // width: at least u_min_px footprints).
            float frac = w / fw;
            c = clamp((0.5 * fw - d) / fw + 0.5, 0.0, 1.0) * frac;
            // The depth: that tent averaged over one more footprint across (crack_look.glsl).
            dd = depth_here * frac * tent_box(d, fw) / (u_shape + 1.0);
        }
        coverage = max(coverage, c);
#ifdef CRACK_NORMALS
        if (dd > depth) deepest_seg = int(si);
#endif
#ifdef CRACK_CURL
        // Only cracks drawn at full width have walls, hence rims (as crack_normal.glsl).
        float ur = (d - hw) / max(hw, 1e-30);
        if ((w_draw >= fw || w > fw) && ur >= 0.0 && ur < rim_u) {
            rim_u = ur; rim_seg = int(si); rim_depth = depth_here;
        }
#endif
        depth = max(depth, dd);
    }
    o_mask = coverage;
    o_width = best_w;
    o_time = best_time;
#ifdef CRACK_CURL
    // Off every crack, on a curled rim: raised by u_curl D (1 - x)^2, x = rim_u / CURL_REACH,
    // the height field whose slope crack_normal.glsl writes (a negative depth: above the surface).
    if (depth <= 0.0 && rim_seg >= 0) {
        float x = rim_u / CURL_REACH;
        depth = -u_curl * rim_depth * (1.0 - x) * (1.0 - x);
    }
#endif
    o_depth = depth;
    o_distance = best_d;
    o_id = best_id;
#ifdef CRACK_NORMALS
    // 1 on a face with no crack depth, 2 + the record of the segment whose depth term wins.
#ifdef CRACK_CURL
    if (deepest_seg < 0 && rim_seg >= 0) deepest_seg = rim_seg;  // on a curled rim
#endif
    float code = 1.0;
    if (deepest_seg >= 0) {
        uint e = atomicAdd(n_records, 1u);
        if (e < u_capacity) {
            record[3u * e] = vec4(p, face);
            record[3u * e + 1u] = vec4(dpx, float(deepest_seg));  // exact below 2^24
            record[3u * e + 2u] = vec4(dpy, 0.0);
        }
        code = 2.0 + float(e);  // exact: the raster keeps e below 2^24 - 2
    }
    o_inside = code;
#else
    o_inside = 1.0;
#endif
}
