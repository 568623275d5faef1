// Look terms shared by crack_bake.frag and crack_normal.glsl (inserted by
// crackbake/bake/normal_map.py where a shader says "// @crack_look.glsl"; compiled only for looks
// that use them, so the default bake runs exactly the code it always ran).
//
// CRACK_CHIP: chipped, ragged edges.  The drawn width of every crack at a texel is scaled by
// 1 + u_chip * n(p), n a seeded two-octave value noise in [-1, 1] of the texel's world point
// (feature size u_chip_scale): a function of the point only, so both passes agree on it, it is
// continuous across UV seams and the same seed gives the same pixels.
// CRACK_CURL: curled cell edges.  Beside each crack a raised rim of height u_curl * D falls off
// quadratically over CURL_REACH half widths: a negative depth in the depth channel
// (crack_bake.frag) and its slope in the normal map (crack_normal.glsl), the same height field.

// A broad rim (3 half widths, was 1.5) is what reads under a grazing light: its slope faces the
// sun on one side of the gap while the walls sit in the occlusion (docs/maps.md, measured).
const float CURL_REACH = 3.0;

// Thin grooves (drawn fewer than GROOVE_BOX_FULL footprints wide, sub-texel ones included): the depth is the groove's
// profile averaged over one footprint fb across the crack, and the normal its slope, the
// difference of the profile over that footprint (the average's exact derivative), so a groove
// one to three texels wide shades smoothly from texel to texel instead of flipping between
// point-sampled walls (dashes along cracks near a texel row).  The box narrows to a point
// sample at GROOVE_BOX_NONE footprints, where the point-sampled groove no longer aliases.
const float GROOVE_BOX_FULL = 3.0;
const float GROOVE_BOX_NONE = 4.0;

// The box width, mesh units, for a groove drawn w wide at a footprint fw (0: point samples).
float groove_box(float w, float fw) {
    float b = fw * clamp(GROOVE_BOX_NONE - w / fw, 0.0, GROOVE_BOX_NONE - GROOVE_BOX_FULL);
    return b > 0.01 * fw ? b : 0.0;  // narrower boxes are the point sample to float precision
}

// The profile q(x) = (1 - |x| / hw)^u_shape (0 beyond the rims), and its integral from 0 to x
// (odd in x, constant beyond the rims).
float groove_q(float x, float hw) {
    float r = 1.0 - abs(x) / hw;
    return r > 0.0 ? pow(r, u_shape) : 0.0;
}

float groove_integral(float x, float hw) {
    float r = max(1.0 - abs(x) / hw, 0.0);
    return sign(x) * hw / (u_shape + 1.0) * (1.0 - pow(r, u_shape + 1.0));
}

// Sub-texel cracks' coverage ramp (1 - |x| / fw) averaged over the box [d - fw/2, d + fw/2],
// and its slope: the same filter for the tent they are drawn as (crack_bake.frag).
float tent_box(float d, float fw) {
    float x0 = d - 0.5 * fw, x1 = d + 0.5 * fw;
    float r0 = max(1.0 - abs(x0) / fw, 0.0), r1 = max(1.0 - abs(x1) / fw, 0.0);
    return 0.5 * (sign(x1) * (1.0 - r1 * r1) - sign(x0) * (1.0 - r0 * r0));
}

float tent_box_slope(float d, float fw) {
    float r0 = max(1.0 - abs(d - 0.5 * fw) / fw, 0.0), r1 = max(1.0 - abs(d + 0.5 * fw) / fw, 0.0);
    return (r1 - r0) / fw;
}

#ifdef CRACK_CHIP
uniform float u_chip;        // relative amplitude of the half-width noise, 0..0.9
uniform float u_chip_scale;  // feature size of the noise, mesh units
uniform uint u_chip_seed;

uint chip_hash(ivec3 c, uint salt) {
    uint h = (uint(c.x) * 0x8da6b343u) ^ (uint(c.y) * 0xd8163841u) ^ (uint(c.z) * 0xcb1ab31fu);
    h ^= u_chip_seed + salt * 0x9e3779b9u;
    h ^= h >> 16; h *= 0x7feb352du; h ^= h >> 15; h *= 0x846ca68bu; h ^= h >> 16;
    return h;
}

float chip_corner(ivec3 c, uint salt) { return float(chip_hash(c, salt) >> 8u) / 8388607.5 - 1.0; }

float chip_value_noise(vec3 q, uint salt) {
    vec3 fl = floor(q);
    ivec3 i = ivec3(fl);
    vec3 f = q - fl;
    f = f * f * (3.0 - 2.0 * f);
    float x00 = mix(chip_corner(i, salt), chip_corner(i + ivec3(1, 0, 0), salt), f.x);
    float x10 = mix(chip_corner(i + ivec3(0, 1, 0), salt), chip_corner(i + ivec3(1, 1, 0), salt), f.x);
    float x01 = mix(chip_corner(i + ivec3(0, 0, 1), salt), chip_corner(i + ivec3(1, 0, 1), salt), f.x);
    float x11 = mix(chip_corner(i + ivec3(0, 1, 1), salt), chip_corner(i + ivec3(1, 1, 1), salt), f.x);
    return mix(mix(x00, x10, f.y), mix(x01, x11, f.y), f.z);
}

// Factor of the drawn width at world point p: 1 + u_chip * n, n in [-1, 1].
float chip_factor(vec3 p) {
    vec3 q = p / u_chip_scale;
    float n = 0.65 * chip_value_noise(q, 1u) + 0.35 * chip_value_noise(2.7 * q, 2u);
    return 1.0 + u_chip * clamp(2.0 * n, -1.0, 1.0);
}
#else
float chip_factor(vec3 p) { return 1.0; }
#endif

#ifdef CRACK_CURL
uniform float u_curl;  // rim height, of the crack's depth
#endif
