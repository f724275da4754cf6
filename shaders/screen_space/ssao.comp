// ssao.comp — SSAO: screen-space ambient occlusion.
// Papers: Mittring 2007 ("Finding next gen: CryEngine 2"); Shanmugam & Orikan 2007
// ("Hardware accelerated ambient occlusion techniques on GPUs").
// Normal-oriented hemisphere kernel: u_samples cosine-distributed directions around the
// shading normal, rotated per pixel and per frame (a random rotation about the normal),
// with u_points kernel points each at distances r * lerp(0.1, 1, x^2) (denser near the
// point; u_points = 1 is the classic one-point kernel, which under-occludes: a point in
// front of an occluder that the direction would hit within r counts as open). Each point is
// projected to the screen and compared with the G-buffer depth there: it is occluded when
// it lies behind the visible surface by more than a small bias, and the range check fades
// occluders whose depth differs from the point's by more than the radius (no halos from
// far-away foreground). A direction is occluded if any of its points is. AO = 1 - occluded
// fraction (cosine-weighted, as Cycles' AO); 1 on the background.
// Output (at u_scale of the full resolution): rgb = AO, a = 1.
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/rng.glsl"
#include "lib/sampling.glsl"
#include "lib/brdf.glsl"
#include "lib/screen.glsl"
#include "screen_space/common.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba16f) uniform writeonly image2D o_ao;

uniform int u_samples;
uniform int u_points;   // kernel points per direction (1 = the classic kernel)
uniform float u_radius;   // world units (= Cycles' AO distance)
uniform float u_bias;     // world units

void main() {
    ivec2 q = ivec2(gl_GlobalInvocationID.xy);
    ivec2 osize = imageSize(o_ao);
    if (any(greaterThanEqual(q, osize))) return;
    ivec2 px = ivec2((vec2(q) + 0.5) * u_resolution / vec2(osize));
    GPixel g = fetch_g(px);
    if (!g.valid) { imageStore(o_ao, q, vec4(1.0)); return; }
    vec3 V = view_dir(g.P);
    vec3 N = g.N;
    // offset the origin along the geometric normal (self-occlusion of flat surfaces)
    vec3 O = g.P + g.Ng * u_bias;
    float d0 = view_depth(g.P);
    vec4 rnd = pixel_noise(px, 11u);
    float rot = TWO_PI * rnd.x;
    float cr = cos(rot), sr = sin(rot);
    float occ = 0.0;
    int n = max(u_samples, 1);
    int m = max(u_points, 1);
    for (int i = 0; i < n; ++i) {
        // stratified cosine-weighted direction (golden-angle spiral), rotated per pixel
        float u1 = (float(i) + rnd.y) / float(n);
        float phi = float(i) * 2.39996323;
        vec2 dsk = sqrt(u1) * vec2(cos(phi), sin(phi));
        dsk = vec2(cr * dsk.x - sr * dsk.y, sr * dsk.x + cr * dsk.y);
        vec3 dir = to_world(vec3(dsk, sqrt(max(0.0, 1.0 - dot(dsk, dsk)))), N);
        float s = fract(float(i) * 0.618034 + rnd.z);
        float o = 0.0;
        for (int k = 0; k < m; ++k) {
            // the kernel point(s) of this direction: denser near P (lerp(0.1, 1, x^2))
            float x = (float(k) + s) / float(m);
            vec3 S = O + dir * (u_radius * mix(0.1, 1.0, x * x));
            vec2 sp = to_pixel(S);
            if (!on_screen(sp)) break;         // off screen: nothing known, counts as open
            GPixel h = fetch_g(ivec2(sp));
            if (!h.valid) continue;
            float ds = view_depth(S);
            float dh = view_depth(h.P);
            if (dh < ds - u_bias) {
                // range check: an occluder much nearer the camera than P is not near P
                o = max(o, smoothstep(0.0, 1.0, u_radius / max(abs(d0 - dh), 1e-6)));
                if (o >= 1.0) break;
            }
        }
        occ += o;
    }
    float ao = clamp(1.0 - occ / float(n), 0.0, 1.0);
    imageStore(o_ao, q, vec4(vec3(ao), 1.0));
}
