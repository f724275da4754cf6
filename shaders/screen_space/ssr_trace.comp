// ssr_trace.comp — SSR ray generation and Hi-Z ray marching.
// Papers: McGuire & Mara 2014 ("Efficient GPU screen-space ray tracing"); Uludag 2014
// ("Hi-Z screen-space cone-traced reflections", GPU Pro 5); Stachowiak 2015 ("Stochastic
// screen-space reflections"); Heitz 2018 (GGX visible-normal sampling).
// One ray per (scaled) pixel and frame: the half-vector is drawn from GGX's visible normals
// (lib/brdf.glsl), the ray is projected to a screen-space segment whose device depth is
// linear in the segment parameter, and marched on the Hi-Z min pyramid: a cell the ray
// passes entirely in front of is skipped and the level goes up; otherwise the level goes
// down. At level 0 the pixel's surface is taken as its plane (G-buffer position and
// geometric normal), not as one depth: the ray hits when it crosses that plane inside the
// pixel from the front, or when it entered the pixel already behind the plane by at most
// u_thickness (measured along the normal, so a wall seen at a grazing angle, whose depth
// changes by more than the thickness from one pixel to the next, still stops the ray).
// A ray behind the plane by more passes behind the object and continues; a ray still in
// front (the pixel's centre depth is nearer than its plane where the ray is) continues.
// (Before: one depth per pixel compared with the ray's depth within u_thickness in view
// depth, so grazing walls and floors were crossed between two samples and their
// reflections broke into speckles; and a back-face hit ended the ray as a miss.)
// Rays that leave the screen or reach u_max_distance miss; their share falls back to SSR's
// miss trace (ssr_miss.comp, the same rays through the scene's BVH; with miss_trace 0 or a
// caller's own fallback: DIRECT's shadowed world reflection or that fallback), and hits fade
// out near the screen edges.
// Outputs: ray0 = (direction xyz, pdf; pdf 0 = no ray; the pdf is computed in a form that
// stays finite for mirrors, common.glsl), ray1 = (hit pixel xy, confidence, hit distance).
// The resolve pass (ssr_resolve.comp) turns them into reflected radiance.
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/rng.glsl"
#include "lib/sampling.glsl"
#include "lib/brdf.glsl"
#include "lib/screen.glsl"
#include "screen_space/common.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform writeonly image2D o_ray0;
layout(binding = 1, rgba32f) uniform writeonly image2D o_ray1;

uniform sampler2D u_hiz;
uniform int u_hiz_levels;
uniform int u_steps;          // max traversal iterations
uniform float u_thickness;    // world units
uniform float u_max_distance; // world units
uniform float u_max_roughness;
uniform float u_edge_fade;    // fraction of the screen
uniform float u_near;
uniform float u_bias;
uniform int u_rough_trace;    // 1: surfaces rougher than u_max_roughness draw a ray for the miss trace only

void main() {
    ivec2 q = ivec2(gl_GlobalInvocationID.xy);
    ivec2 osize = imageSize(o_ray0);
    if (any(greaterThanEqual(q, osize))) return;
    ivec2 px = ivec2((vec2(q) + 0.5) * u_resolution / vec2(osize));
    GPixel g = fetch_g(px);
    imageStore(o_ray1, q, vec4(-1.0, -1.0, 0.0, 0.0));
    if (!g.valid) { imageStore(o_ray0, q, vec4(0.0)); return; }
    Surface s = fetch_surface(px, g.mid);
    vec3 V = view_dir(g.P);
    vec3 N = g.N;
    float NoV = max(dot(N, V), 1e-4);
    bool rough = s.roughness > u_max_roughness;
    if ((rough && u_rough_trace == 0) || max3(specular_albedo(s, NoV)) < 1e-4) {
        imageStore(o_ray0, q, vec4(0.0));
        return;
    }
    vec4 rnd = pixel_noise(px, 21u);
    vec3 Vl = to_local(V, N);
    vec3 Hl = sample_ggx_vndf(Vl, s.alpha, rnd.xy);
    vec3 L = to_world(reflect(-Vl, Hl), N);
    float NoL = dot(N, L);
    float pdf = ss_vndf_pdf(N, V, normalize(V + L), s.alpha * s.alpha);
    if (NoL <= 0.0 || dot(g.Ng, L) <= 0.0 || !(pdf > 0.0)) {
        imageStore(o_ray0, q, vec4(L, 0.0));
        return;
    }
    imageStore(o_ray0, q, vec4(L, min(pdf, FLT_MAX)));
    // rougher than u_max_roughness (u_rough_trace): no screen march, the whole lobe is left to
    // the miss trace (ssr_miss.comp traces this ray through the scene)
    if (rough) return;
    // ---- the ray as a screen-space segment
    vec3 O = g.P + g.Ng * u_bias;
    float dO = view_depth(O);
    float dl = dot(L, u_camera_fwd);
    float len = u_max_distance;
    if (u_ortho == 0 && dl < 0.0) len = min(len, 0.99 * (dO - u_near) / -dl);
    if (len <= 1e-5) return;
    vec3 E = O + L * len;
    vec4 c0 = to_clip(O), c1 = to_clip(E);
    vec3 s0 = vec3((c0.xy / c0.w * 0.5 + 0.5) * u_resolution, c0.z / c0.w);
    vec3 s1 = vec3((c1.xy / c1.w * 0.5 + 0.5) * u_resolution, c1.z / c1.w);
    float iw0 = 1.0 / c0.w, iw1 = 1.0 / c1.w;
    vec3 D = s1 - s0;
    // clip the segment to the screen
    float t_exit = 1.0;
    for (int a = 0; a < 2; ++a) {
        if (D[a] > 1e-6) t_exit = min(t_exit, (u_resolution[a] - 1e-3 - s0[a]) / D[a]);
        else if (D[a] < -1e-6) t_exit = min(t_exit, (1e-3 - s0[a]) / D[a]);
    }
    float dpix = max(abs(D.x), abs(D.y));
    if (dpix < 1e-3 || t_exit <= 0.0) return;
    float t = (1.0 + rnd.z) / dpix;    // start about one pixel away (jittered)
    int level = 0;
    int max_level = max(u_hiz_levels - 1, 0);
    bool hit = false;
    vec2 hit_pix = vec2(-1.0);
    float hit_t = 0.0;
    ivec2 res0 = ivec2(u_resolution);
    for (int it = 0; it < u_steps && t <= t_exit; ++it) {
        vec2 p = s0.xy + D.xy * t;
        // the sizes HiZPass reduced to; textureSize(u_hiz, level) with a varying level
        // returned wrong sizes on llvmpipe (cells clamped to the last row: whole-screen
        // skips, the vertical bands of missed reflections)
        ivec2 lsize = max(res0 >> level, ivec2(1));
        ivec2 cell = min(ivec2(p) >> level, lsize - 1);
        ivec2 lo = cell << level;
        ivec2 hi = ivec2(cell.x == lsize.x - 1 ? res0.x : (cell.x + 1) << level,
                         cell.y == lsize.y - 1 ? res0.y : (cell.y + 1) << level);
        float tx = D.x > 1e-6 ? (float(hi.x) - s0.x) / D.x : (D.x < -1e-6 ? (float(lo.x) - s0.x) / D.x : 1e30);
        float ty = D.y > 1e-6 ? (float(hi.y) - s0.y) / D.y : (D.y < -1e-6 ? (float(lo.y) - s0.y) / D.y : 1e30);
        float t_out = max(min(tx, ty), t) + 1e-4 / dpix;
        float z_in = s0.z + D.z * t;
        float z_out = s0.z + D.z * min(t_out, t_exit);
        float zc = texelFetch(u_hiz, cell, level).r;
        if (max(z_in, z_out) < zc) {           // in front of everything in the cell
            t = t_out;
            level = min(level + 1, max_level);
            continue;
        }
        if (level > 0) { level -= 1; continue; }
        // level 0: the pixel's surface as a plane; where is the ray relative to it?
        vec4 hp4 = texelFetch(u_gb_position, cell, 0);
        float t1 = min(t_out, t_exit);
        if (hp4.w >= 0.0) {
            vec3 Nc = normalize(texelFetch(u_gb_geonormal, cell, 0).xyz + vec3(0.0, 0.0, 1e-12));
            if (dot(Nc, view_dir(hp4.xyz)) < 0.0) Nc = -Nc;     // the side the camera sees
            float sa = dot(Nc, mix(O * iw0, E * iw1, t) / mix(iw0, iw1, t) - hp4.xyz);
            float sb = dot(Nc, mix(O * iw0, E * iw1, t1) / mix(iw0, iw1, t1) - hp4.xyz);
            bool entering = dot(Nc, L) < 0.0;                    // towards the visible side
            if (entering && sb <= 0.0 && sa >= -u_thickness) {
                // crossed the plane inside this pixel, or entered it less than the
                // thickness behind (the crossing fell between two samples)
                hit = true;
                hit_pix = vec2(cell) + 0.5;
                hit_t = sa > 0.0 ? mix(t, t1, sa / max(sa - sb, 1e-12)) : t;
                break;
            }
        }
        t = t_out;   // background, in front of the plane, behind a thin object or its back face
        level = min(1, max_level);   // and climb again: the next cells may be skipped whole
    }
    if (!hit) return;
    GPixel h = fetch_g(ivec2(hit_pix));
    if (!h.valid) return;
    float conf = edge_fade(hit_pix, u_edge_fade);
    // fade rays that hit near the end of their allowed length
    float dist = length(h.P - O);
    conf *= 1.0 - smoothstep(0.8 * u_max_distance, u_max_distance, dist);
    imageStore(o_ray1, q, vec4(hit_pix, conf, dist));
}
