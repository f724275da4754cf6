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
// frame is traced through the scene with the shared ray tracer (lib/scene_rt.glsl): a hit
// sends its diffuse direct light toward the receiver (next-event estimation at the hit), a
// miss is open; that radiance stands for the off-screen directions of every pixel of the
// tile that faces like the tracer (the tracer rotates per frame; temporal accumulation and
// the blur average them), shrunk towards the mean of the pixel's on-screen directions by
// the share of them the screen knows. Without SSDO_WORLD (or at a tile edge) they are unknown: the
// bounce is the mean over the directions the screen knows.
// Output (at u_scale of the full resolution): rgb = mean sender radiance over all samples,
// a = cosine-weighted fraction of directions that stay open (the GI_AO AOV).
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/rng.glsl"
#include "lib/sampling.glsl"
#include "lib/brdf.glsl"
#include "lib/screen.glsl"
#ifdef SSDO_WORLD
#include "lib/lights.glsl"
#include "lib/scene_rt.glsl"
#endif
#include "screen_space/common.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba16f) uniform writeonly image2D o_ssdo;

uniform sampler2D u_radiance;  // direct-lit colour (aov.direct)
uniform int u_samples;
uniform float u_radius;
uniform float u_bias;

#ifdef SSDO_WORLD
uniform int u_world_tile;  // pixels per side of the tile that shares one traced direction
uniform float u_world_distance;

// A direction screen space cannot answer (its sample or far-field march left the screen),
// traced through the scene with the shared ray tracer: true with the diffuse radiance the
// surface it hits sends back along it (next-event estimation at the hit, lib/scene_rt.glsl's
// shade_direct_at: one light, one shadow ray), false = open (the world, which DIRECT
// already lights with). Diffuse only, as for on-screen senders (view_trust): a glossy hit's
// light toward the receiver is a caustic path, which one light sample per ray turns into
// fireflies (glossy_spheres q2: relMSE 0.037 -> 0.080 with it). The surface is made
// diffuse-only: base colour times (1 - metallic) (1 - its dielectric layer's albedo), the
// diffuse lobe eval_principled gives.
bool world_sender(vec3 O, vec3 dir, inout Rng rng, out vec3 L) {
    SurfaceHit s;
    L = vec3(0.0);
    if (!scene_trace(O, dir, 0.0, u_world_distance, s)) return false;
    vec3 V = -dir, Nh, Ngh, ph;
    surface_frame(s, V, Nh, Ngh, ph);
    Surface d = s.bsdf;
    float layer = (d.f0 > 1e-6 && d.metallic < 1.0) ? dielectric_layer_albedo(d, max(dot(Nh, V), 1e-4)) : 0.0;
    d.base_color *= (1.0 - d.metallic) * (1.0 - layer);
    d.metallic = 0.0;
    d.f0 = 0.0;
    L = shade_direct_at(d, ph, Nh, Ngh, V, rng, false);
    return true;
}
#endif

#ifdef SSDO_WORLD
// One traced direction per tile of u_world_tile x u_world_tile pixels (a power of two <= 8,
// so tiles never straddle the 8x8 group): among the tile's pixels that have off-screen
// directions, the one first in a per-frame rotated order traces its first one; its result
// (the radiance sent back, 0 for a miss) stands for the mean off-screen radiance of every
// pixel of the tile whose normal is close to the tracer's. The rotation makes every pixel
// trace in turn, so SSDO's temporal accumulation sees a different direction each frame.
shared int s_pick[64];
shared vec4 s_L[64];      // rgb = traced radiance, a = 1 when traced
shared vec3 s_N[64];
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
                bounce += texelFetch(u_radiance, hp, 0).rgb * view_trust(h, hp, normalize(toP));
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
                    bounce += texelFetch(u_radiance, fp, 0).rgb * view_trust(f, fp, normalize(toP));
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
    if (needs && pick == rank) {
        Rng wrng = rng_init(uvec2(px), u_sample, 29u);
        vec3 Lw;
        s_L[tile] = vec4(world_sender(O, wdir, wrng, Lw) ? Lw : vec3(0.0), 1.0);
        s_N[tile] = N;
    }
    memoryBarrierShared();
    barrier();
    if (needs) {
        // the tracer's radiance stands for this pixel's off-screen directions when the two
        // face alike, shrunk towards the mean of this pixel's known (on-screen) directions by
        // the share of its directions that are known: one traced ray per tile and frame is
        // unbiased but noisy (a ray meeting the sun patch), the on-screen mean is smooth but
        // stands for the off-screen directions only when most directions are known
        // (sunlit_room q1/q2/q3 over 3 seeds 0.0130/0.0105/0.0113 -> 0.0116/0.0084/0.0099;
        // bounce_room ceiling 0.071 -> 0.019); otherwise (an edge in the tile) they are
        // unknown: the mean of the known
        if (dot(N, s_N[tile]) > 0.8) {
            float known = float(n) - wunknown - unknown;
            vec3 mean_known = known > 0.0 ? bounce / known : s_L[tile].rgb;
            bounce += wunknown * mix(s_L[tile].rgb, mean_known, known / float(n));
        } else {
            unknown += wunknown;
        }
    }
    // GI_AO: an off-screen direction counts as open, whatever the trace met (the AO AOV's
    // meaning is the screen-space occlusion within the radius and the on-screen far field)
    open += wunknown;
#endif
    if (!inside) return;
    if (!live) { imageStore(o_ssdo, q, vec4(0.0, 0.0, 0.0, 1.0)); return; }
    // the bounce is the mean over the directions whose outcome is known (screen space or the
    // tile's trace); the unknown ones are assumed to look like those (not open, not black)
    imageStore(o_ssdo, q, vec4(sanitize(bounce / max(float(n) - unknown, 1.0)), open / float(n)));
}
