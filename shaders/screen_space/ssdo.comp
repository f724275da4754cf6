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

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba16f) uniform writeonly image2D o_ssdo;

uniform sampler2D u_radiance;  // direct-lit colour (aov.direct)
uniform sampler2D u_trust;     // per sender pixel (fd, sigma) of view_trust (ssdo_trust.comp)
uniform int u_samples;
uniform float u_radius;
uniform float u_bias;

#ifdef SSDO_WORLD
uniform int u_world_tile;  // pixels per side of the tile that shares one traced direction
layout(binding = 1, rgba32f) uniform writeonly image2D o_ray_o;  // per tile: origin, tracer pixel
layout(binding = 2, rgba32f) uniform writeonly image2D o_ray_d;  // per tile: direction, 1 = traced
layout(binding = 4, rg16f) uniform writeonly image2D o_part;     // per pixel: off-screen, unknown
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
                bounce += texelFetch(u_radiance, hp, 0).rgb *
                          trust_weight(texelFetch(u_trust, hp, 0).rg, view_dir(h.P), normalize(toP));
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
                    bounce += texelFetch(u_radiance, fp, 0).rgb *
                              trust_weight(texelFetch(u_trust, fp, 0).rg, view_dir(f.P), normalize(toP));
            }
        }
    }
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
