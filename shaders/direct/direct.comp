// direct.comp — DIRECT: direct lighting from every light type and emissive meshes, with
// shadow-map visibility, emission, and the world as background only (no ambient).
// Diffuse: exact (the lights' irradiance, lib/lights.glsl light_irradiance: cosine law for
// point/sphere/sun, polygon irradiance for area lights and emissive triangles). Glossy: Monte Carlo with multiple importance sampling (light
// sampling + GGX visible-normal sampling, power heuristic), converging over frames.
// The world: background, and a light like any other (as in Cycles' "direct" reference): its
// irradiance at the normal (lib/world.glsl: exact for a uniform world, order-2 SH for a map)
// times the diffuse albedo, its radiance prefiltered around the glossy lobe's dominant
// direction times the specular albedo, each shadowed by the world visibility from the
// orthographic maps the shadow pass renders along directions sampled each frame (by the
// map's luminance for a world map, so the visibility is weighted by where the light comes from).
// Reads the G-buffer; writes color, GI_Direct, Emit and the world's glossy term (for SSR).
//
// Many lights (docs/techniques/DIRECT.md): each pixel shades the lights of its 16x16 tile's
// list (light_cull.comp: lights whose range of influence meets the tile). A listed light
// with a shadow map is shadowed by it; listed lights that cast shadows but got no shadow map
// (over the shadow pass's budget) are shadowed by ray tracing through the shared scene
// component (lib/scene_rt.glsl): their unshadowed sum minus the light shadows take away,
// estimated with u_rt_shadow_rays lights per pixel per frame chosen by weighted reservoir
// sampling in proportion to their unshadowed contribution, one shadow ray to a point sampled
// on each (c_j b_j W / w_j, b_j the blocked share of the weights of the rays to that light).
// Lights not in the tile's list are
// estimated with u_far_samples light samples per pixel chosen by power (select_light), counted
// only when the chosen light is not listed (unbiased). A light with size that the shadow pass
// left to rays because its moving maps would cost more (Light.shadow.x = -1) gets
// u_rt_shadow_rays rays of its own, to points sampled on it (rt_light_visibility). All the
// ray-traced parts need DIRECT_RT.
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/rng.glsl"
#include "lib/sampling.glsl"
#include "lib/brdf.glsl"
#include "lib/lights.glsl"
#include "lib/shadows.glsl"
#include "lib/albedo.glsl"
#include "lib/world.glsl"
#ifdef DIRECT_RT
#include "lib/scene_rt.glsl"
#endif

layout(local_size_x = 8, local_size_y = 8) in;

layout(binding = 0, rgba32f) uniform writeonly image2D o_color;
layout(binding = 1, rgba32f) uniform writeonly image2D o_direct;
layout(binding = 2, rgba32f) uniform writeonly image2D o_emit;
layout(binding = 3, rgba32f) uniform writeonly image2D o_world_spec;

uniform sampler2D u_gb_albedo;
uniform sampler2D u_gb_normal;
uniform sampler2D u_gb_position;
uniform sampler2D u_gb_geonormal;
uniform sampler2D u_gb_emission;
uniform vec3 u_camera_pos;
uniform int u_ortho;
uniform vec3 u_camera_dir;
uniform uint u_sample;
uniform int u_glossy_samples;
uniform int u_mesh_exact_max;
uniform int u_world_first;
uniform int u_world_count;  // 0: the world lights nothing (black, or no world views)
// per-tile light lists (light_cull.comp)
layout(std430, binding = 6) readonly buffer TileLights { int tile_lights[]; };
uniform int u_tile_capacity;
uniform int u_tiles_x;
uniform int u_tile_size;
uniform int u_rt_shadow_rays;  // shadow rays per pixel: the reservoirs of the lights over the budget, and
                               // each light left to rays by the shadow pass
uniform int u_far_samples;     // light samples per pixel for the lights not listed

// Glossy lobe only: f*cos and its pdf under visible-normal sampling.
vec3 glossy_fcos(Surface s, vec3 N, vec3 V, vec3 L) { return eval_principled(s, N, V, L).glossy; }
float glossy_pdf(Surface s, vec3 N, vec3 V, vec3 L) {
    if (dot(N, L) <= 0.0) return 0.0;
    vec3 H = normalize(V + L);
    return ggx_vndf_pdf(max(dot(N, V), 1e-4), max(dot(N, H), 0.0), s.alpha * s.alpha);
}
vec3 sample_glossy(Surface s, vec3 N, vec3 V, vec2 u) {
    vec3 Hl = sample_ggx_vndf(to_local(V, N), s.alpha, u);
    return to_world(reflect(-to_local(V, N), Hl), N);
}

// The light-sampling half of the glossy MIS: one sample_light() direction, power heuristic
// against visible-normal sampling; divided by the number of sample pairs.
vec3 glossy_light_sample(Light L, Surface s, vec3 P, vec3 N, vec3 V, vec3 u) {
    LightSample ls = sample_light(L, P, u.xy, u.z);
    if (ls.pdf <= 0.0) return vec3(0.0);
    float pb = glossy_pdf(s, N, V, ls.dir);
    return ls.Li * glossy_fcos(s, N, V, ls.dir) * power_heuristic(ls.pdf, pb) / (ls.pdf * float(u_glossy_samples));
}

// The BSDF half of the glossy MIS: one visible-normal direction; if it sees light L
// (light_ray_hit, the one copy PT uses too) its radiance weighted against light sampling.
vec3 glossy_bsdf_sample(Light L, Surface s, vec3 P, vec3 N, vec3 V, vec2 u) {
    vec3 w2 = sample_glossy(s, N, V, u);
    vec3 Le;
    float pl;
    if (!light_ray_hit(L, P, w2, 0.0, T_INF, Le, pl)) return vec3(0.0);
    float pb = glossy_pdf(s, N, V, w2);
    if (pb <= 0.0) return vec3(0.0);
    return Le * glossy_fcos(s, N, V, w2) * power_heuristic(pb, pl) / (pb * float(u_glossy_samples));
}

// Diffuse BRDF constant (Lambert under the specular layer), i.e. f_d = this / 1.
vec3 diffuse_brdf(Surface s, vec3 N, vec3 V) {
    float layer = 1.0 - dielectric_layer_albedo(s, max(dot(N, V), 1e-4));
    return (1.0 - s.metallic) * s.base_color * INV_PI * layer;
}

// Unshadowed light of light li at the shading point. Delta lights: the BSDF in their one
// direction. The others: diffuse from their exact irradiance (light_irradiance), glossy by
// u_glossy_samples pairs of a light sample and a visible-normal sample, MIS'd by the power
// heuristic where a BSDF ray can hit the light (light_has_shape), else (mesh lights) light
// samples alone with weight 1.
vec3 shade_light(int li, Surface s, vec3 P, vec3 N, vec3 V, inout Rng rng) {
    Light L = lights[li];
    if (light_is_delta(L)) {
        LightSample ls = sample_light(L, P, vec2(0.0), 0.0);
        BsdfEval e = eval_principled(s, N, V, ls.dir);
        return ls.Li * (e.diffuse + e.glossy);
    }
    vec3 result = diffuse_brdf(s, N, V) * light_irradiance(L, P, N, u_mesh_exact_max, rng);
    if (s.metallic > 0.0 || s.f0 > 0.0) {
        bool mis = light_has_shape(L);
        for (int k = 0; k < u_glossy_samples; ++k) {
            vec4 u = rng_next4(rng);
            if (mis) {
                result += glossy_light_sample(L, s, P, N, V, u.xyz);
                result += glossy_bsdf_sample(L, s, P, N, V, u.zw);
            } else {
                LightSample ls = sample_light(L, P, u.xy, u.z);
                if (ls.pdf > 0.0)
                    result += ls.Li * glossy_fcos(s, N, V, ls.dir) / (ls.pdf * float(u_glossy_samples));
            }
        }
    }
    return result;
}

#ifdef DIRECT_RT
#ifndef RT_MAX_RESERVOIRS
#define RT_MAX_RESERVOIRS 8
#endif
// One point sampled on light L, seen from the offset origin Po (the ray-traced counterpart
// of the shadow maps, for lights without one): .x = the irradiance it stands for (Li cos / pdf,
// luminance; 0 below the shading normal's horizon, where it is no part of the light's
// irradiance), .y = 1 if the ray to it is blocked (below the geometric horizon: by the surface
// itself). Shares of blocked light are ratios of these weights, never of bare hit counts: a
// light half below a wall's horizon is not half in shadow.
vec2 rt_light_sample(Light L, vec3 Po, vec3 N, vec3 Ng, inout Rng rng) {
    vec4 u = rng_next4(rng);
    LightSample ls = sample_light(L, Po, u.xy, u.z);
    float cosn = dot(ls.dir, N);
    // nothing sampled (inside a sphere light), or no part of the irradiance
    if (ls.pdf <= 0.0 || cosn <= 0.0) return vec2(0.0);
    float w = luminance(ls.Li) * cosn / (ls.delta ? 1.0 : ls.pdf);
    bool blocked = dot(ls.dir, Ng) <= 0.0 || scene_occluded(Po, ls.dir, 0.0, ls.dist * (1.0 - 1e-4));
    return vec2(w, blocked ? 1.0 : 0.0);
}

// Visibility of light L from n points sampled on it: the unblocked share of their weights (a
// ratio estimator, as the shadow maps' origins are averaged: exactly 1 unoccluded, 0 in umbra)
float rt_light_visibility(Light L, vec3 Po, vec3 N, vec3 Ng, int n, inout Rng rng) {
    float num = 0.0, den = 0.0;
    for (int k = 0; k < n; ++k) {
        vec2 s = rt_light_sample(L, Po, N, Ng, rng);
        num += s.x * (1.0 - s.y);
        den += s.x;
    }
    return den > 0.0 ? num / den : 1.0;
}

// Visibility of a light outside the tile's list from one sampled point: 1 - its blocked
// irradiance over the light's unshadowed irradiance E (unbiased; clamped at 0)
float rt_far_visibility(Light L, vec3 Po, vec3 N, vec3 Ng, inout Rng rng) {
    vec2 s = rt_light_sample(L, Po, N, Ng, rng);
    if (s.y <= 0.0) return 1.0;
    float E = luminance(light_irradiance(L, Po, N, u_mesh_exact_max, rng));
    return E > 0.0 ? max(1.0 - s.x / E, 0.0) : 0.0;
}

// Is light j in the tile's list (ascending indices)?
bool tile_listed(int base, int listed, int j) {
    int lo = 0, hi = listed - 1;
    while (lo <= hi) {
        int mid = (lo + hi) / 2;
        int v = tile_lights[base + 1 + mid];
        if (v == j) return true;
        if (v < j) lo = mid + 1; else hi = mid - 1;
    }
    return false;
}
#endif

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    ivec2 size = imageSize(o_color);
    if (any(greaterThanEqual(px, size))) return;
    vec4 pos = texelFetch(u_gb_position, px, 0);
    if (pos.w < 0.0) {
        imageStore(o_color, px, vec4(sanitize(world_background(px, size)), 1.0));
        imageStore(o_direct, px, vec4(0.0, 0.0, 0.0, 1.0));
        imageStore(o_emit, px, vec4(0.0, 0.0, 0.0, 1.0));
        imageStore(o_world_spec, px, vec4(0.0, 0.0, 0.0, 1.0));
        return;
    }
    int mid = int(pos.w + 0.5);
    vec3 P = pos.xyz;
    vec4 gb_n = texelFetch(u_gb_normal, px, 0);
    vec4 gb_ng = texelFetch(u_gb_geonormal, px, 0);
    vec3 N = normalize(gb_n.xyz);
    vec3 Ng = normalize(gb_ng.xyz);
    vec3 V = u_ortho == 1 ? -u_camera_dir : normalize(u_camera_pos - P);
    Surface s = gbuffer_surface(materials[mid], texelFetch(u_gb_albedo, px, 0), gb_n, gb_ng,
                                texelFetch(u_gb_emission, px, 0).rgb);
    Rng rng = rng_init(uvec2(px), u_sample, 1u);
    vec3 direct = vec3(0.0);
    int tile = (px.y / u_tile_size) * u_tiles_x + px.x / u_tile_size;
    int base = tile * (u_tile_capacity + 1);
    int listed = tile_lights[base];
#ifdef DIRECT_RT
    // shadow rays leave from the G-buffer point moved off the surface (scale-aware: the
    // rasterised position is not exactly on the BVH's triangle)
    vec3 Po = rt_offset_ray(P + Ng * (2e-5 * length(P - u_camera_pos) + 1e-6), Ng);
    int r_idx[RT_MAX_RESERVOIRS];
    vec3 r_c[RT_MAX_RESERVOIRS];
    float r_w[RT_MAX_RESERVOIRS];
    for (int j = 0; j < RT_MAX_RESERVOIRS; ++j) { r_idx[j] = -1; r_c[j] = vec3(0.0); r_w[j] = 0.0; }
    float wsum = 0.0;
    vec3 unshadowed = vec3(0.0);  // sum of the unshadowed contributions of the reservoir's candidates
    int K = min(u_rt_shadow_rays, RT_MAX_RESERVOIRS);
#endif
    for (int k = 0; k < listed; ++k) {
        int i = tile_lights[base + 1 + k];
        vec3 c = shade_light(i, s, P, N, V, rng);
        if (max3(c) <= 0.0) continue;
#ifdef DIRECT_RT
        Light L = lights[i];
        if (L.axis_w.w > 0.5 && L.shadow.x < -0.5) {  // a light with size the shadow pass left to rays
            direct += c * rt_light_visibility(L, Po, N, Ng, u_rt_shadow_rays, rng);
            continue;
        }
        if (L.axis_w.w > 0.5 && L.shadow.y < 0.5 && K > 0) {  // casts shadows, no shadow map
            float w = max(luminance(c), 1e-30);
            wsum += w;
            unshadowed += c;
            for (int j = 0; j < K; ++j) {
                if (rng_next(rng) * wsum <= w) { r_idx[j] = i; r_c[j] = c; r_w[j] = w; }
            }
            continue;
        }
#endif
        direct += c * light_visibility(lights[i], P, N, Ng);
    }
#ifdef DIRECT_RT
    // sum c_i V_i = sum c_i - sum c_i (1 - V_i): the unshadowed sum is exact, only the light
    // the shadows take away is estimated (c_j (1 - V_j) W / w_j per reservoir): no noise where
    // every candidate is visible, whatever the lights' colours
    // each reservoir's share of blocked light is the ratio over the rays of every reservoir
    // that holds the same light (weights: the irradiance each point stands for): exactly 0
    // where the light is unoccluded and 1 in its umbra, whatever the single rays read
    vec2 r_s[RT_MAX_RESERVOIRS];
    for (int j = 0; j < K; ++j)
        r_s[j] = r_idx[j] < 0 ? vec2(0.0) : rt_light_sample(lights[r_idx[j]], Po, N, Ng, rng);
    vec3 taken = vec3(0.0);
    for (int j = 0; j < K; ++j) {
        if (r_idx[j] < 0) continue;
        float num = 0.0, den = 0.0;
        for (int k = 0; k < K; ++k) {
            if (r_idx[k] != r_idx[j]) continue;
            num += r_s[k].x * r_s[k].y;
            den += r_s[k].x;
        }
        float blocked = den > 0.0 ? num / den : 0.0;
        taken += r_c[j] * (blocked * wsum / (r_w[j] * float(K)));
    }
    // a channel can overshoot (a blocked light of another colour than the rest): clamp at 0
    // (in luminance the estimate never overshoots: w = luminance)
    if (wsum > 0.0) direct += max(unshadowed - taken, vec3(0.0));
    // lights outside the tile's list: one light by power, counted when it is not listed
    for (int f = 0; f < u_far_samples && listed < u_light_count; ++f) {
        float sel;
        int j = select_light(rng_next(rng), sel);
        if (sel <= 0.0 || tile_listed(base, listed, j)) continue;
        vec3 c = shade_light(j, s, P, N, V, rng);
        if (max3(c) <= 0.0) continue;
        Light L = lights[j];
        float vis = L.axis_w.w < 0.5 ? 1.0
                  : (L.shadow.y > 0.5 ? light_visibility(L, P, N, Ng) : rt_far_visibility(L, Po, N, Ng, rng));
        direct += c * (vis / (sel * float(u_far_samples)));
    }
#endif
    vec3 world_spec = vec3(0.0);
    if (u_world_count > 0) {
        float a = s.alpha;
        vec3 D = specular_dominant_dir(N, V, a);
        float vis_d, vis_g;
        world_visibility(u_world_first, u_world_count, P, N, Ng, D, vis_d, vis_g);
        float NoV = max(dot(N, V), 1e-4);
        direct += world_irradiance(N) * INV_PI * diffuse_albedo(s, NoV) * vis_d;
        world_spec = sanitize(world_glossy(D, a) * specular_albedo(s, NoV) * vis_g);
        direct += world_spec;
    }
    direct = sanitize(direct);
    vec3 emit = sanitize(s.emission);
    imageStore(o_color, px, vec4(direct + emit, 1.0));
    imageStore(o_direct, px, vec4(direct, 1.0));
    imageStore(o_emit, px, vec4(emit, 1.0));
    imageStore(o_world_spec, px, vec4(world_spec, 1.0));
}
