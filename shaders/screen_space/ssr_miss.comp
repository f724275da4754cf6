// ssr_miss.comp — SSR's miss trace: each (scaled) pixel's reflection ray,
// the one ssr_trace.comp drew from the GGX lobe and marched on screen, traced again through
// the scene's BVH with the shared ray tracer (lib/scene_rt.glsl), so that the share of the
// lobe the screen did not find gets the light of what the ray really meets, hidden or off
// screen, instead of DIRECT's shadowed world reflection (~0 where hidden geometry blocks the
// ray). Run by SSRTracePass as its second dispatch (after a barrier: it reads the rays the
// first one stored).
// Radiance along the ray towards the reflecting pixel:
//   hit: direct light at the hit, next-event estimation (shade_direct: one light by power, one
//        point on it, one shadow ray; the hit's full BSDF seen from -L; at a glossy hit also one
//        BSDF-sampled ray for the lights it meets, MIS-weighted as in PT: the largest sample of a
//        light's highlight seen in the corridor's mirror floor 98 -> 52 over 12 frames), plus the world's light
//        on it with one cosine-sampled visibility ray (a uniform world times its diffuse and glossy
//        albedos where that ray escapes; as DIRECT lights a pixel by the world). A hit smoother
//        than SSR_MISS_GLOSSY_MIN_ROUGHNESS (0.15) is shaded diffuse-only: one light sample of a
//        near-mirror lobe is a firefly path (corridor, q1: the gold wall, which sees the mirror
//        floor, relMSE 0.107 -> 0.188 with its glossy lobe, 0.105 without; a sun glint on a roughness-0.1 ball
//        seen in a mirror: one 4.4 pixel in 2 frames; docs SSR.md). Emission of
//        a hit emitter is NOT added: its glossy reflection is already in DIRECT's MIS glossy
//        term, which SSR does not replace (only the world reflection aov.world_spec).
//   miss (escapes): the world radiance along the ray (the sun disks are DIRECT's lights).
// In:  u_ray0 (direction, pdf; pdf 0 = no ray), u_ray1 (hit pixel, confidence, distance).
// Out: o_miss = (radiance, distance to the hit > 0; SSR_MISS_ESCAPE_DIST where the ray escapes)
//      for a traced ray, 0 where there is none; with SSR_MISS_OFF
//      (param miss_trace = 0) 0 everywhere, and the resolve keeps aov.world_spec.
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/rng.glsl"
#include "lib/sampling.glsl"
#include "lib/brdf.glsl"
#include "lib/lights.glsl"
#include "lib/screen.glsl"
#include "screen_space/common.glsl"
#ifndef SSR_MISS_OFF
#include "lib/scene_rt.glsl"
#endif

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform readonly image2D u_ray0;
layout(binding = 1, rgba32f) uniform readonly image2D u_ray1;
layout(binding = 2, rgba16f) uniform writeonly image2D o_miss;
uniform int u_shade_samples;   // light/BSDF/world samples per hit (param miss_samples / _moving)

#ifndef SSR_MISS_OFF
// the distance stored for a ray that escapes (its light comes from infinitely far: a virtual
// image this far behind the mirror barely moves with the camera, like the sky)
#define SSR_MISS_ESCAPE_DIST 1000.0
// the direct light at a hit: shade_direct_split (lib/scene_rt.glsl) also returns the glossy
// share and the light's distance (see gdist below)
// t: the distance to the hit (SSR_MISS_ESCAPE_DIST: escaped). gdist: the distance the
// reflected light's image lies behind the reflecting pixel, as one parallax: a hit's light is
// where the hit is (t), except what its glossy lobe reflects from a light, whose image lies at
// the unfolded path length t + distance to the light (a highlight moves with the viewpoint
// over the hit's surface; on the corridor test scene the gold wall's highlights seen in the mirror
// floor lagged behind when reprojected by the wall point). The parallaxes 1 / (dcam + d) are
// averaged weighted by luminance. SSR_MISS_HIT_PARALLAX: gdist = t (the hit's own distance only).
vec3 miss_radiance(vec3 O, vec3 L, float dcam, inout Rng rng, out float t, out float gdist) {
    SurfaceHit s;
    t = SSR_MISS_ESCAPE_DIST;
    gdist = t;
    if (!scene_trace(O, L, 0.0, T_INF, s)) return world_radiance(L);
    t = clamp(s.t, 1e-3, SSR_MISS_ESCAPE_DIST);
    gdist = t;
    vec3 V = -L, Nh, Ngh, ph;
    surface_frame(s, V, Nh, Ngh, ph);
    Surface bs = s.bsdf;
#ifndef SSR_MISS_GLOSSY_MIN_ROUGHNESS
#define SSR_MISS_GLOSSY_MIN_ROUGHNESS 0.15
#endif
    bool glossy = bs.roughness >= SSR_MISS_GLOSSY_MIN_ROUGHNESS;
    if (!glossy) bs = surface_diffuse_only(bs, max(dot(Nh, V), 1e-4));
#ifndef SSR_MISS_NO_MIS
    // a glossy hit: one light sample and one BSDF sample, MIS-weighted (power heuristic), as PT
    // does at every bounce: a glossy lobe narrower than an area light's solid angle is found by
    // the BSDF sample without the light sample's fireflies
    glossy = glossy && lobe_weights(bs, max(dot(Nh, V), 1e-4)).y > 0.05;
#else
    glossy = false;
#endif
    // u_shade_samples light/BSDF/world samples at the hit (more while the camera moves and
    // the fallback's history is short: the trace is shared, the shading noise divides)
    vec3 c = vec3(0.0);
    float lum_g = 0.0, tl = 0.0;   // glossy light's luminance, its luminance-weighted light distance
    int ns = max(u_shade_samples, 1);
    for (int k = 0; k < ns; ++k) {
        vec3 cg;
        float ldist;
        c += shade_direct_split(bs, ph, Nh, Ngh, V, rng, glossy, cg, ldist);
        float lg = luminance(cg);
        if (lg > 0.0) {
            tl = (tl * lum_g + min(ldist, SSR_MISS_ESCAPE_DIST) * lg) / (lum_g + lg);
            lum_g += lg;
        }
        if (glossy) {
            vec3 gb, Lb;
            float t_b;
            c += bsdf_sample_lights(bs, ph, Nh, Ngh, V, rng, gb, Lb, t_b);
            // the light this ray met: its distance to the light's centre (emitting surfaces: the hit)
            float lb = luminance(gb);
            if (lb > 0.0) {
                bool hb = t_b < T_INF;
                float tb = hb ? t_b : 0.0;
                for (int i = 0; i < u_light_count; ++i) {
                    vec3 le;
                    float lp;
                    if (light_ray_hit(lights[i], ph, Lb, 0.0, hb ? t_b : T_INF, le, lp)) {
                        tb = int(lights[i].pos_type.w + 0.5) == LIGHT_SUN ? SSR_MISS_ESCAPE_DIST
                                                                           : length(lights[i].pos_type.xyz - ph);
                        break;
                    }
                }
                tl = (tl * lum_g + tb * lb) / (lum_g + lb);
                lum_g += lb;
            }
        }
        if (u_world_select <= 0.0 && max3(u_world_color) > 0.0) {
            vec4 u = rng_next4(rng);
            vec3 d = to_world(sample_cosine_hemisphere(u.xy), Nh);
            if (dot(d, Ngh) > 0.0 && !scene_occluded(ph, d, 0.0, T_INF)) {
                float NoV = max(dot(Nh, V), 1e-4);
                c += u_world_color * (diffuse_albedo(bs, NoV) + specular_albedo(bs, NoV));
            }
        }
    }
    c /= float(ns);
    lum_g /= float(ns);
#ifndef SSR_MISS_HIT_PARALLAX
    float lum = luminance(c);
    if (lum_g > 0.0 && lum > 0.0) {
        float fg = clamp(lum_g / lum, 0.0, 1.0);
        float par = (1.0 - fg) / (dcam + t) + fg / (dcam + min(t + tl, SSR_MISS_ESCAPE_DIST));
        gdist = clamp(1.0 / par - dcam, t, SSR_MISS_ESCAPE_DIST);
    }
#endif
    return c;
}
#endif

void main() {
    ivec2 q = ivec2(gl_GlobalInvocationID.xy);
    ivec2 osize = imageSize(o_miss);
    if (any(greaterThanEqual(q, osize))) return;
#ifdef SSR_MISS_OFF
    imageStore(o_miss, q, vec4(0.0));
#else
    vec4 r0 = imageLoad(u_ray0, q);
    if (!(r0.w > 0.0)) { imageStore(o_miss, q, vec4(0.0)); return; }
    ivec2 px = ivec2((vec2(q) + 0.5) * u_resolution / vec2(osize));
    GPixel g = fetch_g(px);
    if (!g.valid) { imageStore(o_miss, q, vec4(0.0)); return; }
    // from the G-buffer point moved off the surface (scale-aware, as DIRECT's shadow rays)
    vec3 O = rt_offset_ray(g.P + g.Ng * (2e-5 * length(g.P - u_camera_pos) + 1e-6), g.Ng);
    Rng rng = rng_init(uvec2(px), u_sample, 31u);
    float t, gdist;
    vec3 Lm = sanitize(miss_radiance(O, normalize(r0.xyz), length(g.P - u_camera_pos), rng, t, gdist));
    imageStore(o_miss, q, vec4(Lm, gdist));
#endif
}
