// screen_probes/common.glsl — screen-space radiance probes (GI10 and SCREEN_PROBES):
// one probe per u_sp_tile × u_sp_tile pixel tile, placed on a surface the tile sees, tracing
// u_sp_res × u_sp_res rays over the hemisphere of its normal. Host side:
// addon/render/passes/screen_probes.py (ScreenProbes: the uniforms, resources and passes).
//
// Per probe (textures of u_sp_grid texels, one per tile): position (xyz; w = state: 0 no
// probe (the tile sees no surface), 1 kept from last frame and not traced this frame,
// 2 kept and traced (refreshed), 3 new and traced), normal (xyz; w = number of traces blended
// in), and its radiance over the hemisphere projected on 2-band SH (lib/sh.glsl), one
// texture per colour channel. Per-frame ray results: the atlas (u_sp_res texels per tile
// side, rgb = radiance towards the probe, a = hit distance, negative for a back face, 0 for a
// miss).
// Directions: the hemisphere is cut into res² strata of equal solid angle (cos θ in
// [i, i+1] / res, φ in [j, j+1] / res · 2π). Ray texel k samples stratum k (jittered per probe
// and frame by a hash), or with importance sampling a stratum drawn from the probe's CDF
// (sp_ray); every estimate weights a ray by 1 / (N · pdf), so a frame's SH projection and
// irradiance are unbiased either way.
#ifndef GI_SCREEN_PROBES_GLSL
#define GI_SCREEN_PROBES_GLSL

#include "lib/sh.glsl"

uniform int u_sp_tile;       // pixels per probe tile side
uniform int u_sp_res;        // ray texels per probe side
uniform ivec2 u_sp_grid;     // probe tiles (x, y)
uniform uint u_sp_frame;     // the probes' own frame counter (refresh pattern, jitter)

bool sp_in_grid(ivec2 t) { return all(greaterThanEqual(t, ivec2(0))) && all(lessThan(t, u_sp_grid)); }

uniform int u_sp_importance;  // 1: rays importance-sampled (SCREEN_PROBES), 0: one per stratum
const float SP_DEFENSIVE = 0.25;  // share of the rays spread uniformly whatever the history says
#define SP_MAX_STRATA 256

int sp_strata() { return u_sp_res * u_sp_res; }

// A direction in stratum j (of res², uniform in solid angle) of the hemisphere around n; u in [0,1)².
vec3 sp_stratum_dir(int j, vec2 u, vec3 n) {
    vec2 s = (vec2(j % u_sp_res, j / u_sp_res) + u) / float(u_sp_res);
    float z = s.x, r = sqrt(max(1.0 - z * z, 0.0)), phi = TWO_PI * s.y;
    return to_world(vec3(r * cos(phi), r * sin(phi), z), n);
}

// Importance sampling (Lumen's screen probes: rays distributed by the BRDF and last frame's
// light): stratum j gets the probability (1 - d) · w_j / Σw + d / N, w_j = the cosine × the
// luminance of last frame's radiance there (the probe's SH history), d = SP_DEFENSIVE (no
// direction is starved). sp_build_cdf fills the per-invocation CDF; without history the
// strata are equally likely.
float sp_cdf[SP_MAX_STRATA];

void sp_build_cdf(vec4 r, vec4 g, vec4 b, vec3 n, bool history) {
    int N = sp_strata();
    float sum = 0.0;
    for (int j = 0; j < N; ++j) {
        float w = 0.0;
        if (history) {
            vec3 d = sp_stratum_dir(j, vec2(0.5), n);
            vec4 y = sh_basis(d);
            w = max(luminance(vec3(dot(r, y), dot(g, y), dot(b, y))), 0.0) * max(dot(d, n), 0.0);
        }
        sp_cdf[j] = w;
        sum += w;
    }
    float acc = 0.0;
    for (int j = 0; j < N; ++j) {
        acc += sum > 0.0 ? (1.0 - SP_DEFENSIVE) * sp_cdf[j] / sum + SP_DEFENSIVE / float(N) : 1.0 / float(N);
        sp_cdf[j] = acc;
    }
    sp_cdf[N - 1] = 1.0;
}

// Ray k of probe t with normal n this frame: its direction and pdf (per steradian). Uniform:
// ray k is a jittered direction in stratum k (pdf 1/2π). Importance: a stratum drawn from
// sp_cdf (stratified over the rays), then a uniform direction inside it.
vec3 sp_ray(ivec2 t, int k, vec3 n, uint frame, out float pdf) {
    uvec4 h = pcg4d(uvec4(uvec2(t), uint(k), frame));
    vec2 u = vec2(h.xy >> 8u) * (1.0 / 16777216.0);
    int N = sp_strata(), j = k;
    float p = 1.0 / float(N);
    if (u_sp_importance != 0) {
        float x = (float(k) + float(h.z >> 8u) * (1.0 / 16777216.0)) / float(N);
        j = 0;
        while (j < N - 1 && sp_cdf[j] <= x) ++j;
        p = sp_cdf[j] - (j > 0 ? sp_cdf[j - 1] : 0.0);
    }
    pdf = p * float(N) / TWO_PI;
    return sp_stratum_dir(j, u, n);
}

// Irradiance at normal m from the SH coefficients of radiance (per channel), unclamped.
vec3 sp_sh_irradiance(vec4 r, vec4 g, vec4 b, vec3 m) {
    vec4 c = sh_cosine_lobe(m);
    return vec3(dot(r, c), dot(g, c), dot(b, c));
}

// Irradiance at normal m from a probe with normal n: the SH's, corrected by what it misses at
// n (e_n: the exact irradiance there), the correction fading as m turns away from n.
vec3 sp_irradiance(vec4 r, vec4 g, vec4 b, vec3 e_n, vec3 n, vec3 m) {
    vec3 fix = e_n - sp_sh_irradiance(r, g, b, n);
    return max(sp_sh_irradiance(r, g, b, m) + fix * max(dot(m, n), 0.0), vec3(0.0));
}

// Interpolation weight of a probe (position pp, normal n) for the surface point P (geometric
// normal Ng, view depth `depth`) with bilinear weight b: how well P lies in the probe's plane
// (exp(-(|n·(P - p)| / (tol · depth))²)) and how far the normals agree (max(0, Ng·n)^4).
float sp_probe_weight(float b, vec3 pp, vec3 n, vec3 P, vec3 Ng, float depth, float tol) {
    float pd = abs(dot(n, P - pp)) / (tol * depth);
    return max(b, 1e-3) * exp(-pd * pd) * pow(max(dot(Ng, n), 0.0), 4.0);
}

// The probes of the 2×2 tiles (of `tile` pixels, `grid` tiles) around pixel px: their summed
// weight for P, and (when `sh` is set) the weighted sums of their irradiance at N (E) and at R
// (ER, when `glossy`). pos/nrm: the probes; shr/shg/shb/shn: their SH and irradiance at the normal.
float sp_gather_grid(sampler2D pos, sampler2D nrm, sampler2D shr, sampler2D shg, sampler2D shb, sampler2D shn,
                     bool sh, int tile, ivec2 grid, vec2 px, vec3 P, vec3 Ng, vec3 N, vec3 R, bool glossy,
                     float depth, float tol, inout vec3 E, inout vec3 ER) {
    vec2 f = px / float(tile) - 0.5;
    ivec2 t0 = ivec2(floor(f));
    vec2 fr = f - vec2(t0);
    float wsum = 0.0;
    for (int j = 0; j < 2; ++j)
        for (int i = 0; i < 2; ++i) {
            ivec2 t = clamp(t0 + ivec2(i, j), ivec2(0), grid - 1);
            vec4 pp = texelFetch(pos, t, 0);
            if (pp.w < 0.5) continue;
            vec3 n = texelFetch(nrm, t, 0).xyz;
            float b = (i == 0 ? 1.0 - fr.x : fr.x) * (j == 0 ? 1.0 - fr.y : fr.y);
            float w = sp_probe_weight(b, pp.xyz, n, P, Ng, depth, tol);
            if (w <= 1e-6) continue;
            wsum += w;
            if (!sh) continue;
            vec4 r = texelFetch(shr, t, 0), g = texelFetch(shg, t, 0), bb = texelFetch(shb, t, 0);
            vec3 en = texelFetch(shn, t, 0).rgb;
            E += w * sp_irradiance(r, g, bb, en, n, N);
            if (glossy) ER += w * sp_irradiance(r, g, bb, en, n, R);
        }
    return wsum;
}

#endif
