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
// Output (at u_scale of the full resolution): rgb = mean sender radiance over all samples,
// a = cosine-weighted fraction of directions that stay open (the GI_AO AOV).
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
uniform int u_samples;
uniform float u_radius;
uniform float u_bias;

void main() {
    ivec2 q = ivec2(gl_GlobalInvocationID.xy);
    ivec2 osize = imageSize(o_ssdo);
    if (any(greaterThanEqual(q, osize))) return;
    ivec2 px = ivec2((vec2(q) + 0.5) * u_resolution / vec2(osize));
    GPixel g = fetch_g(px);
    if (!g.valid) { imageStore(o_ssdo, q, vec4(0.0, 0.0, 0.0, 1.0)); return; }
    vec3 N = g.N;
    vec3 O = g.P + g.Ng * u_bias;
    float d0 = view_depth(g.P);
    vec4 rnd = pixel_noise(px, 13u);
    float rot = TWO_PI * rnd.x;
    float cr = cos(rot), sr = sin(rot);
    vec3 bounce = vec3(0.0);
    float open = 0.0, unknown = 0.0;
    int n = max(u_samples, 1);
    for (int i = 0; i < n; ++i) {
        float u1 = (float(i) + rnd.y) / float(n);
        float phi = float(i) * 2.39996323;
        vec2 dsk = sqrt(u1) * vec2(cos(phi), sin(phi));
        dsk = vec2(cr * dsk.x - sr * dsk.y, sr * dsk.x + cr * dsk.y);
        vec3 dir = to_world(vec3(dsk, sqrt(max(0.0, 1.0 - dot(dsk, dsk)))), N);
        float s = fract(float(i) * 0.618034 + rnd.z);
        vec3 S = O + dir * (u_radius * mix(0.1, 1.0, s));
        vec2 sp = to_pixel(S);
        if (!on_screen(sp)) { open += 1.0; unknown += 1.0; continue; }   // unknown to screen space
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
                open += 1.0;
                unknown += 1.0;
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
    // the bounce is the mean over the directions whose outcome screen space knows; the
    // unknown ones (off screen) are assumed to look like those (not open, not black)
    imageStore(o_ssdo, q, vec4(sanitize(bounce / max(float(n) - unknown, 1.0)), open / float(n)));
}
