// gather.comp — per pixel: the indirect light from the screen probes, added to DIRECT's colour.
// The probes of the 2×2 tiles around the pixel are weighted bilinearly, by how well the pixel
// lies in the probe's plane (exp(-(|n_p·(P - p)| / (tol · depth))²)) and by how far the normals
// agree (max(0, N·n_p)^4); E = the weighted mean of their (spatially filtered) SH irradiance at
// the pixel's normal. Where the probes' weight w is below u_min_weight (no probe shares the
// pixel's surface: interpolation failed), the world radiance cache's irradiance at the pixel
// makes up the rest (E = (Σ w_p E_p + (w_min - Σ w_p) E_cache) / w_min), the cell being
// requested when missing (GI-1.0's fallback; SP_ADAPTIVE: first the adaptive probes placed
// where the coarse ones fail), if the point its entry traces from is visible
// from the pixel (radiance_cache/common.glsl: a cell may straddle a thin wall). Diffuse: color += kd · E / π; glossy (u_glossy):
// color += ks · E(R) / π, the same probes read at the mirror direction (blurry, as RTXGI's).
// Render passes: o_diffuse, o_glossy, o_effect (their sum); debug views o_view_probes (the
// interpolated irradiance E/π, each probe drawn as a dot: green kept, yellow refreshed this
// frame, red new; SP_ADAPTIVE: blue for the adaptive probes) and o_view_cache (the cache cell of each pixel in a colour of its own,
// brighter with more samples; black: no entry).
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/rng.glsl"
#include "lib/sampling.glsl"
#include "lib/brdf.glsl"
#include "lib/lights.glsl"
#include "lib/scene_rt.glsl"
#include "lib/screen.glsl"
#include "screen_space/common.glsl"
#include "radiance_cache/common.glsl"
#include "screen_probes/common.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform image2D io_color;
layout(binding = 1, rgba32f) uniform writeonly image2D o_effect;
layout(binding = 2, rgba32f) uniform writeonly image2D o_diffuse;
layout(binding = 3, rgba32f) uniform writeonly image2D o_glossy;
layout(binding = 4, rgba32f) uniform writeonly image2D o_view_probes;
layout(binding = 5, rgba32f) uniform writeonly image2D o_view_cache;
uniform sampler2D u_sp_pos;
uniform sampler2D u_sp_nrm;
uniform sampler2D u_sh_r;
uniform sampler2D u_sh_g;
uniform sampler2D u_sh_b;
uniform sampler2D u_sh_n;
uniform float u_sp_plane_tol;
uniform float u_min_weight;
uniform int u_glossy;      // 1: glossy indirect light from the probes
uniform int u_cache;
uniform int u_debug;
#ifdef SP_ADAPTIVE
uniform sampler2D u_fine_pos;
uniform sampler2D u_fine_nrm;
uniform sampler2D u_fine_sh_r;
uniform sampler2D u_fine_sh_g;
uniform sampler2D u_fine_sh_b;
uniform sampler2D u_fine_sh_n;
uniform int u_fine_tile;
uniform ivec2 u_fine_grid;
#endif

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    ivec2 size = imageSize(io_color);
    if (any(greaterThanEqual(px, size))) return;
    GPixel g = fetch_g(px);
    vec4 c = imageLoad(io_color, px);
    vec3 diff = vec3(0.0), gloss = vec3(0.0), field = vec3(0.0);
    if (g.valid) {
        Surface s = fetch_surface(px, g.mid);
        vec3 V = view_dir(g.P);
        float NoV = max(dot(g.N, V), 1e-4);
        vec3 R = reflect(-V, g.N);
        bool glossy = u_glossy != 0 && max3(specular_albedo(s, NoV)) > 0.0;
        float depth = max(view_depth(g.P), 1e-4);
        vec3 E = vec3(0.0), ER = vec3(0.0);
        float wsum = sp_gather_grid(u_sp_pos, u_sp_nrm, u_sh_r, u_sh_g, u_sh_b, u_sh_n, true, u_sp_tile, u_sp_grid,
                                    vec2(px) + 0.5, g.P, g.Ng, g.N, R, glossy, depth, u_sp_plane_tol, E, ER);
#ifdef SP_ADAPTIVE
        if (wsum < u_min_weight) {  // the adaptive probes placed where these fail
            vec3 Ef = vec3(0.0), ERf = vec3(0.0);
            float wf = sp_gather_grid(u_fine_pos, u_fine_nrm, u_fine_sh_r, u_fine_sh_g, u_fine_sh_b, u_fine_sh_n, true,
                                      u_fine_tile, u_fine_grid, vec2(px) + 0.5, g.P, g.Ng, g.N, R, glossy, depth,
                                      u_sp_plane_tol, Ef, ERf);
            if (wf > 1e-4) {
                float k = u_min_weight - wsum;
                E += k * Ef / wf;
                ER += k * ERf / wf;
                wsum = u_min_weight;
            }
        }
#endif
        if (wsum < u_min_weight && u_cache != 0) {
            float smp;
            vec3 Ec = rc_irradiance(g.P, g.Ng, true, smp);  // (visibility-checked)
            bool ok = smp > 0.0;
            if (ok) {
                float k = u_min_weight - wsum;
                E = (E + k * Ec) / u_min_weight;
                ER = (ER + k * Ec) / u_min_weight;
            } else if (wsum > 0.0) {
                E /= wsum;
                ER /= wsum;
            }
        } else if (wsum > 0.0) {
            E /= wsum;
            ER /= wsum;
        }
        field = E * INV_PI;
        diff = diffuse_albedo(s, NoV) * field;
        if (glossy) gloss = specular_albedo(s, NoV) * ER * INV_PI;
    }
    vec3 total = sanitize(c.rgb + diff + gloss);
    imageStore(io_color, px, vec4(total, c.a));
    imageStore(o_effect, px, vec4(total - c.rgb, 1.0));
    imageStore(o_diffuse, px, vec4(sanitize(diff), 1.0));
    imageStore(o_glossy, px, vec4(sanitize(gloss), 1.0));
    if (u_debug == 0) return;
    vec3 vp = g.valid ? field : vec3(0.0);
    ivec2 t = clamp(px / u_sp_tile, ivec2(0), u_sp_grid - 1);
    vec4 pp = texelFetch(u_sp_pos, t, 0);
    if (pp.w > 0.5 && distance(vec2(px) + 0.5, to_pixel(pp.xyz)) < max(1.0, float(u_sp_tile) * 0.08))
        vp = pp.w > 2.5 ? vec3(1.0, 0.1, 0.1) : (pp.w > 1.5 ? vec3(1.0, 0.9, 0.1) : vec3(0.1, 1.0, 0.2));
#ifdef SP_ADAPTIVE
    ivec2 tf = clamp(px / u_fine_tile, ivec2(0), u_fine_grid - 1);
    vec4 pf = texelFetch(u_fine_pos, tf, 0);
    if (pf.w > 0.5 && distance(vec2(px) + 0.5, to_pixel(pf.xyz)) < max(1.0, float(u_fine_tile) * 0.12))
        vp = vec3(0.2, 0.5, 1.0);
#endif
    imageStore(o_view_probes, px, vec4(vp, 1.0));
    vec3 vc = vec3(0.0);
    if (g.valid && u_cache != 0) {
        int i = rc_find(g.P, g.Ng, false);
        if (i >= 0) {
            uvec4 h = pcg4d(uvec4(uint(i), 7u, 11u, 13u));
            vec3 col = 0.25 + 0.75 * vec3(h.xyz & 255u) / 255.0;
            vc = col * min(rc_irr[i].w / 16.0, 1.0);
        }
    }
    imageStore(o_view_cache, px, vec4(vc, 1.0));
}
