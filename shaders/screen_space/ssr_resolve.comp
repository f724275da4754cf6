// ssr_resolve.comp — SSR resolve: importance-sampled rays shared between neighbours.
// Paper: Stachowiak 2015 ("Stochastic screen-space reflections", the ratio estimator).
// Each full-resolution pixel reuses the rays of u_resolve_samples neighbouring (scaled)
// pixels, its own included, within a radius that grows with roughness: a neighbour's hit
// point seen from this pixel gives a direction L, weighted by this pixel's glossy BSDF
// times cosine divided by the pdf the neighbour drew its ray with; missed rays use the
// neighbour's direction and the fallback (the uniform world radiance). The weighted mean of
// the incident radiance is the demodulated reflection; the composite multiplies it by the
// specular albedo and subtracts DIRECT's world glossy term, which it replaces. Radiance at
// hits is aov.direct (reflected direct light; the emission of hit emitters is already in
// DIRECT's glossy term), so this is one bounce.
// Output: rgb = demodulated specular incident radiance, a = 1 where SSR replaces DIRECT's
// world reflection; 0 (rgb 0) where there is no glossy lobe or the surface is rougher than
// u_max_roughness (DIRECT's shadowed world reflection is kept there).
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/rng.glsl"
#include "lib/sampling.glsl"
#include "lib/brdf.glsl"
#include "lib/screen.glsl"
#include "screen_space/common.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba16f) uniform writeonly image2D o_spec;

uniform sampler2D u_ray0;
uniform sampler2D u_ray1;
uniform sampler2D u_radiance;
uniform int u_resolve_samples;
uniform float u_max_roughness;

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    ivec2 osize = imageSize(o_spec);
    if (any(greaterThanEqual(px, osize))) return;
    GPixel g = fetch_g(px);
    if (!g.valid) { imageStore(o_spec, px, vec4(0.0)); return; }
    Surface s = fetch_surface(px, g.mid);
    vec3 V = view_dir(g.P);
    vec3 N = g.N;
    float NoV = max(dot(N, V), 1e-4);
    if (max3(specular_albedo(s, NoV)) < 1e-4) { imageStore(o_spec, px, vec4(0.0)); return; }
    if (s.roughness > u_max_roughness) { imageStore(o_spec, px, vec4(0.0)); return; }
    ivec2 rsize = textureSize(u_ray0, 0);
    vec2 scale = vec2(rsize) / u_resolution;
    ivec2 qc = min(ivec2((vec2(px) + 0.5) * scale), rsize - 1);
    vec4 rnd = pixel_noise(px, 22u);
    float radius = 1.0 + 3.0 * s.roughness;
    vec3 sum = vec3(0.0);
    float wsum = 0.0;
    vec3 own = u_world;
    int n = max(u_resolve_samples, 1);
    for (int k = 0; k < n; ++k) {
        ivec2 qq = qc;
        if (k > 0) {
            float a = TWO_PI * (float(k) * 0.618034 + rnd.x);
            float r = radius * sqrt((float(k) - 0.5 + rnd.y) / float(n));
            qq = clamp(qc + ivec2(round(r * vec2(cos(a), sin(a)))), ivec2(0), rsize - 1);
        }
        vec4 r0 = texelFetch(u_ray0, qq, 0);
        if (!(r0.w > 0.0)) continue;
        vec4 r1 = texelFetch(u_ray1, qq, 0);
        vec3 L = r0.xyz;
        vec3 Li = u_world;
        if (r1.z > 0.0) {
            ivec2 hp = ivec2(r1.xy);
            vec3 Ph = texelFetch(u_gb_position, hp, 0).xyz;
            vec3 d = Ph - g.P;
            if (dot(d, d) > 1e-10) L = normalize(d);
            Li = mix(u_world, texelFetch(u_radiance, hp, 0).rgb, clamp(r1.z, 0.0, 1.0));
        }
        if (k == 0) own = Li;
        float w = luminance(eval_principled(s, N, V, L).glossy) / r0.w;
        if (!(w > 0.0) || isinf(w)) continue;
        sum += w * Li;
        wsum += w;
    }
    vec3 res = wsum > 0.0 ? sum / wsum : own;
    imageStore(o_spec, px, vec4(sanitize(res), 1.0));
}
