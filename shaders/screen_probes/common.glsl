// screen_probes/common.glsl — screen-space radiance probes (GI10; SCREEN_PROBES can share them):
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
// Directions: texel (i, j) of a probe is one stratum of the hemisphere, uniform in solid
// angle (cos θ in [i, i+1] / res, φ in [j, j+1] / res · 2π), jittered per probe and frame by a
// hash, so the SH projection of a frame is an unbiased estimate (2π / res² per sample).
#ifndef GI_SCREEN_PROBES_GLSL
#define GI_SCREEN_PROBES_GLSL

#include "lib/sh.glsl"

uniform int u_sp_tile;       // pixels per probe tile side
uniform int u_sp_res;        // ray texels per probe side
uniform ivec2 u_sp_grid;     // probe tiles (x, y)
uniform uint u_sp_frame;     // the probes' own frame counter (refresh pattern, jitter)

bool sp_in_grid(ivec2 t) { return all(greaterThanEqual(t, ivec2(0))) && all(lessThan(t, u_sp_grid)); }

// Direction of texel `k` (in [0, res)^2) of probe `t` with normal n this frame.
vec3 sp_ray_dir(ivec2 t, ivec2 k, vec3 n, uint frame) {
    uvec4 h = pcg4d(uvec4(uvec2(t), uint(k.x + k.y * u_sp_res), frame));
    vec2 u = (vec2(k) + vec2(h.xy >> 8u) * (1.0 / 16777216.0)) / float(u_sp_res);
    float z = u.x, r = sqrt(max(1.0 - z * z, 0.0)), phi = TWO_PI * u.y;
    return to_world(vec3(r * cos(phi), r * sin(phi), z), n);
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

#endif
