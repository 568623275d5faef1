#version 430 core
// Stress bake: the world stress tensor S (interpolated linearly between the simulation nodes)
// expressed in the texel's tangent frame
//     N  = normalize(N_interp)
//     e1 = normalize(T - N (N.T))        (T Gram-Schmidt against N: the tangent, +u)
//     e2 = sign(w) cross(N, e1)          (the bitangent, +v)
// as sigma_xx = e1.S.e1, sigma_yy = e2.S.e2, sigma_xy = e1.S.e2.  Principal values and
// directions are computed after readback and gutter fill (crackbake/bake/stress.py).

in vec3 v_t;
in float v_w;
in vec3 v_n;
in vec3 v_sd;
in vec3 v_so;
in float v_sep;

// One single-channel R32F target per value, so each reads back straight into its own image.
layout(location = 0) out float o_xx;
layout(location = 1) out float o_yy;
layout(location = 2) out float o_xy;
layout(location = 3) out float o_sep;      // >= 0; targets are cleared to -1 (= not drawn)

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
    mat3 s = mat3(v_sd.x, v_so.x, v_so.y,
                  v_so.x, v_sd.y, v_so.z,
                  v_so.y, v_so.z, v_sd.z);
    vec3 s1 = s * e1;
    o_xx = dot(e1, s1);
    o_yy = dot(e2, s * e2);
    o_xy = dot(e2, s1);
    o_sep = v_sep;
}
