// integrate.comp — one invocation per probe: this frame's rays projected on 2-band SH
// (1/N · Σ L(ω) Y(ω) / pdf(ω), screen_probes/common.glsl sp_ray) and integrated into the
// irradiance at the probe's normal (1/N · Σ L(ω) n·ω / pdf(ω): exact, where 2-band SH is not: it
// misses the third band of the cosine lobe, 25 % of a light at the normal), blended into the history
// the probe brought along (o_src: last frame's tile, -1 for a new probe) with weight
// max(1 / traces, u_sp_min_blend), raised to u_sp_fast_blend when the irradiance at the
// probe's normal moved by more than u_sp_change_threshold (relative: GI-1.0's blend driven by
// luminance change). A probe that did not trace this frame keeps its history as it is.
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/sampling.glsl"
#include "lib/rng.glsl"
#include "screen_probes/common.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform writeonly image2D o_sh_r;
layout(binding = 1, rgba32f) uniform writeonly image2D o_sh_g;
layout(binding = 2, rgba32f) uniform writeonly image2D o_sh_b;
layout(binding = 3, rgba32f) uniform writeonly image2D o_sh_n;
uniform sampler2D u_sp_pos;
uniform sampler2D u_sp_nrm;
uniform isampler2D u_sp_src;
uniform sampler2D u_sp_atlas;
uniform sampler2D u_prev_sh_r;
uniform sampler2D u_prev_sh_g;
uniform sampler2D u_prev_sh_b;
uniform sampler2D u_prev_sh_n;
uniform float u_sp_min_blend;
uniform float u_sp_fast_blend;
uniform float u_sp_change_threshold;

void main() {
    ivec2 t = ivec2(gl_GlobalInvocationID.xy);
    if (!sp_in_grid(t)) return;
    vec4 pp = texelFetch(u_sp_pos, t, 0);
    vec4 pn = texelFetch(u_sp_nrm, t, 0);
    int src = texelFetch(u_sp_src, t, 0).x;
    vec4 hr = vec4(0.0), hg = vec4(0.0), hb = vec4(0.0), hn = vec4(0.0);
    if (src >= 0) {
        ivec2 q = ivec2(src % u_sp_grid.x, src / u_sp_grid.x);
        hr = finite_or_zero(texelFetch(u_prev_sh_r, q, 0));
        hg = finite_or_zero(texelFetch(u_prev_sh_g, q, 0));
        hb = finite_or_zero(texelFetch(u_prev_sh_b, q, 0));
        hn = finite_or_zero(texelFetch(u_prev_sh_n, q, 0));
    }
    if (pp.w > 1.5) {
        vec3 n = normalize(pn.xyz);
        vec4 fr = vec4(0.0), fg = vec4(0.0), fb = vec4(0.0);
        vec3 fn = vec3(0.0);
        if (u_sp_importance != 0) sp_build_cdf(hr, hg, hb, n, src >= 0);  // as the trace drew its rays
        int N = sp_strata();
        for (int k = 0; k < N; ++k) {
            vec3 L = finite_or_zero(texelFetch(u_sp_atlas, t * u_sp_res + ivec2(k % u_sp_res, k / u_sp_res), 0)).rgb;
            float pdf;
            vec3 d = sp_ray(t, k, n, u_sp_frame, pdf);
            float w = 1.0 / (float(N) * max(pdf, 1e-8));
            vec4 y = sh_basis(d) * w;
            fr += L.r * y;
            fg += L.g * y;
            fb += L.b * y;
            fn += L * (max(dot(n, d), 0.0) * w);
        }
        float traces = max(pn.w, 1.0);
        float a = src >= 0 ? max(1.0 / traces, u_sp_min_blend) : 1.0;
        float lp = luminance(hn.rgb), ln = luminance(fn);
        if (src >= 0 && abs(ln - lp) > u_sp_change_threshold * max(max(lp, ln), 1e-6)) a = max(a, u_sp_fast_blend);
        hr = mix(hr, fr, a);
        hg = mix(hg, fg, a);
        hb = mix(hb, fb, a);
        hn = vec4(mix(hn.rgb, fn, a), 1.0);
    } else if (pp.w < 0.5) {
        hr = hg = hb = hn = vec4(0.0);
    }
    imageStore(o_sh_r, t, hr);
    imageStore(o_sh_g, t, hg);
    imageStore(o_sh_b, t, hb);
    imageStore(o_sh_n, t, hn);
}
