#version 430 core
// Stress bake: each field's world stress tensor S (interpolated linearly between the
// simulation nodes) expressed in the texel's tangent frame
//     N  = normalize(N_interp)
//     e1 = normalize(T - N (N.T))        (T Gram-Schmidt against N: the tangent, +u)
//     e2 = sign(w) cross(N, e1)          (the bitangent, +v)
// as sigma_xx = e1.S.e1, sigma_yy = e2.S.e2, sigma_xy = e1.S.e2.  Principal values and
// directions are computed after readback and gutter fill (crackbake/bake/stress.py).

in vec3 v_t;
in float v_w;
in vec3 v_n;
in vec3 v_sd0;
in vec3 v_so0;
in float v_sep0;
in vec3 v_sd;
in vec3 v_so;
in float v_sep;

// One single-channel R32F target per value, so each reads back straight into its own image.
// Targets are cleared to -1: sep >= 0 marks the texels drawn.
layout(location = 0) out float o_xx0;
layout(location = 1) out float o_yy0;
layout(location = 2) out float o_xy0;
layout(location = 3) out float o_sep0;
layout(location = 4) out float o_xx;
layout(location = 5) out float o_yy;
layout(location = 6) out float o_xy;
layout(location = 7) out float o_sep;

vec3 in_frame(vec3 sd, vec3 so, vec3 e1, vec3 e2) {
    mat3 s = mat3(sd.x, so.x, so.y,
                  so.x, sd.y, so.z,
                  so.y, so.z, sd.z);
    vec3 s1 = s * e1;
    return vec3(dot(e1, s1), dot(e2, s * e2), dot(e2, s1));
}

void main() {
    vec3 n = normalize(v_n);
    vec3 t = v_t - n * dot(n, v_t);
    float tl = length(t);
    if (!(tl > 1e-20)) {
        // No usable tangent (degenerate UVs): any direction in the plane keeps the values finite.
        t = abs(n.x) < 0.9 ? cross(n, vec3(1.0, 0.0, 0.0)) : cross(n, vec3(0.0, 1.0, 0.0));
        tl = length(t);
    }
    vec3 e1 = t / tl;
    vec3 e2 = (v_w < 0.0 ? -1.0 : 1.0) * cross(n, e1);
    vec3 a = in_frame(v_sd0, v_so0, e1, e2);
    vec3 b = in_frame(v_sd, v_so, e1, e2);
    o_xx0 = a.x; o_yy0 = a.y; o_xy0 = a.z; o_sep0 = v_sep0;
    o_xx = b.x; o_yy = b.y; o_xy = b.z; o_sep = v_sep;
}
