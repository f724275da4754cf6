// composite.comp — adds a screen-space technique's indirect light to DIRECT's colour.
// DIRECT already holds all direct light, the world's included (shadowed by its world-light
// maps), so the composites add only what DIRECT lacks:
// MODE_AO (SSAO, HBAO; Mittring 2007, Bavoil et al. 2008): the survey's ambient term, AO
//   times a constant one-or-more-bounce estimate from the screen means (radiosity's ambient
//   term): L_amb = B * e * sum_{k<bounces} (rho * e)^k (B mean direct-lit radiance, e mean
//   enclosure 1-AO, rho mean diffuse albedo); diffuse: albedo_d * AO * L_amb.
// MODE_SSDO (Ritschel et al. 2009): diffuse albedo_d * one bounce from on-screen senders.
// MODE_SSR (McGuire & Mara 2014, Stachowiak 2015): the resolved radiance of the hits found
//   on screen (rgb, weighted by their confidence) covers the share a of the lobe; the rest,
//   1 - a (misses, untrusted hits, too rough: a = 0), takes the fallback u_fallback (default
//   DIRECT's shadowed world reflection aov.world_spec; a probe technique can pass its own),
//   and both replace the glossy terms already in colour (u_replaced0..N_REPLACED-1, default
//   aov.world_spec): add = ks * rgb + (1 - a) * fallback - replaced. a varies smoothly
//   (confidence fades, temporal mean), so found and fallback blend without a seam.
// Reads and writes "color" in place; writes the AO effect image (MODE_AO / MODE_SSDO) and
// the effect image: what this pass added (SSR: negative where on-screen geometry replaces
// DIRECT's world reflection by something darker).
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/rng.glsl"
#include "lib/sampling.glsl"
#include "lib/brdf.glsl"
#include "lib/screen.glsl"
#include "screen_space/common.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform image2D io_color;
layout(binding = 1, rgba32f) uniform writeonly image2D o_ao;
layout(binding = 2, rgba32f) uniform writeonly image2D o_effect;  // what this pass adds (effect AOV)

uniform sampler2D u_signal;
#ifdef MODE_SSR
uniform sampler2D u_fallback;    // glossy light for the share not found (default aov.world_spec)
uniform sampler2D u_replaced0;   // glossy terms already in colour that SSR replaces (N_REPLACED)
uniform sampler2D u_replaced1;
#endif
#ifdef MODE_AO
uniform sampler2D u_stats0;
uniform sampler2D u_stats1;
uniform float u_stats_lod;
uniform int u_ambient_bounces;
#endif

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(px, imageSize(io_color)))) return;
    GPixel g = fetch_g(px);
    if (!g.valid) {
#if defined(MODE_AO) || defined(MODE_SSDO)
        imageStore(o_ao, px, vec4(1.0));
#endif
        imageStore(o_effect, px, vec4(0.0, 0.0, 0.0, 1.0));
        return;
    }
    Surface s = fetch_surface(px, g.mid);
    float NoV = max(dot(g.N, view_dir(g.P)), 1e-4);
    vec3 kd = diffuse_albedo(s, NoV);
    vec3 ks = specular_albedo(s, NoV);
    vec4 sig = texelFetch(u_signal, px, 0);
    vec3 add = vec3(0.0);
#ifdef MODE_AO
    float ao = clamp(sig.r, 0.0, 1.0);
    vec4 m0 = textureLod(u_stats0, vec2(0.5), u_stats_lod);
    vec4 m1 = textureLod(u_stats1, vec2(0.5), u_stats_lod);
    vec3 Lamb = vec3(0.0);
    if (m0.a > 1e-6 && u_ambient_bounces > 0) {
        vec3 B = m0.rgb / m0.a;
        float rho = clamp(m1.x / m0.a, 0.0, 0.95);
        float e = clamp(m1.y / m0.a, 0.0, 1.0);
        float series = 0.0, term = 1.0;
        for (int k = 0; k < u_ambient_bounces; ++k) { series += term; term *= rho * e; }
        Lamb = B * e * series;
    }
    add = kd * ao * Lamb;
    imageStore(o_ao, px, vec4(vec3(ao), 1.0));
#endif
#ifdef MODE_SSDO
    float vis = clamp(sig.a, 0.0, 1.0);
    add = kd * max(sig.rgb, vec3(0.0));
    imageStore(o_ao, px, vec4(vec3(vis), 1.0));
#endif
#ifdef MODE_SSR
    float found_share = clamp(sig.a, 0.0, 1.0);
    vec3 replaced = vec3(0.0);
#if N_REPLACED > 0
    replaced += texelFetch(u_replaced0, px, 0).rgb;
#endif
#if N_REPLACED > 1
    replaced += texelFetch(u_replaced1, px, 0).rgb;
#endif
    add = ks * max(sig.rgb, vec3(0.0)) + (1.0 - found_share) * texelFetch(u_fallback, px, 0).rgb - replaced;
#endif
    vec4 c = imageLoad(io_color, px);
    vec3 total = sanitize(c.rgb + add);
    imageStore(io_color, px, vec4(total, c.a));
    imageStore(o_effect, px, vec4(total - c.rgb, 1.0));
}
