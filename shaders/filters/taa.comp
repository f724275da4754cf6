// taa.comp — temporal anti-aliasing (Karis 2014, "High quality temporal supersampling"),
// made safe for a noisy (1-spp path-traced) input.
// Camera jitter: the session's R2 sequence (see docs/techniques/TAA.md). Motion vectors are
// unjittered, so the jitter needs no correction in the reprojection.
// * Reprojection: the history's 2x2 bilinear taps through gbuffer.motion, each kept only if
//   finite and geometrically the same surface (its stored position within 2 pixel
//   footprints of this pixel's tangent plane; background stays background): disocclusion
//   is detected by geometry, not by colour. The kept taps are renormalised. Where all 4x4
//   taps around the point pass, the colour is resampled with Catmull-Rom instead (bilinear
//   resampling blurs the history a little every moving frame, and the blur accumulates).
// * Under motion (|motion| > u_normal_motion) a history tap must also face like this pixel
//   (normal . N > u_hist_normal; history normals in taa.aux.yzw): the plane test alone accepted
//   the front face's texels near an edge for a grazing side face revealed by a pan (they lie
//   within 2 footprints of its plane), a lit ghost that decayed at alpha (Cornell pan trail
//   1.1-1.9x the still level over seeds). Where no bilinear tap passes, the same-surface texels
//   of the 3x3 around the reprojected point are used (Schied 2017's fallback). A still pixel
//   keeps the plane test only: its own texel holds its footprint's mix of surfaces (the edge
//   anti-aliasing), whatever surface this frame's jittered sample hit.
// * A light edit caps the history length (u_len_cap) instead of restarting it.
// * History length per pixel (alpha channel): the blend weight is max(u_alpha, 1/length),
//   so a disoccluded pixel starts from its own samples and converges like a running mean.
//   A disoccluded pixel starts from the mean of its 3x3 neighbours on the same surface
//   (length 2), not from one noisy sample.
// * Variance clipping (Salvi 2016) in linear YCoCg: the history is clipped towards the 3x3
//   mean within gamma x max(spatial sigma, temporal sigma). The temporal sigma (from the
//   luminance second moment kept in history) widens the box where the input's noise is heavy-
//   tailed (light through a window reaching a wall by one bounce): a box from 9 single
//   samples would otherwise cut the rare bright samples every frame and darken the result.
//   No min/max box and no tone-mapped blend for the same reason (both are biased on noisy
//   input); the blend is linear, so the running mean is the samples' mean.
// * Reconstruction filter of the current frame (Karis' filtered current sample; here a 5x5
//   binomial over the neighbours on the same surface (u_radius 2; 3x3 once the history is
//   older than u_young with u_radius 1), u_input_filter = 1): a 1-spp path-traced
//   sample blended alone at weight alpha lets its full noise through every frame (flicker
//   2-4x Cycles' frame-to-frame change on the sun-lit room); the binomial divides its standard
//   deviation by up to 3.7 (5x5; 2.7 at 3x3) and is linear and normalised, so it keeps the energy. The clip box
//   and the temporal moments still use the raw samples (they describe the sample spread).
// Off-screen, geometrically different or non-finite history is dropped.
#include "lib/common.glsl"
#include "lib/screen.glsl"
#include "filters/common.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform writeonly image2D o_hist;   // rgb result, a = history length
layout(binding = 1, rgba32f) uniform writeonly image2D o_aux;    // x = E[Y^2] (same average), yzw = normal
layout(binding = 2, rgba32f) uniform writeonly image2D o_pos;    // xyz, w = 1 surface / 0 background
layout(binding = 3, rgba32f) uniform writeonly image2D o_debug;  // r = length / max, g = share clipped

uniform sampler2D u_color;
uniform sampler2D u_hist;
uniform sampler2D u_hist_aux;
uniform sampler2D u_hist_pos;
uniform sampler2D u_gb_motion;
uniform sampler2D u_gb_position;
uniform sampler2D u_gb_normal;
uniform int u_reset;
uniform float u_alpha;
uniform float u_gamma;
uniform float u_max_history;
uniform int u_input_filter;  // 1: blend the same-surface binomial of this frame's samples
// 0: the background pixels take their own sample. The background is the world seen along the
// pixel's ray, without noise; a uniform world may be filtered (it smooths the samples of a
// silhouette that land on the far side), a world map may not (a blur spreads an HDRI's sun
// or street lamps over their neighbours on every frame: relMSE 13 instead of 0.02).
uniform int u_background_filter;
uniform float u_young;       // history length up to which the input filter is 5x5
uniform int u_radius;        // input filter radius beyond (1: 3x3, 2: 5x5)
uniform int u_history_filter;    // 0: bilinear history, 1: Catmull-Rom where all 16 taps are usable
uniform float u_len_cap;  // history length kept through this frame (a light edit: light_history)
uniform int u_hist_fallback;  // 1: 3x3 same-surface search where no bilinear tap is usable
uniform float u_hist_normal;  // history tap kept only if its normal . this normal > this (-1: off)

// is the history texel (position hp, normal hn) on this pixel's surface (P, N)?
uniform float u_normal_motion;  // ... where the reprojection moves by more than this (pixels)
float g_ncos = -2.0;  // the normal threshold in force for this pixel (set in main)
bool g_moving = false;  // |motion| > u_normal_motion (set in main)
bool g_moved = false;   // the reprojection moves at all (set in main)
uniform float u_turned_len;  // history length cap where a sub-pixel move keeps texels facing elsewhere (0: off)
bool hist_same_surface(bool surf, vec3 P, vec3 N, vec4 hp, vec3 hn) {
    if (!surf) return hp.w < 0.5;
    return hp.w >= 0.5 && plane_pixels(P, N, hp.xyz) <= 2.0 && dot(N, hn) > g_ncos;
}

// Catmull-Rom weights of the taps at -1, 0, 1, 2 for a fraction f in [0, 1)
vec4 catmull_rom_weights(float f) {
    return vec4(f * (-0.5 + f * (1.0 - 0.5 * f)), 1.0 + f * f * (-2.5 + 1.5 * f),
                f * (0.5 + f * (2.0 - 1.5 * f)), f * f * (-0.5 + 0.5 * f));
}

// Reconstruction filter of this frame's samples: a (2r+1)^2 binomial over the neighbours on
// the same surface (tangent plane within 2 pixel footprints, normal within ~25 degrees; for a
// background pixel: the background neighbours). Linear and normalised: keeps the energy.
const float BINOM1[3] = float[3](1.0, 2.0, 1.0);
const float BINOM2[5] = float[5](1.0, 4.0, 6.0, 4.0, 1.0);
// Also returns the clip box of the same window (mean and sigma of the raw samples in YCoCg):
// the box must see every sample the filtered input spreads into this pixel, or the energy of
// a rare bright sample spread over its neighbours is clipped away there (sun-lit room: 20 %).
vec3 rgb2ycocg(vec3 c);
// q is on this pixel's surface (for a background pixel: q is background)
bool input_same_surface(ivec2 q, bool surf, vec3 P, vec3 N) {
    vec4 pq = texelFetch(u_gb_position, q, 0);
    return surf ? same_surface_texel(P, N, pq, texelFetch(u_gb_normal, q, 0).xyz) : pq.w < 0.0;
}
// History guide: where this pixel has history, a neighbour's sample joins the filter only if
// the history at the neighbour's reprojected texel is within GUIDE_RATIO of this pixel's (in
// luminance). The history is a converged estimate of the signal, so what it separates is a
// real edge in the lighting (a highlight of a bright light on a glossy sphere, a sun shadow),
// not noise: without it the binomial spreads a highlight 10^4 times brighter than the surface
// around it over two pixels on every frame, and the blur never averages out.
#define GUIDE_RATIO 8.0
float g_guide = -1.0;        // this pixel's history luminance (< 0: no guide)
float g_guide_eps;           // half the 3x3 mean of this frame's samples: where the history is
                             // still dark and noisy, only what stands far above it is an edge
vec2 g_guide_motion;         // this pixel's motion, reused for its neighbours
float guide_luminance(ivec2 q, ivec2 size) {
    ivec2 t = ivec2(floor(vec2(q) - g_guide_motion + 0.5));
    if (any(lessThan(t, ivec2(0))) || any(greaterThanEqual(t, size))) return -1.0;
    vec4 h = texelFetch(u_hist, t, 0);
    return (finite4(h) && h.a >= 1.0) ? luminance(max(h.rgb, vec3(0.0))) : -1.0;
}
bool guide_rejects(ivec2 q, ivec2 size) {
    if (g_guide < 0.0) return false;
    float lq = guide_luminance(q, size);
    return lq >= 0.0 && (lq > GUIDE_RATIO * g_guide + g_guide_eps || g_guide > GUIDE_RATIO * lq + g_guide_eps);
}
vec3 filtered_input(ivec2 px, ivec2 size, bool surf, vec3 P, vec3 N, int r, out vec3 bmean, out vec3 bsig) {
    vec3 sum = vec3(0.0), b1 = vec3(0.0), b2 = vec3(0.0);
    float ws = 0.0, nb = 0.0;
    for (int dy = -r; dy <= r; ++dy)
        for (int dx = -r; dx <= r; ++dx) {
            ivec2 q = px + ivec2(dx, dy);
            if (any(lessThan(q, ivec2(0))) || any(greaterThanEqual(q, size))) continue;
            vec3 yq = rgb2ycocg(sanitize(texelFetch(u_color, q, 0).rgb));
            b1 += yq;
            b2 += yq * yq;
            nb += 1.0;
            if (!input_same_surface(q, surf, P, N) || guide_rejects(q, size)) continue;
            float g = r == 1 ? BINOM1[dx + 1] * BINOM1[dy + 1] : BINOM2[dx + 2] * BINOM2[dy + 2];
            sum += g * sanitize(texelFetch(u_color, q, 0).rgb);
            ws += g;
        }
    bmean = b1 / max(nb, 1.0);
    bsig = sqrt(max(b2 / max(nb, 1.0) - bmean * bmean, vec3(0.0)));
    return ws > 0.0 ? sum / ws : sanitize(texelFetch(u_color, px, 0).rgb);
}

// Thin surfaces (u_thin_neff > 0): a face a pixel or two wide (seen edge-on, revealed by a
// pan) has few same-surface samples in the 5x5: the effective sample count (sum g)^2 / sum g^2
// of the 5x5 binomial's same-surface weights is 3.7 for a 1-px column, 13.4 inside a face. So
// while its history is young its input is ~2x noisier than a face's; there the young input is
// the plain mean of the same-surface samples of the (2 u_thin_radius + 1)^2 box.
uniform float u_thin_neff;
uniform int u_thin_radius;
float surface_neff(ivec2 px, ivec2 size, bool surf, vec3 P, vec3 N) {
    float ws = 0.0, ws2 = 0.0;
    for (int dy = -2; dy <= 2; ++dy)
        for (int dx = -2; dx <= 2; ++dx) {
            ivec2 q = px + ivec2(dx, dy);
            if (any(lessThan(q, ivec2(0))) || any(greaterThanEqual(q, size))) continue;
            if (!input_same_surface(q, surf, P, N)) continue;
            float g = BINOM2[dx + 2] * BINOM2[dy + 2];
            ws += g;
            ws2 += g * g;
        }
    return ws2 > 0.0 ? ws * ws / ws2 : 0.0;
}
bool thin_surface(ivec2 px, ivec2 size, bool surf, vec3 P, vec3 N) {
    return u_thin_neff > 0.0 && surface_neff(px, size, surf, P, N) < u_thin_neff;
}
vec3 thin_input(ivec2 px, ivec2 size, bool surf, vec3 P, vec3 N, int r) {
    vec3 sum = vec3(0.0);
    float n = 0.0;
    for (int dy = -r; dy <= r; ++dy)
        for (int dx = -r; dx <= r; ++dx) {
            ivec2 q = px + ivec2(dx, dy);
            if (any(lessThan(q, ivec2(0))) || any(greaterThanEqual(q, size))) continue;
            if (!input_same_surface(q, surf, P, N)) continue;
            sum += sanitize(texelFetch(u_color, q, 0).rgb);
            n += 1.0;
        }
    return n > 0.0 ? sum / n : sanitize(texelFetch(u_color, px, 0).rgb);
}

vec3 rgb2ycocg(vec3 c) {
    return vec3(0.25 * c.r + 0.5 * c.g + 0.25 * c.b, 0.5 * c.r - 0.5 * c.b, -0.25 * c.r + 0.5 * c.g - 0.25 * c.b);
}
vec3 ycocg2rgb(vec3 c) { return vec3(c.x + c.y - c.z, c.x + c.z, c.x - c.y - c.z); }

// clip q towards the box centre c with half-extent e (clip, not clamp: no box-corner colours)
vec3 clip_box(vec3 c, vec3 e, vec3 q) {
    vec3 v = q - c;
    vec3 a = abs(v / max(e, vec3(1e-6)));
    float m = max(a.x, max(a.y, a.z));
    return m > 1.0 ? c + v / m : q;
}

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    ivec2 size = textureSize(u_color, 0);
    if (any(greaterThanEqual(px, size))) return;
    vec3 cur = sanitize(texelFetch(u_color, px, 0).rgb);
    vec4 pos = texelFetch(u_gb_position, px, 0);
    bool surf = pos.w >= 0.0;
    vec3 P = pos.xyz;
    vec3 N = normalize(texelFetch(u_gb_normal, px, 0).xyz + vec3(0.0, 0.0, 1e-12));
    vec3 m1 = vec3(0.0), m2 = vec3(0.0), same = vec3(0.0);
    float ns = 0.0;
    for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
            ivec2 q = clamp(px + ivec2(dx, dy), ivec2(0), size - 1);
            vec3 cq = sanitize(texelFetch(u_color, q, 0).rgb);
            vec3 y = rgb2ycocg(cq);
            m1 += y;
            m2 += y * y;
            vec4 pq = texelFetch(u_gb_position, q, 0);
            bool ok = surf ? (pq.w >= 0.0 && plane_pixels(P, N, pq.xyz) <= 2.0) : pq.w < 0.0;
            if (ok) {
                same += cq;
                ns += 1.0;
            }
        }
    m1 /= 9.0;
    vec3 sig = sqrt(max(m2 / 9.0 - m1 * m1, vec3(0.0)));
    float ycur = luminance(cur);

    vec3 hc = vec3(0.0);
    float hlen = 0.0, hm2 = 0.0, wsum = 0.0, turned = 0.0;
    if (u_reset == 0) {
        vec2 mv = texelFetch(u_gb_motion, px, 0).xy;
        g_guide_motion = mv;
        vec2 prev = vec2(px) + 0.5 - mv - 0.5;
        bool moving = length(mv) > u_normal_motion;
        if (moving) g_ncos = u_hist_normal;
        g_moving = moving;
        g_moved = dot(mv, mv) > 1e-8;
        ivec2 b = ivec2(floor(prev));
        vec2 f = prev - vec2(b);
        for (int j = 0; j < 2; ++j)
            for (int i = 0; i < 2; ++i) {
                ivec2 t = b + ivec2(i, j);
                if (any(lessThan(t, ivec2(0))) || any(greaterThanEqual(t, size))) continue;
                vec4 h = texelFetch(u_hist, t, 0);
                vec4 ha = texelFetch(u_hist_aux, t, 0);
                vec4 hp = texelFetch(u_hist_pos, t, 0);
                if (!(finite4(h) && finite4(ha) && finite4(hp)) || h.a < 1.0) continue;
                if (!hist_same_surface(surf, P, N, hp, ha.yzw)) continue;
                float w = (i == 0 ? 1.0 - f.x : f.x) * (j == 0 ? 1.0 - f.y : f.y);
                if (g_moved && !g_moving && surf && dot(N, ha.yzw) <= u_hist_normal) turned += w;
                hc += w * max(h.rgb, vec3(0.0));
                hlen += w * h.a;
                hm2 += w * max(ha.x, 0.0);
                wsum += w;
            }
        // Catmull-Rom history colour (u_history_filter = 1): the bilinear resample blurs the
        // history a little every frame the camera moves, and a long average accumulates it (a
        // lit edge smears into its dark neighbour and stays there as a lag). Used only where all
        // 4x4 taps are finite and on this surface (else the bilinear taps above); negative lobes
        // are clamped by the clip below and the final max(0).
        if (u_history_filter == 1 && wsum > 0.999) {
            vec4 cx = catmull_rom_weights(f.x), cyw = catmull_rom_weights(f.y);
            vec3 cr = vec3(0.0);
            bool ok = true;
            for (int j = -1; j <= 2 && ok; ++j)
                for (int i = -1; i <= 2; ++i) {
                    ivec2 t = b + ivec2(i, j);
                    if (any(lessThan(t, ivec2(0))) || any(greaterThanEqual(t, size))) { ok = false; break; }
                    vec4 h = texelFetch(u_hist, t, 0);
                    vec4 hp = texelFetch(u_hist_pos, t, 0);
                    vec4 ha = texelFetch(u_hist_aux, t, 0);
                    if (!(finite4(h) && finite4(hp) && finite4(ha)) || h.a < 1.0
                        || !hist_same_surface(surf, P, N, hp, ha.yzw)) { ok = false; break; }
                    cr += cx[i + 1] * cyw[j + 1] * max(h.rgb, vec3(0.0));
                }
            if (ok) hc = wsum * max(cr, vec3(0.0));  // hc is divided by wsum below
        }
        // no bilinear tap on this surface: the same-surface texels of the 3x3 around the
        // reprojected point (Schied 2017's fallback), so an edge pixel whose jittered sample
        // flips between two surfaces keeps its own surface's history instead of restarting
        if (u_hist_fallback == 1 && moving && wsum <= 0.01) {
            ivec2 c = ivec2(floor(prev + 0.5));
            for (int j = -1; j <= 1; ++j)
                for (int i = -1; i <= 1; ++i) {
                    ivec2 t = c + ivec2(i, j);
                    if (any(lessThan(t, ivec2(0))) || any(greaterThanEqual(t, size))) continue;
                    vec4 h = texelFetch(u_hist, t, 0);
                    vec4 ha = texelFetch(u_hist_aux, t, 0);
                    vec4 hp = texelFetch(u_hist_pos, t, 0);
                    if (!(finite4(h) && finite4(ha) && finite4(hp)) || h.a < 1.0) continue;
                    if (!hist_same_surface(surf, P, N, hp, ha.yzw)) continue;
                    hc += max(h.rgb, vec3(0.0));
                    hlen += h.a;
                    hm2 += max(ha.x, 0.0);
                    wsum += 1.0;
                }
        }
    }
    vec3 outc;
    float len, om2, clipped = 0.0;
    if (wsum > 0.01) {
        hc /= wsum;
        hlen /= wsum;
        hm2 /= wsum;
        // u_turned_len: a sub-pixel move keeps the plane test only (normal_motion), so a face
        // revealed edge-on can inherit the texels of the surface it meets (the plane test passes
        // near their common edge): where most of the history faces elsewhere it is followed at
        // >= 1/u_turned_len per frame instead of alpha
        if (u_turned_len > 0.0 && turned > 0.5 * wsum) hlen = min(hlen, u_turned_len);
        len = min(min(hlen, u_len_cap) + 1.0, max(u_max_history, 1.0));
        // young history (running mean, weight 1/len per frame): the wider 5x5 filter, so a
        // disoccluded pixel's early frames do not leave their noise in it for the next ~10 frames
        vec3 bm = m1, bs = sig;
        vec3 curf = cur;
        g_guide = luminance(hc);
        g_guide_eps = 0.5 * max(m1.x, 0.0) + 1e-6;
        if (u_input_filter == 1 && (surf || u_background_filter == 1)) {
            curf = filtered_input(px, size, surf, P, N, len <= u_young ? 2 : u_radius, bm, bs);
            if (len <= u_young && thin_surface(px, size, surf, P, N))
                curf = thin_input(px, size, surf, P, N, u_thin_radius);
        }
        vec3 hy = rgb2ycocg(hc);
        float sig_t = sqrt(max(hm2 - hy.x * hy.x, 0.0));
        vec3 e = u_gamma * max(bs, vec3(sig_t));
        vec3 cy = clip_box(bm, e, hy);
        clipped = length(cy - hy) / (length(hy) + 1e-4);
        float a = max(u_alpha, 1.0 / len);
        outc = mix(max(ycocg2rgb(cy), vec3(0.0)), curf, a);
        om2 = mix(hm2, ycur * ycur, a);
    } else {
        // no usable history (disocclusion, off-screen, reset): the same-surface 5x5 binomial
        // (3x3 mean without the input filter)
        vec3 bm, bs;
        outc = (!surf && u_background_filter == 0) ? cur
             : u_input_filter == 1 ? filtered_input(px, size, surf, P, N, 2, bm, bs) : (ns > 0.0 ? same / ns : cur);
        if (u_input_filter == 1 && surf && thin_surface(px, size, surf, P, N))
            outc = thin_input(px, size, surf, P, N, u_thin_radius);
        len = ns >= 4.0 ? 2.0 : 1.0;
        om2 = ycur * ycur;
        clipped = 1.0;
    }
    outc = sanitize(outc);
    imageStore(o_hist, px, vec4(outc, len));
    imageStore(o_aux, px, vec4(isnan(om2) || isinf(om2) ? 0.0 : om2, surf ? N : vec3(0.0)));
    imageStore(o_pos, px, surf ? vec4(P, 1.0) : vec4(0.0));
    imageStore(o_debug, px, vec4(vec3(len / max(u_max_history, 1.0), min(clipped, 1.0), 0.0), 1.0));
}
