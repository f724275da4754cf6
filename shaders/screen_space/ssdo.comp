// ssdo.comp — SSDO: screen-space directional occlusion with one indirect bounce.
// Paper: Ritschel, Grosch & Seidel 2009 ("Approximating dynamic global illumination in
// image space").
// For u_samples cosine-distributed directions around the normal (rotated per pixel and
// frame), a point at a random distance within the radius is projected to the screen.
// Occluded (behind the G-buffer surface there): the G-buffer pixel that hides the point is
// a small sender; its radiance is the direct-lit colour buffer (aov.direct: reflected
// direct light, without emission, which DIRECT already counts), received if the sender
// faces the receiver. The estimator is the cosine-weighted mean of incident radiance, so
// the diffuse bounce is albedo_d * mean(L_in): bounded by the brightest on-screen sender.
// Not occluded: the direction is open (DIRECT already lights with the world, shadowed by
// its world-light maps, so an open direction adds nothing here).
// Far field (an extension of the paper's near-field samples): a direction open within the
// radius is marched further (far_blocker, common.glsl); a surface met there is a sender
// too, so the bounce from walls beyond the radius (a room's far side) is not lost.
// Off screen (a sample, or the far-field march, left the screen: screen space does not know
// what is there): with SSDO_WORLD one such direction per tile of u_world_tile^2 pixels and
// frame is traced through the scene: this pass picks the tile's tracer (rotating per frame)
// and writes its ray (o_ray_o, o_ray_d); ssdo_trace.comp traces the rays (lib/scene_rt.glsl:
// a hit sends its diffuse direct light toward the receiver, a miss is open) and
// ssdo_resolve.comp lets that radiance stand for the off-screen directions of every pixel of
// the tile that faces like the tracer, shrunk towards the mean of the pixel's on-screen
// directions by the share of them the screen knows. Without SSDO_WORLD (or at a tile edge)
// they are unknown: the bounce is the mean over the directions the screen knows.
// Bright senders (SSDO_SENDERS): each receiver also picks u_sender_samples sender pixels in
// proportion to their flux (ssdo_flux.comp) and weights both strategies by MIS (see
// pick_sender): the sun-lit room's speckles were far-field directions meeting the small sun
// patch on the floor, rare and large (docs/techniques/SSDO.md).
// Output (at u_scale of the full resolution): rgb = mean sender radiance over all samples,
// a = cosine-weighted fraction of directions that stay open (the GI_AO AOV). With
// SSDO_WORLD, a pixel with off-screen directions leaves the SUM of its known senders'
// radiance in rgb and its counts in o_part (off-screen, unknown) for ssdo_resolve.comp.
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/rng.glsl"
#include "lib/sampling.glsl"
#include "lib/brdf.glsl"
#include "lib/screen.glsl"
#include "screen_space/common.glsl"
#include "screen_space/ssdo_flux.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba16f) uniform writeonly image2D o_ssdo;

uniform sampler2D u_radiance;  // direct-lit colour (aov.direct)
uniform sampler2D u_trust;     // per sender pixel (fd, sigma) of view_trust (ssdo_trust.comp)
uniform int u_samples;
uniform float u_radius;
uniform float u_bias;
// Diagnostic: which sample classes add their radiance (a sum of bits; the default, all): 1 near-field
// senders, 2 far-field senders, 4 traced off-screen directions (ssdo_resolve.comp), 8 picked
// senders. The counts (open, unknown) are unchanged, so the classes' images add up to the whole
// (docs/techniques/SSDO.md: which samples made the sun-lit room's speckles).
#ifndef SSDO_CLASSES
#define SSDO_CLASSES 15
#endif
const float W_NEAR = (SSDO_CLASSES & 1) != 0 ? 1.0 : 0.0;
const float W_FAR = (SSDO_CLASSES & 2) != 0 ? 1.0 : 0.0;
const float W_SEND = (SSDO_CLASSES & 8) != 0 ? 1.0 : 0.0;

#ifdef SSDO_WORLD
uniform int u_world_tile;  // pixels per side of the tile that shares one traced direction
layout(binding = 1, rgba32f) uniform writeonly image2D o_ray_o;  // per tile: origin, tracer pixel
layout(binding = 2, rgba32f) uniform writeonly image2D o_ray_d;  // per tile: direction, 1 = traced
layout(binding = 4, rg16f) uniform writeonly image2D o_part;     // per pixel: off-screen, unknown
#endif

#ifdef SSDO_SENDERS
// Importance sampling of bright senders (multiple importance sampling with the cosine samples).
// A small, bright on-screen sender (the sun patch on a floor) is met by few of the cosine
// directions: rare large samples, the speckles of a few frames' mean. u_flux (ssdo_flux.comp,
// summed upwards by ssdo_flux_reduce.comp) holds per block of sender pixels (one pixel at full
// resolution, 2x2 at q0's half resolution: ssdo_flux.glsl) its flux (r) and pixel count (g);
// each receiver also picks u_sender_samples sender pixels, a block in proportion to its flux by
// descending the pyramid and one of its pixels uniformly. Both strategies estimate the same integral over sender area,
// E/pi = integral of L cos_r cos_s / (pi d^2) dA; in area measure the cosine strategy's pdf is
// pc = cos_r cos_s / (pi d^2) and the sender strategy's pv = (flux / total) / (count area), and each
// sample is weighted by the balance heuristic (Veach 1997): a cosine sample adds L n pc /
// (n pc + m pv) (per direction, the sum divided by n), a picked sender
// n L pc / (n pc + m pv) if the segment to it is free in the depth buffer (screen-space march).
// Every sample stays bounded by its sender's radiance (no 1/d^2 singularity).
uniform sampler2D u_flux;   // rg: flux, pixel count of the block; mip levels (power-of-two image)
uniform int u_flux_top;     // its coarsest level (1x1)
uniform int u_sender_samples;

float flux_total() { return texelFetch(u_flux, ivec2(0), u_flux_top).r; }

// the pdf (area measure) of picking the sender pixel hp (point P, normal N): its block in
// proportion to the block's flux, then one of the block's count pixels (ssdo_flux.glsl)
float sender_pdf(ivec2 hp, vec3 P, vec3 N, float total) {
    vec2 fc = texelFetch(u_flux, flux_block(hp, imageSize(o_ssdo)), 0).rg;
    return fc.x > 0.0 && total > 0.0 ? fc.x / (total * fc.y * sender_area(P, N)) : 0.0;
}

bool segment_free(vec3 O, vec3 Ps, float jitter);

// MIS weight of a cosine sample that found sender pixel hp at Ph (normal Nh) from receiver P, N
// (ray origin O). The sender strategy could have produced this sample only if the segment to Ph
// is free: a sender the direction met only by SSDO's approximations (a point behind the visible
// surface stands for the hidden side of an object: the front pixel is the sender) is one the
// sender strategy never delivers, so it keeps weight 1 (checked only where the weight would drop).
float cosine_weight(vec3 P, vec3 N, vec3 O, ivec2 hp, vec3 Ph, vec3 Nh, float total, float n, float m, float jitter) {
    vec3 d = Ph - P;
    float d2 = max(dot(d, d), 1e-8);
    vec3 w = d * inversesqrt(d2);
    float pc = max(dot(N, w), 0.0) * max(-dot(Nh, w), 0.0) / (PI * d2);
    float pv = sender_pdf(hp, Ph, Nh, total);
    float wc = n * pc + m * pv > 0.0 ? n * pc / (n * pc + m * pv) : 1.0;
    if (pc <= 0.0 || (wc < 0.999 && !segment_free(O, Ph, jitter))) return 1.0;
    return wc;
}

// a sender pixel in proportion to its block's flux: descend the pyramid from the top, choosing
// among the (up to four) children with u (rescaled at each level), then one of the block's
// pixels uniformly with what is left of u
ivec2 pick_sender(float u) {
    ivec2 t = ivec2(0);
    for (int l = u_flux_top; l > 0; --l) {
        ivec2 cs = textureSize(u_flux, l - 1);
        vec4 w = vec4(0.0);
        for (int k = 0; k < 4; ++k) {
            ivec2 c = 2 * t + ivec2(k & 1, k >> 1);
            if (all(lessThan(c, cs))) w[k] = texelFetch(u_flux, c, l - 1).r;
        }
        float sum = w.x + w.y + w.z + w.w;
        if (sum <= 0.0) return ivec2(-1);
        float x = u * sum;
        int k = 0;
        float acc = 0.0;
        for (; k < 3; ++k) {
            if (w[k] > 0.0 && x < acc + w[k]) break;
            acc += w[k];
        }
        if (w[k] <= 0.0) {  // rounding carried x past the last child with flux
            for (k = 3; k > 0 && w[k] <= 0.0; --k) {}
            acc = 0.0;
            for (int i = 0; i < k; ++i) acc += w[i];
        }
        u = clamp((x - acc) / max(w[k], 1e-30), 0.0, 0.99999994);
        t = 2 * t + ivec2(k & 1, k >> 1);
    }
    ivec2 lo, hi;
    flux_block_range(t, imageSize(o_ssdo), lo, hi);
    ivec2 c = max(hi - lo, ivec2(1));
    if (c == ivec2(1)) return lo;  // full resolution: the block is the pixel
    int k = min(int(u * float(c.x * c.y)), c.x * c.y - 1);
    return lo + ivec2(k % c.x, k / c.x);
}

// is the segment from O to the sender point Ps free in the depth buffer? (a coarse march, the
// far field's thickness: a point behind the visible surface by less than the step plus 5 % of
// its distance is blocked, unless that surface is the sender's own, near Ps)
bool segment_free(vec3 O, vec3 Ps, float jitter) {
    vec3 D = Ps - O;
    float len = length(D);
    const int M = 6;
    float step = len / float(M);
    for (int j = 0; j < M; ++j) {
        float f = (float(j) + jitter) / float(M);
        vec3 X = O + D * f;
        vec2 sp = to_pixel(X);
        if (!on_screen(sp)) continue;
        vec4 hpos = texelFetch(u_gb_position, ivec2(sp), 0);
        if (hpos.w < 0.0) continue;
        float ds = view_depth(X), dh = view_depth(hpos.xyz);
        if (dh < ds - u_bias && ds - dh < step + 0.05 * len * f && distance(hpos.xyz, Ps) > step) return false;
    }
    return true;
}
#endif

#ifdef SSDO_WORLD
// One traced direction per tile of u_world_tile x u_world_tile pixels (a power of two <= 8,
// so tiles never straddle the 8x8 group): among the tile's pixels that have off-screen
// directions, the one first in a per-frame rotated order traces its first one; its result
// (the radiance sent back, 0 for a miss; ssdo_trace.comp) stands for the mean off-screen
// radiance of every pixel of the tile whose normal is close to the tracer's (ssdo_resolve.comp).
// The rotation makes every pixel trace in turn, so SSDO's temporal accumulation sees a
// different direction each frame.
shared int s_pick[64];
#endif

void main() {
    ivec2 q = ivec2(gl_GlobalInvocationID.xy);
    ivec2 osize = imageSize(o_ssdo);
    bool inside = all(lessThan(q, osize));
    ivec2 px = ivec2((vec2(q) + 0.5) * u_resolution / vec2(osize));
    GPixel g;
    g.valid = false;
    if (inside) g = fetch_g(px);
    bool live = inside && g.valid;
    vec3 N = live ? g.N : vec3(0.0, 0.0, 1.0);
    vec3 O = live ? g.P + g.Ng * u_bias : vec3(0.0);
    float d0 = live ? view_depth(g.P) : 0.0;
    vec4 rnd = pixel_noise(px, 13u);
    float rot = TWO_PI * rnd.x;
    float cr = cos(rot), sr = sin(rot);
    vec3 bounce = vec3(0.0);
    float open = 0.0, unknown = 0.0;
    int n = max(u_samples, 1);
#ifdef SSDO_SENDERS
    float total = live ? flux_total() : 0.0;
    float nf = float(n), mf = float(max(u_sender_samples, 0));
#endif
#ifdef SSDO_WORLD
    // the first off-screen direction met from a random start in the sample order is the one
    // this pixel traces if it is its tile's tracer this frame
    int start = int(rnd.w * float(n)) % n;
    vec3 wdir = N;
    float wunknown = 0.0;
#endif
    for (int k = 0; k < (live ? n : 0); ++k) {
#ifdef SSDO_WORLD
        int i = (k + start) % n;
#else
        int i = k;
#endif
        float u1 = (float(i) + rnd.y) / float(n);
        float phi = float(i) * 2.39996323;
        vec2 dsk = sqrt(u1) * vec2(cos(phi), sin(phi));
        dsk = vec2(cr * dsk.x - sr * dsk.y, sr * dsk.x + cr * dsk.y);
        vec3 dir = to_world(vec3(dsk, sqrt(max(0.0, 1.0 - dot(dsk, dsk)))), N);
        float s = fract(float(i) * 0.618034 + rnd.z);
        vec3 S = O + dir * (u_radius * mix(0.1, 1.0, s));
        vec2 sp = to_pixel(S);
        if (!on_screen(sp)) {
#ifdef SSDO_WORLD
            if (wunknown == 0.0) wdir = dir;
            wunknown += 1.0;
#else
            open += 1.0; unknown += 1.0;
#endif
            continue;
        }
        ivec2 hp = ivec2(sp);
        GPixel h = fetch_g(hp);
        if (!h.valid) { open += 1.0; continue; }
        float ds = view_depth(S);
        float dh = view_depth(h.P);
        if (dh < ds - u_bias && abs(d0 - dh) < u_radius) {
            // blocked: the hiding pixel sends its direct-lit radiance if it faces P
            vec3 toP = g.P - h.P;
            if (dot(h.N, toP) > 0.0)
                bounce += W_NEAR * texelFetch(u_radiance, hp, 0).rgb *
                          trust_weight(texelFetch(u_trust, hp, 0).rg, view_dir(h.P), normalize(toP))
#ifdef SSDO_SENDERS
                          * cosine_weight(g.P, N, O, hp, h.P, h.N, total, nf, mf, s)
#endif
                          ;
        } else {
            // open within the radius: march further (far field); a surface met there is
            // the sender, otherwise the direction stays open
            ivec2 fp = far_blocker(O, dir, u_radius, fract(s + 0.5));
            if (fp.x == -2) {
#ifdef SSDO_WORLD
                if (wunknown == 0.0) wdir = dir;
                wunknown += 1.0;
#else
                open += 1.0;
                unknown += 1.0;
#endif
            } else if (fp.x < 0) {
                open += 1.0;
            } else {
                GPixel f = fetch_g(fp);
                vec3 toP = g.P - f.P;
                if (dot(f.N, toP) > 0.0)
                    bounce += W_FAR * texelFetch(u_radiance, fp, 0).rgb *
                              trust_weight(texelFetch(u_trust, fp, 0).rg, view_dir(f.P), normalize(toP))
#ifdef SSDO_SENDERS
                              * cosine_weight(g.P, N, O, fp, f.P, f.N, total, nf, mf, fract(s + 0.25))
#endif
                              ;
            }
        }
    }
#ifdef SSDO_SENDERS
    // the picked senders (see pick_sender)
    if (live && total > 0.0) {
        Rng sr = rng_init(uvec2(px), u_sample, 17u);
        for (int j = 0; j < u_sender_samples; ++j) {
            vec2 r2 = rng_next2(sr);
            ivec2 sp = pick_sender(r2.x);
            if (sp.x < 0 || any(greaterThanEqual(sp, ivec2(u_resolution)))) continue;
            GPixel f = fetch_g(sp);
            if (!f.valid) continue;
            vec3 d = f.P - g.P;
            float d2 = max(dot(d, d), 1e-8);
            vec3 w = d * inversesqrt(d2);
            float cr = dot(N, w), cs = -dot(f.N, w);
            if (cr <= 0.0 || cs <= 0.0) continue;
            float pc = cr * cs / (PI * d2);
            float pv = sender_pdf(sp, f.P, f.N, total);
            if (pv <= 0.0 || !segment_free(O, f.P, r2.y)) continue;
            bounce += W_SEND * texelFetch(u_radiance, sp, 0).rgb *
                      trust_weight(texelFetch(u_trust, sp, 0).rg, view_dir(f.P), -w) *
                      (nf * pc / (nf * pc + mf * pv));
        }
    }
#endif
#ifdef SSDO_WORLD
    int T = clamp(u_world_tile, 1, 8);
    ivec2 lq = ivec2(gl_LocalInvocationID.xy);
    int tile = (lq.y / T) * (8 / T) + lq.x / T;
    ivec2 lt = lq % T;
    int rank = ((lt.y * T + lt.x) + int(u_sample % 4096u) * 5) % (T * T);   // rotated per frame
    if (gl_LocalInvocationIndex < 64u) s_pick[gl_LocalInvocationIndex] = 0x7fffffff;
    memoryBarrierShared();
    barrier();
    bool needs = live && wunknown > 0.0;
    if (needs) atomicMin(s_pick[tile], rank);
    memoryBarrierShared();
    barrier();
    int pick = s_pick[tile];
    ivec2 tq = ivec2(gl_WorkGroupID.xy) * (8 / T) + lq / T;  // this tile in the tile grid
    if (needs && pick == rank) {
        imageStore(o_ray_o, tq, vec4(O, float(px.x + 65536 * px.y)));
        imageStore(o_ray_d, tq, vec4(wdir, 1.0));
    } else if (lt == ivec2(0) && pick == 0x7fffffff) {
        imageStore(o_ray_d, tq, vec4(0.0));  // no tracer in this tile
    }
    // GI_AO: an off-screen direction counts as open, whatever the trace met (the AO AOV's
    // meaning is the screen-space occlusion within the radius and the on-screen far field)
    open += wunknown;
    if (inside) imageStore(o_part, q, vec4(live ? wunknown : 0.0, unknown, 0.0, 0.0));
    if (inside && live && wunknown > 0.0) {  // ssdo_resolve.comp completes this pixel
        imageStore(o_ssdo, q, vec4(bounce, open / float(n)));
        return;
    }
#endif
    if (!inside) return;
    if (!live) { imageStore(o_ssdo, q, vec4(0.0, 0.0, 0.0, 1.0)); return; }
    // the bounce is the mean over the directions whose outcome is known (screen space or the
    // tile's trace); the unknown ones are assumed to look like those (not open, not black)
    imageStore(o_ssdo, q, vec4(sanitize(bounce / max(float(n) - unknown, 1.0)), open / float(n)));
}
