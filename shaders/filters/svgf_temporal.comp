// svgf_temporal.comp — SVGF's temporal stage (Schied et al. 2017, §4.1–4.2).
// Demodulates the noisy colour (minus the surface's emission) by the G-buffer albedo,
// reprojects last frame's temporally integrated
// illumination and moments through gbuffer.motion
// (bilinear 2x2, each tap kept only if its surface lies on this pixel's plane, has a similar
// normal and projects near this pixel), integrates with an exponential moving average
// alpha = max(1/len, 1/u_max_history) (the moments with at least u_moments_alpha, as in the
// paper), and estimates the luminance variance from the temporal moments, or spatially (7x7,
// edge-stopped) while the history is shorter than 4; the variance handed to the à-trous is
// that of the integrated signal (samples' / len: the paper hands over the samples' variance).
// History taps that are not finite are rejected, so NaN in history is gone within a frame.
#define USE_SCENE_BUFFERS
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/screen.glsl"
#include "lib/sampling.glsl"
#include "lib/brdf.glsl"
#include "lib/albedo.glsl"
#include "filters/common.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform writeonly image2D o_illum;    // rgb illumination, a variance
layout(binding = 1, rgba32f) uniform writeonly image2D o_moments;  // m1, m2, history length
layout(binding = 2, rgba32f) uniform writeonly image2D o_pos;      // xyz, w = 1 surface
layout(binding = 3, rgba32f) uniform writeonly image2D o_nrm;
layout(binding = 4, rgba32f) uniform writeonly image2D o_dbg_var;  // debug view: variance (grey)
layout(binding = 5, rgba32f) uniform writeonly image2D o_dbg_len;  // debug view: history length / max (grey)

uniform sampler2D u_color;
uniform sampler2D u_gb_albedo;
uniform sampler2D u_gb_position;
uniform sampler2D u_gb_normal;
uniform sampler2D u_gb_geonormal;
uniform sampler2D u_gb_motion;
uniform sampler2D u_hist_illum;
uniform sampler2D u_hist_moments;
uniform sampler2D u_hist_pos;
uniform sampler2D u_hist_nrm;
uniform int u_reset;
uniform float u_max_history;
uniform float u_moments_alpha;  // least weight of this frame in the moments (the paper's 0.2)
uniform float u_edge_len;      // history length cap at moving geometric-edge pixels (0: off)
uniform float u_len_cap;       // history length cap of this frame (a light edit: light_history; else 1e9)

// a 3x3 neighbour of px lies on another surface (off this pixel's plane, turned away, or background)
bool geometric_edge(ivec2 px, ivec2 size, vec3 P, vec3 N) {
    for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
            ivec2 q = clamp(px + ivec2(dx, dy), ivec2(0), size - 1);
            if (!same_surface_texel(P, N, texelFetch(u_gb_position, q, 0), texelFetch(u_gb_normal, q, 0).xyz))
                return true;
        }
    return false;
}

vec3 cur_illum(ivec2 q) {
    vec3 c = sanitize(texelFetch(u_color, q, 0).rgb);
    vec3 e = gb_emission(texelFetch(u_gb_position, q, 0), q);  // emission bypasses demodulation
    vec4 pq = texelFetch(u_gb_position, q, 0);
    return max(c - e, vec3(0.0)) / demod_albedo(texelFetch(u_gb_albedo, q, 0), texelFetch(u_gb_normal, q, 0),
                                               texelFetch(u_gb_geonormal, q, 0), pq, view_dir(pq.xyz));
}

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    ivec2 size = ivec2(u_resolution);
    if (any(greaterThanEqual(px, size))) return;
    vec4 pos = texelFetch(u_gb_position, px, 0);
    if (pos.w < 0.0) {  // background: passed through unfiltered
        imageStore(o_illum, px, vec4(sanitize(texelFetch(u_color, px, 0).rgb), 0.0));
        imageStore(o_moments, px, vec4(0.0));
        imageStore(o_pos, px, vec4(0.0));
        imageStore(o_nrm, px, vec4(0.0));
        imageStore(o_dbg_var, px, vec4(0.0, 0.0, 0.0, 1.0));
        imageStore(o_dbg_len, px, vec4(0.0, 0.0, 0.0, 1.0));
        return;
    }
    vec3 P = pos.xyz;
    vec3 N = normalize(texelFetch(u_gb_normal, px, 0).xyz + vec3(0.0, 0.0, 1e-12));
    vec3 c = cur_illum(px);
    float l = luminance(c);
    vec2 mom = vec2(l, l * l);

    vec3 hc = vec3(0.0);
    vec2 hm = vec2(0.0);
    float hlen = 0.0, wsum = 0.0;
    vec2 mv = texelFetch(u_gb_motion, px, 0).xy;
    if (u_reset == 0) {
        vec2 prev = vec2(px) + 0.5 - mv - 0.5;
        ivec2 b = ivec2(floor(prev));
        vec2 f = prev - vec2(b);
        for (int j = 0; j < 2; ++j)
            for (int i = 0; i < 2; ++i) {
                ivec2 t = b + ivec2(i, j);
                if (any(lessThan(t, ivec2(0))) || any(greaterThanEqual(t, size))) continue;
                vec4 hp = texelFetch(u_hist_pos, t, 0);
                vec4 hn = texelFetch(u_hist_nrm, t, 0);
                vec4 hi = texelFetch(u_hist_illum, t, 0);
                vec4 hmo = texelFetch(u_hist_moments, t, 0);
                if (!(finite4(hp) && finite4(hn) && finite4(hi) && finite4(hmo))) continue;
                if (hp.w <= 0.0 || hmo.z <= 0.0) continue;
                vec2 tp = to_pixel(hp.xyz) - (vec2(px) + 0.5);
                if (plane_pixels(P, N, hp.xyz) > 2.0 || dot(tp, tp) > 2.25 || dot(hn.xyz, N) < 0.9) continue;
                float w = (i == 0 ? 1.0 - f.x : f.x) * (j == 0 ? 1.0 - f.y : f.y);
                hc += w * max(hi.rgb, vec3(0.0));
                hm += w * max(hmo.xy, vec2(0.0));
                hlen += w * hmo.z;
                wsum += w;
            }
    }
    float len = 1.0;
    if (wsum > 0.01) {
        hc /= wsum;
        hm /= wsum;
        hlen /= wsum;
        // u_edge_len: an edge pixel's value is its surfaces' coverage, which changes as the camera
        // moves; at alpha = 1/32 the history trails it by ~30 frames (Cornell slow pan)
        if (u_edge_len > 0.0 && dot(mv, mv) > 1e-8 && geometric_edge(px, size, P, N)) hlen = min(hlen, u_edge_len);
        len = min(min(hlen, u_len_cap) + 1.0, max(u_max_history, 1.0));
        float a = 1.0 / len;
        c = mix(hc, c, a);
        mom = mix(hm, mom, max(a, u_moments_alpha));
    }
    float var = max(mom.y - mom.x * mom.x, 0.0);
    if (len < 4.0) {  // too little history: spatial estimate of the moments (7x7, edge-stopped)
        vec2 sm = vec2(0.0);
        float sw = 0.0;
        for (int dy = -3; dy <= 3; ++dy)
            for (int dx = -3; dx <= 3; ++dx) {
                ivec2 q = px + ivec2(dx, dy);
                if (any(lessThan(q, ivec2(0))) || any(greaterThanEqual(q, size))) continue;
                vec4 pq = texelFetch(u_gb_position, q, 0);
                if (pq.w < 0.0) continue;
                vec3 nq = texelFetch(u_gb_normal, q, 0).xyz;
                float w = pow(max(dot(N, nq), 0.0), 32.0) * exp(-plane_pixels(P, N, pq.xyz) / (1.0 + length(vec2(dx, dy))));
                float lq = luminance(cur_illum(q));
                sm += w * vec2(lq, lq * lq);
                sw += w;
            }
        sm /= max(sw, 1e-6);
        var = max(sm.y - sm.x * sm.x, 0.0);
    }
    // the integrated signal averages ~len samples: its variance is the samples' over len
    var /= len;
    imageStore(o_illum, px, vec4(sanitize(c), isnan(var) || isinf(var) ? 0.0 : var));
    imageStore(o_moments, px, vec4(mom, len, 0.0));
    imageStore(o_pos, px, vec4(P, 1.0));
    imageStore(o_nrm, px, vec4(N, 0.0));
    float v = isnan(var) || isinf(var) ? 0.0 : var;
    imageStore(o_dbg_var, px, vec4(vec3(v), 1.0));
    imageStore(o_dbg_len, px, vec4(vec3(len / max(u_max_history, 1.0)), 1.0));
}
