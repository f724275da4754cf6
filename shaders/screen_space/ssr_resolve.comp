// ssr_resolve.comp — SSR resolve: importance-sampled rays shared between neighbours.
// Paper: Stachowiak 2015 ("Stochastic screen-space reflections", the ratio estimator).
// Each full-resolution pixel reuses the rays of u_resolve_samples neighbouring (scaled)
// pixels, its own included, within a radius that grows with roughness. A neighbour's ray
// is weighted by this pixel's glossy BSDF x cosine in the direction of the neighbour's hit
// divided by the pdf the neighbour drew it with, w = D(H) G2 / (4 NoV pdf) (the Fresnel
// term and the specular albedo are left out: they vary little over the lobe and the
// composite multiplies by the specular albedo). This pixel's own ray uses its own sampled
// direction, whose weight has the closed form G2 / G1(V) (D and the pdf cancel), so a
// near-mirror degenerates gracefully to its own ray with the right weight: a neighbour's
// direction lies outside a mirror's lobe (D ~ 0) and drops out. D is evaluated in a form
// that does not overflow (ss_ggx_D, common.glsl). At a reduced trace scale only the pixel
// the ray was traced from counts it as its own. (Before: a mirror's pdf overflowed to
// inf, every weight was 0 or NaN, and the pixel fell back to its own ray unweighted.)
// Hits carry the hit pixel's reflected direct light aov.direct (one bounce; the emission
// of hit emitters is already in DIRECT's glossy term) times their confidence (edge and
// distance fades). Misses (the ray left the screen, went behind everything or too far)
// carry nothing here: the fallback for the missing share (the composite's, in proportion
// 1 - a) is SSR_MISS's o_fallback below, or without it DIRECT's own world reflection,
// shadowed by its world-light maps (aov.world_spec). So a ray fading out at the screen edge blends into the world
// reflection without a seam, and a miss indoors is not lit by the unshadowed sky.
// Output: rgb = sum(w conf L_hit) / sum(w) (demodulated incident radiance of the hits),
// a = sum(w conf) / sum(w) (the share of the lobe found on screen); both 0 where there is
// no glossy lobe or the surface is rougher than u_max_roughness (DIRECT's term stays).
// o_hit_dist: the found hits' mean distance (same weights; 0 = none), with which the
// temporal pass reprojects the reflection by the reflected point.
// SSR_MISS (SSR's own chain): o_fallback, the glossy light (times the
// specular albedo, the composite's units) for the share 1 - a of the lobe not found: the
// same neighbours' rays traced through the scene (ssr_miss.comp, u_miss), each weighted by
// w (1 - conf), i.e. the ratio estimator restricted to the missed share; where no ray of
// this frame missed (all found, a < 1 only through the temporal mean), the mean over every
// traced ray (w); where no ray was traced (too rough, no glossy lobe, miss_trace off) DIRECT's
// aov.world_spec, so that the composite's result is then exactly the one without the trace.
// o_miss_dist: how far behind the surface the fallback's reflected point lies, for its own
// temporal pass (ssr_fallback_temporal, reprojected like ssr_temporal by the virtual image
// point): the rays' distances (ssr_miss.comp; escaped rays count as far away) averaged as
// parallax, 1 / (camera distance + length), with the fallback's weights; 0 = no ray.
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/rng.glsl"
#include "lib/sampling.glsl"
#include "lib/brdf.glsl"
#include "lib/screen.glsl"
#include "screen_space/common.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba16f) uniform writeonly image2D o_spec;
layout(binding = 1, r32f) uniform writeonly image2D o_hit_dist;  // weighted mean hit distance, 0 = none

uniform sampler2D u_ray0;
uniform sampler2D u_ray1;
uniform sampler2D u_radiance;
#ifdef SSR_MISS
layout(binding = 2, rgba32f) uniform writeonly image2D o_fallback;
layout(binding = 3, r32f) uniform writeonly image2D o_miss_dist;  // the fallback's reflected distance, 0 = none
uniform sampler2D u_miss;        // ssr_miss.comp: radiance along each traced ray, a = 1 traced
uniform sampler2D u_world_spec;  // DIRECT's shadowed world reflection
#define STORE_FALLBACK(v) imageStore(o_fallback, px, vec4(v, 1.0))
#else
#define STORE_FALLBACK(v)
#endif
uniform int u_resolve_samples;
uniform float u_max_roughness;
uniform int u_rough_trace;   // 1: rougher surfaces take their whole lobe from the miss trace

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    ivec2 osize = imageSize(o_spec);
    if (any(greaterThanEqual(px, osize))) return;
    GPixel g = fetch_g(px);
    imageStore(o_hit_dist, px, vec4(0.0));
#ifdef SSR_MISS
    vec3 world_spec = texelFetch(u_world_spec, px, 0).rgb;
#endif
    STORE_FALLBACK(world_spec);
#ifdef SSR_MISS
    imageStore(o_miss_dist, px, vec4(0.0));
#endif
    if (!g.valid) { imageStore(o_spec, px, vec4(0.0)); return; }
    Surface s = fetch_surface(px, g.mid);
    vec3 V = view_dir(g.P);
    vec3 N = g.N;
    float NoV = max(dot(N, V), 1e-4);
    if (max3(specular_albedo(s, NoV)) < 1e-4) { imageStore(o_spec, px, vec4(0.0)); return; }
    bool rough = s.roughness > u_max_roughness;
    if (rough && u_rough_trace == 0) { imageStore(o_spec, px, vec4(0.0)); return; }
    ivec2 rsize = textureSize(u_ray0, 0);
    vec2 scale = vec2(rsize) / u_resolution;
    ivec2 qc = min(ivec2((vec2(px) + 0.5) * scale), rsize - 1);
    vec4 rnd = pixel_noise(px, 22u);
    float radius = 1.0 + 3.0 * s.roughness;
    float a2 = s.alpha * s.alpha;
    vec3 sum = vec3(0.0);
    float cover = 0.0, wsum = 0.0, dsum = 0.0;
#ifdef SSR_MISS
    vec3 msum = vec3(0.0), tsum = vec3(0.0);
    float mw = 0.0, tw = 0.0, mpar = 0.0, tpar = 0.0;
    float dcam = length(g.P - u_camera_pos);
#endif
    int n = max(u_resolve_samples, 1);
    for (int k = 0; k < n; ++k) {
        ivec2 qq = qc;
        if (k > 0) {
            float a = TWO_PI * (float(k) * 0.618034 + rnd.x);
            float r = radius * sqrt((float(k) - 0.5 + rnd.y) / float(n));
            qq = clamp(qc + ivec2(round(r * vec2(cos(a), sin(a)))), ivec2(0), rsize - 1);
            if (qq == qc) continue;   // the own ray is sample 0
        }
        vec4 r0 = texelFetch(u_ray0, qq, 0);
        if (!(r0.w > 0.0)) continue;
        vec4 r1 = texelFetch(u_ray1, qq, 0);
        vec3 L = r0.xyz;
        bool found = r1.z > 0.0 && !rough;   // a rough pixel takes nothing from the screen
        // the closed-form weight holds only for a ray drawn from this pixel's own lobe; at a
        // reduced trace scale the ray at qc was traced from another pixel (ssr_trace's
        // mapping) unless that pixel is this one, and is weighted like a neighbour's
        bool own = k == 0 && ivec2((vec2(qc) + 0.5) * u_resolution / vec2(rsize)) == px;
        vec3 Lhit = vec3(0.0);
        float conf = 0.0, hdist = 0.0;
        if (found) {
            ivec2 hp = ivec2(r1.xy);
            GPixel h = fetch_g(hp);
            vec3 d = h.P - g.P;
            hdist = length(d);
            if (!own && dot(d, d) > 1e-10) L = normalize(d);
            Lhit = texelFetch(u_radiance, hp, 0).rgb;
            conf = clamp(r1.z, 0.0, 1.0) * view_trust(h, hp, -L);
        }
        float NoL = dot(N, L);
        if (NoL <= 0.0) continue;
        float G2 = ggx_V(NoV, NoL, a2) * 4.0 * NoV * NoL;
        float w;
        if (own) {
            w = G2 / ggx_G1(NoV, a2);                       // own ray: f cos / pdf in closed form
        } else {
            w = ss_ggx_D(N, normalize(V + L), a2) * G2 / (4.0 * NoV * r0.w);
        }
        if (!(w > 0.0) || isinf(w)) continue;
        sum += w * conf * Lhit;
        cover += w * conf;
        dsum += w * conf * hdist;
        wsum += w;
#ifdef SSR_MISS
        vec4 lm = texelFetch(u_miss, qq, 0);
        if (lm.a > 0.0) {
            // parallax of the virtual image point ~ 1 / (camera distance + ray length)
            // (lm.a: the ray's light-weighted distance, ssr_miss.comp)
            float par = 1.0 / (dcam + lm.a);
            msum += w * (1.0 - conf) * lm.rgb;
            mpar += w * (1.0 - conf) * par;
            mw += w * (1.0 - conf);
            tsum += w * lm.rgb;
            tpar += w * par;
            tw += w;
        }
#endif
    }
#ifdef SSR_MISS
    vec3 ks = specular_albedo(s, NoV);
    float par = 0.0;
    if (mw > 1e-6 * tw && mw > 0.0) { STORE_FALLBACK(sanitize(ks * msum / mw)); par = mpar / mw; }
    else if (tw > 0.0) { STORE_FALLBACK(sanitize(ks * tsum / tw)); par = tpar / tw; }
    // distance behind the mirror of the point whose parallax is the rays' mean parallax
    if (par > 0.0) imageStore(o_miss_dist, px, vec4(max(1.0 / par - dcam, 1e-4)));
#endif
    imageStore(o_hit_dist, px, vec4(cover > 1e-6 ? dsum / cover : 0.0));
    vec3 res = wsum > 0.0 ? sum / wsum : vec3(0.0);
    float a = wsum > 0.0 ? clamp(cover / wsum, 0.0, 1.0) : 0.0;
    imageStore(o_spec, px, vec4(sanitize(res), a));
}
