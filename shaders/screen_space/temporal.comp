// temporal.comp — temporal accumulation shared by the screen-space family.
// Papers: Nehab et al. 2007 ("Accelerating real-time shading with reverse reprojection
// caching"); Karis 2014 (temporal reprojection); Jimenez et al. 2016 (GTAO's temporal filter).
// The current (possibly lower-resolution) signal is upsampled with a joint bilateral 2x2
// filter (plane distance and normal of the full-resolution pixel), the history is
// reprojected with the G-buffer motion vectors (bilinear over 2x2 taps), and each tap is
// kept only if the surface there last frame lies on this pixel's plane, projects to within
// 1.5 pixels of this pixel in the current view, and has a similar normal (disocclusion rejection, so a moving camera does not ghost). The output is the
// running mean over min(history + 1, u_max_history) frames: a still camera converges, a
// moving one forgets within u_max_history frames.
// Outputs: o_out (signal), o_len (history length), and this frame's position/normal for
// the next frame's rejection test.
#include "lib/common.glsl"
#include "lib/screen.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform writeonly image2D o_out;
layout(binding = 1, r32f) uniform writeonly image2D o_len;
layout(binding = 2, rgba32f) uniform writeonly image2D o_pos;   // xyz world, w = history length
layout(binding = 3, rgba16f) uniform writeonly image2D o_nrm;

uniform sampler2D u_current;
uniform sampler2D u_hist;
uniform sampler2D u_hist_pos;
uniform sampler2D u_hist_nrm;
uniform sampler2D u_gb_position;
uniform sampler2D u_gb_normal;
uniform sampler2D u_gb_motion;
uniform int u_reset;
uniform float u_max_history;
uniform vec4 u_background;    // what the signal is on background pixels
#ifdef REFLECTION_REPROJECT
// Reflections move with the reflected point, not with the reflecting surface (Stachowiak
// 2015): a mirror image lies at the virtual point X = P - V * hit distance behind the
// surface, along the camera ray. Where the resolve found a hit (u_hit_dist > 0), the history
// is fetched where X was last frame: the surface's motion plus X's parallax relative to P
// (both through the current and previous view-projection, so the jitter cancels). The tap
// must still lie on this pixel's plane with a similar normal, but not at this pixel's own
// surface point (it is another point of the same mirror). No hit: the surface's motion.
uniform sampler2D u_hit_dist;
uniform mat4 u_prev_view_proj;
vec2 prev_pixel(vec3 X) {
    vec4 c = u_prev_view_proj * vec4(X, 1.0);
    if (c.w <= 1e-7) return vec2(-1e9);
    return (c.xy / c.w * 0.5 + 0.5) * u_resolution;
}
#endif

#ifdef HISTORY_CLAMP
// Neighbourhood clamp (Karis 2014), for a signal whose history can lag behind the image in a
// way the geometric tests cannot see (SSR's miss fallback: a highlight seen in a mirror moves
// with neither the mirror nor the hit point): while u_clamp is 1 (the camera moves) the
// reprojected history is clamped to the range of this frame's signal over the 3x3 pixels
// around this one. A still camera keeps the plain running mean.
uniform int u_clamp;
#endif

vec4 upsample(ivec2 px, vec3 P, vec3 N) {
    ivec2 csize = textureSize(u_current, 0);
    if (csize == ivec2(u_resolution)) return texelFetch(u_current, px, 0);
    vec2 scale = vec2(csize) / u_resolution;
    vec2 c = (vec2(px) + 0.5) * scale - 0.5;
    ivec2 base = ivec2(floor(c));
    vec2 f = c - vec2(base);
    float ppu = pixels_per_unit(view_depth(P));
    vec4 sum = vec4(0.0);
    float wsum = 0.0;
    for (int j = 0; j < 2; ++j)
        for (int i = 0; i < 2; ++i) {
            ivec2 qq = clamp(base + ivec2(i, j), ivec2(0), csize - 1);
            ivec2 fp = clamp(ivec2((vec2(qq) + 0.5) / scale), ivec2(0), ivec2(u_resolution) - 1);
            vec4 pq = texelFetch(u_gb_position, fp, 0);
            if (pq.w < 0.0) continue;
            vec3 nq = texelFetch(u_gb_normal, fp, 0).xyz;
            float bw = (i == 0 ? 1.0 - f.x : f.x) * (j == 0 ? 1.0 - f.y : f.y) + 1e-3;
            float plane = abs(dot(N, pq.xyz - P)) * ppu;   // in pixels
            float w = bw * exp(-plane * 0.5) * pow(max(dot(N, nq), 0.0), 8.0);
            sum += w * texelFetch(u_current, qq, 0);
            wsum += w;
        }
    if (wsum <= 1e-6) return texelFetch(u_current, clamp(ivec2(c + 0.5), ivec2(0), csize - 1), 0);
    return sum / wsum;
}

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(px, ivec2(u_resolution)))) return;
    vec4 pos = texelFetch(u_gb_position, px, 0);
    vec3 N = normalize(texelFetch(u_gb_normal, px, 0).xyz + vec3(0.0, 0.0, 1e-12));
    if (pos.w < 0.0) {
        imageStore(o_out, px, u_background);
        imageStore(o_len, px, vec4(0.0));
        imageStore(o_pos, px, vec4(0.0));
        imageStore(o_nrm, px, vec4(0.0));
        return;
    }
    vec3 P = pos.xyz;
    vec4 cur = upsample(px, P, N);
    cur = vec4(sanitize(cur.rgb), clamp(isnan(cur.a) || isinf(cur.a) ? 0.0 : cur.a, 0.0, 1e20));
    vec4 hist = vec4(0.0);
    float len = 0.0;
    if (u_reset == 0) {
        vec2 prev = vec2(px) + 0.5 - texelFetch(u_gb_motion, px, 0).xy - 0.5;
        bool by_hit = false;
#ifdef REFLECTION_REPROJECT
        float hd = texelFetch(u_hit_dist, px, 0).r;
        if (hd > 0.0 && u_ortho == 0) {
            vec3 X = P - view_dir(P) * hd;
            vec2 pX = prev_pixel(X), pP = prev_pixel(P);
            if (pX.x > -1e8 && pP.x > -1e8) {
                // parallax of X relative to P between the two views
                prev -= (to_pixel(X) - pX) - (to_pixel(P) - pP);
                by_hit = true;
            }
        }
#endif
        ivec2 b = ivec2(floor(prev));
        vec2 f = prev - vec2(b);
        float d = view_depth(P);
        float foot = 1.0 / pixels_per_unit(d);   // one pixel in world units at this depth
        float tol = 2.0 * foot + 0.01 * d;
        float wsum = 0.0;
        vec4 hsum = vec4(0.0);
        float lsum = 0.0;
        ivec2 hsize = textureSize(u_hist, 0);
        for (int j = 0; j < 2; ++j)
            for (int i = 0; i < 2; ++i) {
                ivec2 t = b + ivec2(i, j);
                if (any(lessThan(t, ivec2(0))) || any(greaterThanEqual(t, hsize))) continue;
                vec4 hp = texelFetch(u_hist_pos, t, 0);
                if (!(hp.w > 0.0) || isinf(hp.w)) continue;   // no history (NaN-safe: a NaN tap is none)
                vec4 hv = texelFetch(u_hist, t, 0);
                if (any(isnan(hv)) || any(isinf(hv)) || any(isnan(hp.xyz))) continue;
                vec3 hn = texelFetch(u_hist_nrm, t, 0).xyz;
                vec3 dp = hp.xyz - P;
                // the tap's surface point must land within ~1.5 pixels of this pixel now
                vec2 tp = to_pixel(hp.xyz) - (vec2(px) + 0.5);
                if (abs(dot(N, dp)) > tol || (!by_hit && dot(tp, tp) > 2.25) || !(dot(hn, N) >= 0.9)) continue;
                float w = (i == 0 ? 1.0 - f.x : f.x) * (j == 0 ? 1.0 - f.y : f.y);
                hsum += w * hv;
                lsum += w * hp.w;
                wsum += w;
            }
        if (wsum > 0.05) {
            hist = hsum / wsum;
            len = lsum / wsum;
        }
#ifdef HISTORY_CLAMP
        if (u_clamp != 0 && len > 0.0) {
            vec3 lo = cur.rgb, hi = cur.rgb;
            for (int j = -1; j <= 1; ++j)
                for (int i = -1; i <= 1; ++i) {
                    ivec2 q = px + ivec2(i, j);
                    if (any(lessThan(q, ivec2(0))) || any(greaterThanEqual(q, ivec2(u_resolution)))) continue;
                    if (texelFetch(u_gb_position, q, 0).w < 0.0) continue;
                    vec3 c = sanitize(upsample(q, P, N).rgb);
                    lo = min(lo, c);
                    hi = max(hi, c);
                }
            hist.rgb = clamp(hist.rgb, lo, hi);
        }
#endif
    }
    float n = min(len + 1.0, max(u_max_history, 1.0));
    vec4 outv = len > 0.0 ? mix(hist, cur, 1.0 / n) : cur;
    imageStore(o_out, px, outv);
    imageStore(o_len, px, vec4(n));
    imageStore(o_pos, px, vec4(P, n));
    imageStore(o_nrm, px, vec4(N, 0.0));
}
