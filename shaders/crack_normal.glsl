// Depth-normal and occlusion of one crack segment at a texel (inserted into crack_normal.comp,
// which runs it at the crack texels only).  Everything is analytic in world space: the depth term that wins the
// texel is differentiated in closed form, so the normal is exact at the texel centre whatever the
// UV stretch, and continuous across UV seams (no image-space filter).
//
// The crack's cross-section: height z(x) = -D (1 - |x| / hw) ^ shape for |x| < hw, 0 outside,
// x the world distance to the crack axis, hw the half width, D the depth.

const int VIS_SAMPLES = 8;  // profile samples per side for the horizon search (exact for a V)
const int BOX_OCC_SAMPLES = 4;  // occlusion samples across a thin groove's box

float profile_z(float x, float hw, float depth) {
    return -depth * pow(max(1.0 - abs(x) / hw, 0.0), u_shape);
}

// Sine of the angle from the unit normal n to the unit direction v, positive towards +x.
float side_sine(vec2 n, vec2 v) { return v.x * n.y - v.y * n.x; }

// Sky visibility (cosine-weighted, i.e. the view factor to the sky) of the point at distance
// xp >= 0 from the axis of an infinitely long groove of that cross-section, with the 2D normal n.
// For a long groove the view factor from a strip to the sky between the horizon directions at
// angles a (towards -x) and b (towards +x) from the normal is (sin b - sin a) / 2; the horizons
// are the highest profile points on either side (for a V the two rims: exact), clipped to the
// tangent plane.  Flat ground gives 1; the apex of a V of slope angle alpha gives cos^2(alpha).
float groove_visibility(float xp, float hw, float depth, vec2 n) {
    vec2 p = vec2(xp, profile_z(xp, hw, depth));
    float right = -1e30;  // highest elevation (tangent of the angle above +x) towards +x
    float left = -1e30;   // towards -x
    for (int k = 1; k <= VIS_SAMPLES; ++k) {
        float f = float(k) / float(VIS_SAMPLES);
        float xr = mix(xp, hw, f);
        float xl = mix(xp, -hw, f);
        if (xr > xp) right = max(right, (profile_z(xr, hw, depth) - p.y) / (xr - xp));
        if (xl < xp) left = max(left, (profile_z(xl, hw, depth) - p.y) / (xp - xl));
    }
    // The apex: the lowest point, a horizon only for fuller (U-like) profiles.
    if (xp > 0.0) left = max(left, (-depth - p.y) / xp);
    vec2 vr = normalize(vec2(1.0, max(right, -1e6)));
    vec2 vl = normalize(vec2(-1.0, max(left, -1e6)));
    float sr = dot(n, vr) > 0.0 ? side_sine(n, vr) : 1.0;
    float sl = dot(n, vl) > 0.0 ? side_sine(n, vl) : -1.0;
    return clamp(0.5 * (sr - sl), 0.0, 1.0);
}

// Mean sky visibility over the walls of the groove: by reciprocity, everything entering the
// opening (width 2 hw) lands on the walls, so wall length x mean view factor = 2 hw.
float groove_mean_visibility(float hw, float depth) {
    float len = 0.0;
    vec2 q = vec2(-hw, 0.0);
    for (int k = 1; k <= 2 * VIS_SAMPLES; ++k) {
        float x = mix(-hw, hw, float(k) / float(2 * VIS_SAMPLES));
        vec2 r = vec2(x, profile_z(x, hw, depth));
        len += length(r - q);
        q = r;
    }
    return clamp(2.0 * hw / max(len, 1e-30), 0.0, 1.0);
}

// World gradient of the segment's depth term at p (the term crack_bake.frag maximises), and the
// occlusion there.  Full cracks (w >= fw): the point-sampled profile D(t) (1 - d / hw(t))^shape,
// differentiated across (along the distance gradient g/d) and along the segment (D and w vary
// linearly in t); drawn fewer than GROOVE_BOX_NONE footprints wide, that profile averaged over a
// box about one footprint across (crack_look.glsl), differentiated the same way.  Sub-texel
// cracks (w < fw): the bake stores the area average over the texel, a tent
// D w / ((shape + 1) fw) * (1 - d / fw) of one footprint's half width, averaged over one more
// footprint across (tent_box: a point-sampled tent's slope flips sign at the axis: dashes); the
// normal is that filtered height field's slope, and the occlusion the filtered covered fraction
// times the groove's mean wall visibility.
vec3 depth_gradient(Segment s, vec3 p, vec3 dpx, vec3 dpy, float texel_iso, out float occ) {
    vec3 ab = s.b.xyz - s.a.xyz;
    float len2 = dot(ab, ab);
    float t_raw = len2 > 0.0 ? dot(p - s.a.xyz, ab) / len2 : 0.0;
    float t = clamp(t_raw, 0.0, 1.0);
    // Past an end the distance is to the end point: t no longer moves with p.
    vec3 grad_t = (t_raw > 0.0 && t_raw < 1.0) ? ab / len2 : vec3(0.0);
    vec3 g = p - (s.a.xyz + t * ab);
    float d = length(g);
    float chip = chip_factor(p);      // chipped edges (1 without): the drawn width only
    float w_phys = chip * mix(s.a.w, s.b.w, t);
    float dw = chip * (s.b.w - s.a.w);  // d(width)/dt
    float depth = mix(s.dt.x, s.dt.y, t);
    float ddepth = s.dt.y - s.dt.x;   // d(depth)/dt
    // On the axis itself the two walls meet: no across slope (their average).
    vec3 gn = vec3(0.0);
    float fw = texel_iso;
    if (d > 1e-6 * texel_iso) {
        gn = g / d;
        fw = length(vec2(dot(gn, dpx), dot(gn, dpy)));
    }
    fw = max(fw, 1e-30);
    // The drawn width, as crack_bake.frag draws it: at least u_min_px footprints; where that
    // floor holds, the width no longer varies along the segment.
    float w = max(w_phys, u_min_px * fw);
    if (w > w_phys) dw = 0.0;
    float hw = 0.5 * w;
    occ = 1.0;
    if (w_phys >= fw || w > fw) {  // the branch crack_bake.frag takes
        float u = d / max(hw, 1e-30);
        // Thin grooves: the box-averaged profile reaches half a box past the rim.
        float box = groove_box(w, fw);
#ifdef CRACK_CURL
        // The curled rim beside the crack: height u_curl D (1 - x)^2, x = (d - hw) / (R hw).
        if (d - 0.5 * box >= hw && u < 1.0 + CURL_REACH) {
            float x = (u - 1.0) / CURL_REACH;
            return (2.0 * u_curl * depth * (1.0 - x) / (CURL_REACH * max(hw, 1e-30))) * gn;
        }
#endif
        if (d - 0.5 * box >= hw) return vec3(0.0);
        if (box > 0.0) {
            // The depth D(t) A(d, hw(t)), A the profile's mean over [d - box/2, d + box/2]
            // (crack_bake.frag): across, A's derivative is the profile's difference over the
            // box; along, D and hw vary with t (dF/dhw, F the profile's integral).
            float x0 = d - 0.5 * box;
            float x1 = d + 0.5 * box;
            float mean = (groove_integral(x1, hw) - groove_integral(x0, hw)) / box;
            float across = depth * (groove_q(x1, hw) - groove_q(x0, hw)) / box;
            float r0 = max(1.0 - abs(x0) / hw, 0.0);
            float r1 = max(1.0 - abs(x1) / hw, 0.0);
            float g0 = sign(x0) * ((1.0 - pow(r0, u_shape + 1.0)) / (u_shape + 1.0)
                                   - groove_q(x0, hw) * min(abs(x0) / hw, 1.0));
            float g1 = sign(x1) * ((1.0 - pow(r1, u_shape + 1.0)) / (u_shape + 1.0)
                                   - groove_q(x1, hw) * min(abs(x1) / hw, 1.0));
            float along = ddepth * mean + depth * (g1 - g0) / box * (0.5 * dw);
            // The occlusion averaged over the box too: each point's wall (or flat ground
            // beyond the rim) with its own normal, as the point-sampled groove shades it.
            occ = 0.0;
            for (int k = 0; k < BOX_OCC_SAMPLES; ++k) {
                float x = abs(mix(x0, x1, (float(k) + 0.5) / float(BOX_OCC_SAMPLES)));
                if (x >= hw) { occ += 1.0; continue; }
                float wall = -depth * u_shape * pow(max(1.0 - x / hw, 1e-6), u_shape - 1.0) / hw;
                occ += groove_visibility(x, hw, depth, normalize(vec2(wall, 1.0)));
            }
            occ /= float(BOX_OCC_SAMPLES);
            return across * gn + along * grad_t;
        }
        float q = max(1.0 - u, 1e-6);  // U profiles (shape < 1) have vertical walls at the rim
        float qs = pow(q, u_shape);
        float qs1 = pow(q, u_shape - 1.0);
        float across = -depth * u_shape * qs1 / max(hw, 1e-30);
        float along = ddepth * qs + depth * u_shape * qs1 * u * (0.5 * dw) / max(hw, 1e-30);
        occ = groove_visibility(d, hw, depth, normalize(vec2(across, 1.0)));
        return across * gn + along * grad_t;
    }
    // The tent averaged over a footprint across (crack_bake.frag), and its exact slope.
    float ramp = tent_box(d, fw);
    float k = 1.0 / (fw * (u_shape + 1.0));
    float across = depth * w * k * tent_box_slope(d, fw);
    float along = (ddepth * w + depth * dw) * ramp * k;
    occ = 1.0 - ramp * (w / fw) * (1.0 - groove_mean_visibility(hw, depth));
    return across * gn + along * grad_t;
}

// The texel's tangent-space normal (xyz) and occlusion (w) for the winning segment.  The
// perturbed world normal n' = normalize(N + grad_s depth) (height h = -depth over the shading
// normal, grad_s the gradient projected into the plane normal to N) is expressed in the
// interpolated frame an engine decodes with, n = normalize(x T + y B + z N), B = w cross(N, T),
// by solving [T B N] (x, y, z) = n' and normalising.
vec4 crack_normal(Segment s, vec3 p, vec3 dpx, vec3 dpy, float texel_iso, uint face) {
    float occ;
    vec3 grad = u_normal_strength * depth_gradient(s, p, dpx, dpy, texel_iso, occ);
    // Barycentrics of p in its face (world positions are affine in UV inside a face, so these
    // are the rasteriser's), then N and T interpolated as the engine's rasteriser does.
    Frame f0 = frame[face_vertex[3u * face]];
    Frame f1 = frame[face_vertex[3u * face + 1u]];
    Frame f2 = frame[face_vertex[3u * face + 2u]];
    vec3 e1 = f1.pos.xyz - f0.pos.xyz;
    vec3 e2 = f2.pos.xyz - f0.pos.xyz;
    vec3 q = p - f0.pos.xyz;
    float d00 = dot(e1, e1), d01 = dot(e1, e2), d11 = dot(e2, e2);
    float denom = d00 * d11 - d01 * d01;
    vec3 bary = vec3(1.0 / 3.0);  // a face of no world area: its mean frame
    if (denom > 1e-12 * d00 * d11) {
        float b1 = (d11 * dot(q, e1) - d01 * dot(q, e2)) / denom;
        float b2 = (d00 * dot(q, e2) - d01 * dot(q, e1)) / denom;
        bary = vec3(1.0 - b1 - b2, b1, b2);
    }
    vec3 N = bary.x * f0.normal.xyz + bary.y * f1.normal.xyz + bary.z * f2.normal.xyz;
    vec4 T4 = bary.x * f0.tangent + bary.y * f1.tangent + bary.z * f2.tangent;
    vec3 T = T4.xyz;
    vec3 B = (T4.w < 0.0 ? -1.0 : 1.0) * cross(N, T);
    vec3 c0 = cross(B, N);
    vec3 c1 = cross(N, T);
    vec3 c2 = cross(T, B);
    float det = dot(T, c0);
    float scale = length(T) * length(B) * length(N);
    if (!(abs(det) > 1e-6 * scale) || dot(grad, grad) == 0.0) return vec4(0.0, 0.0, 1.0, occ);
    vec3 nn = normalize(N);
    vec3 n = normalize(nn + (grad - dot(grad, nn) * nn));
    vec3 ts = vec3(dot(n, c0), dot(n, c1), dot(n, c2)) / det;
    return vec4(normalize(ts), occ);
}
