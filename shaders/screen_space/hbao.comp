// hbao.comp — HBAO in the cosine-weighted (GTAO) form.
// Papers: Bavoil, Sainz & Dimitrov 2008 ("Image-space horizon-based ambient occlusion");
// Jimenez et al. 2016 ("Practical real-time strategies for accurate indirect occlusion", GTAO).
// For u_directions screen-space slice directions per pixel (rotated per pixel and frame),
// march u_steps samples on both sides within the projected radius, keep the highest
// horizon (max cos to the view vector) with a distance falloff to the radius, and integrate
// the cosine-weighted visible arc between the two horizons analytically against the normal
// projected into the slice (GTAO's inner integral). The slices' average is the cosine-
// weighted visibility within the radius, the quantity Cycles' AO node computes.
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

uniform int u_directions;
uniform int u_steps;
uniform float u_radius;    // world units (= Cycles' AO distance)
uniform float u_falloff;   // fraction of the radius over which occluders fade out
uniform float u_bias;      // world units
uniform mat4 u_view;       // world -> view

vec3 to_view(vec3 P) { return (u_view * vec4(P, 1.0)).xyz; }

void main() {
    ivec2 q = ivec2(gl_GlobalInvocationID.xy);
    ivec2 osize = imageSize(o_ao);
    if (any(greaterThanEqual(q, osize))) return;
    ivec2 px = ivec2((vec2(q) + 0.5) * u_resolution / vec2(osize));
    GPixel g = fetch_g(px);
    if (!g.valid) { imageStore(o_ao, q, vec4(1.0)); return; }
    vec3 Pv = to_view(g.P + g.Ng * u_bias);
    vec3 Nv = normalize(mat3(u_view) * g.N);
    vec3 Vv = u_ortho == 1 ? vec3(0.0, 0.0, 1.0) : normalize(-Pv);
    float d0 = view_depth(g.P);
    float r_px = u_radius * pixels_per_unit(d0);
    vec4 rnd = pixel_noise(px, 12u);
    int nd = max(u_directions, 1);
    int ns = max(u_steps, 1);
    float vis = 0.0;
    vec2 center = vec2(px) + 0.5;
    float fall0 = u_radius * (1.0 - clamp(u_falloff, 0.0, 1.0));
    for (int d = 0; d < nd; ++d) {
        float phi = PI * (float(d) + rnd.x) / float(nd);
        vec2 dir2 = vec2(cos(phi), sin(phi));
        // slice plane: contains V and the screen direction (view-space x right, y up)
        vec3 dirv = vec3(dir2, 0.0);
        vec3 ortho_dir = dirv - dot(dirv, Vv) * Vv;
        vec3 axis = normalize(cross(dirv, Vv));
        vec3 np = Nv - axis * dot(Nv, axis);
        float nlen = length(np);
        if (nlen < 1e-6) continue;
        float cos_n = clamp(dot(np, Vv) / nlen, -1.0, 1.0);
        float n = (dot(np, ortho_dir) < 0.0 ? -1.0 : 1.0) * acos(cos_n);
        // horizons start at the tangent plane: side +dir at n + pi/2, side -dir at n - pi/2
        float low_pos = cos(n + PI * 0.5);
        float low_neg = cos(n - PI * 0.5);
        float hc_pos = low_pos, hc_neg = low_neg;
        for (int side = 0; side < 2; ++side) {
            vec2 sd = side == 0 ? dir2 : -dir2;
            float low = side == 0 ? low_pos : low_neg;
            float best = low;
            for (int k = 0; k < ns; ++k) {
                float t = (float(k) + rnd.y) / float(ns);
                float off = max(1.0, t * t * r_px);   // denser near the pixel
                vec2 sp = center + sd * off;
                if (!on_screen(sp)) break;
                GPixel h = fetch_g(ivec2(sp));
                if (!h.valid) continue;
                vec3 S = to_view(h.P) - Pv;
                float len = length(S);
                if (len < 1e-6 || len > u_radius) continue;
                float c = dot(S / len, Vv);
                float w = 1.0 - clamp((len - fall0) / max(u_radius - fall0, 1e-6), 0.0, 1.0);
                best = max(best, mix(low, c, w));
            }
            if (side == 0) hc_pos = best; else hc_neg = best;
        }
        float h0 = -acos(clamp(hc_neg, -1.0, 1.0));
        float h1 = acos(clamp(hc_pos, -1.0, 1.0));
        h0 = n + clamp(h0 - n, -PI * 0.5, PI * 0.5);
        h1 = n + clamp(h1 - n, -PI * 0.5, PI * 0.5);
        float sn = sin(n);
        float a = 0.25 * (-cos(2.0 * h0 - n) + cos_n + 2.0 * h0 * sn)
                + 0.25 * (-cos(2.0 * h1 - n) + cos_n + 2.0 * h1 * sn);
        vis += nlen * a;
    }
    float ao = clamp(vis / float(nd), 0.0, 1.0);
    imageStore(o_ao, q, vec4(vec3(ao), 1.0));
}
