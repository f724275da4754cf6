// restir_di.comp — ReSTIR DI (Bitterli et al. 2020, "Spatiotemporal reservoir resampling for
// real-time ray tracing with dynamic direct lighting").
// Samples live in primary sample space: a reservoir holds u = (light select, 2D point, emitter
// select) in [0,1)^4, mapped to a light point by the shared sampler (select_light +
// sample_light) at whichever pixel evaluates it, so reusing it at another pixel needs no
// Jacobian. Target p^(u) = luminance(f Li cos / (p_sel p_light)) (the unshadowed
// contribution); candidates have pdf 1 in this space.
// STAGE 0: u_candidates RIS candidates, visibility reuse (the chosen sample's shadow ray:
//   occluded -> W = 0), temporal reuse from last frame's final reservoir reprojected through
//   gbuffer.motion (plane/normal tests), M capped at u_m_cap x candidates.
// STAGE 1: spatial reuse over u_spatial neighbours in a u_radius-pixel disk (depth/normal
//   tests), bias correction u_bias_mode: 0 = 1/M, 1 = MIS-normalised (1/Z, Z = the M of the
//   reservoirs whose surface can produce the sample), 2 = 1 with ray-traced visibility in Z;
//   then shading (final shadow ray) + emission, and the reservoir kept for the next frame.
// BASELINE (u_baseline_spp > 0, STAGE 1 only): the mean of u_baseline_spp light samples by
//   power (the same shared sampler without reuse), for equal-time comparisons.
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/sampling.glsl"
#include "lib/rng.glsl"
#include "lib/brdf.glsl"
#include "lib/lights.glsl"
#include "lib/scene_rt.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform writeonly image2D o_u;      // reservoir sample u
layout(binding = 1, rgba32f) uniform writeonly image2D o_meta;   // W, M, p^ (at its pixel), 0
layout(binding = 2, rgba32f) uniform writeonly image2D o_color;
layout(binding = 3, rgba32f) uniform writeonly image2D o_pos;    // xyz, w = material id (-1 none)
layout(binding = 4, rgba32f) uniform writeonly image2D o_nrm;    // shading normal

uniform sampler2D u_gb_albedo;
uniform sampler2D u_gb_position;
uniform sampler2D u_gb_normal;
uniform sampler2D u_gb_geonormal;
uniform sampler2D u_gb_motion;
uniform sampler2D u_in_u;       // STAGE 0: last frame's final reservoirs; STAGE 1: this frame's
uniform sampler2D u_in_meta;
uniform sampler2D u_prev_pos;
uniform sampler2D u_prev_nrm;
uniform int u_stage;
uniform int u_reset;
uniform int u_candidates;
uniform int u_temporal;
uniform int u_spatial;
uniform float u_radius;
uniform float u_m_cap;
uniform int u_bias_mode;
uniform int u_baseline_spp;
uniform uint u_sample;
uniform uint u_seed;
uniform vec3 u_camera_pos;

struct Shading { Surface s; vec3 P; vec3 N; vec3 Ng; vec3 V; vec3 p; bool valid; };

Shading load(ivec2 q) {
    Shading sh;
    vec4 pos = texelFetch(u_gb_position, q, 0);
    sh.valid = pos.w >= 0.0;
    sh.P = pos.xyz;
    sh.V = normalize(u_camera_pos - pos.xyz);
    sh.N = normalize(texelFetch(u_gb_normal, q, 0).xyz + vec3(0.0, 0.0, 1e-12));
    sh.Ng = normalize(texelFetch(u_gb_geonormal, q, 0).xyz + vec3(0.0, 0.0, 1e-12));
    if (dot(sh.Ng, sh.V) < 0.0) sh.Ng = -sh.Ng;
    sh.s = make_surface(scene_material(int(pos.w + 0.5)), texelFetch(u_gb_albedo, q, 0).rgb);
    // rays leave from a point off the surface along the geometric normal (scale-aware)
    sh.p = sh.P + sh.Ng * (1e-4 * (1.0 + length(sh.P)));
    return sh;
}

// unshadowed contribution of sample u at a shading point, in primary sample space
vec3 contrib(Shading sh, vec4 u, out vec3 dir, out float dist, out bool shadows) {
    dir = vec3(0.0); dist = 0.0; shadows = false;
    if (u_light_count <= 0 || !sh.valid) return vec3(0.0);
    float sel;
    int li = select_light(u.x, sel);
    Light L = lights[li];
    LightSample ls = sample_light(L, sh.p, u.yz, u.w);
    if (ls.pdf <= 0.0 || sel <= 0.0 || dot(ls.dir, sh.Ng) <= 0.0) return vec3(0.0);
    BsdfEval fe = eval_principled(sh.s, sh.N, sh.V, ls.dir);
    vec3 f = fe.diffuse + fe.glossy;
    dir = ls.dir; dist = ls.dist; shadows = L.axis_w.w > 0.5;
    vec3 c = f * ls.Li / (sel * ls.pdf);
    return (any(isnan(c)) || any(isinf(c))) ? vec3(0.0) : max(c, vec3(0.0));
}

float target(Shading sh, vec4 u) {
    vec3 d; float t; bool sh_;
    return luminance(contrib(sh, u, d, t, sh_));
}

bool visible(Shading sh, vec4 u) {
    vec3 d; float t; bool casts;
    vec3 c = contrib(sh, u, d, t, casts);
    if (max3(c) <= 0.0) return false;
    return !(casts && scene_occluded(sh.p, d, 0.0, t * (1.0 - 1e-4)));
}

struct Reservoir { vec4 u; float wsum; float M; float W; };

bool update(inout Reservoir r, vec4 u, float w, float M, float xi) {
    r.wsum += w;
    r.M += M;
    if (w > 0.0 && xi * r.wsum < w) { r.u = u; return true; }
    return false;
}

vec4 u_finite(vec4 v) { return (any(isnan(v)) || any(isinf(v))) ? vec4(0.0) : clamp(v, 0.0, 0.99999994); }

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    ivec2 size = imageSize(o_u);
    if (any(greaterThanEqual(px, size))) return;
    Rng rng = rng_init(uvec2(px), u_sample * 2u + uint(u_stage), u_seed);
    Shading sh = load(px);
    if (!sh.valid) {
        imageStore(o_u, px, vec4(0.0));
        imageStore(o_meta, px, vec4(0.0));
        if (u_stage == 1) {
            imageStore(o_color, px, vec4(u_rt_world, 1.0));
            imageStore(o_pos, px, vec4(0.0, 0.0, 0.0, -1.0));
            imageStore(o_nrm, px, vec4(0.0));
        }
        return;
    }
    if (u_stage == 1 && u_baseline_spp > 0) {  // light sampling by power, no reuse
        vec3 acc = vec3(0.0);
        for (int k = 0; k < u_baseline_spp; ++k) acc += shade_direct_at(sh.s, sh.p, sh.N, sh.Ng, sh.V, rng, false);
        imageStore(o_color, px, vec4(acc / float(u_baseline_spp) + sh.s.emission, 1.0));
        imageStore(o_u, px, vec4(0.0));
        imageStore(o_meta, px, vec4(0.0));
        imageStore(o_pos, px, vec4(sh.P, -1.0));
        imageStore(o_nrm, px, vec4(sh.N, 0.0));
        return;
    }
    Reservoir r;
    r.u = vec4(0.0); r.wsum = 0.0; r.M = 0.0; r.W = 0.0;
    if (u_stage == 0) {
        for (int k = 0; k < u_candidates; ++k) {
            vec4 u = rng_next4(rng);
            update(r, u, target(sh, u), 1.0, rng_next4(rng).x);
        }
        float ph = target(sh, r.u);
        r.W = ph > 0.0 ? r.wsum / (r.M * ph) : 0.0;
        if (r.W > 0.0 && !visible(sh, r.u)) r.W = 0.0;  // visibility reuse
        // temporal reuse
        float Mcur = r.M;
        if (u_temporal == 1 && u_reset == 0) {
            vec2 prev = vec2(px) + 0.5 - texelFetch(u_gb_motion, px, 0).xy;
            ivec2 q = ivec2(floor(prev));
            if (all(greaterThanEqual(q, ivec2(0))) && all(lessThan(q, size))) {
                vec4 pp = texelFetch(u_prev_pos, q, 0);
                vec3 pn = texelFetch(u_prev_nrm, q, 0).xyz;
                vec4 pm = texelFetch(u_in_meta, q, 0);
                vec4 pu = u_finite(texelFetch(u_in_u, q, 0));
                bool ok = pp.w >= 0.0 && !any(isnan(pm)) && !any(isinf(pm)) && !any(isnan(pp)) && !any(isnan(pn))
                          && abs(dot(sh.N, pp.xyz - sh.P)) < 0.02 * (1.0 + length(sh.P - u_camera_pos))
                          && dot(pn, sh.N) > 0.9;
                if (ok && pm.y > 0.0) {
                    float Mp = min(pm.y, u_m_cap * float(u_candidates));
                    float Wp = max(pm.x, 0.0);
                    // fold the current reservoir (weight p^ W M) and the previous one
                    Reservoir t;
                    t.u = r.u; t.wsum = 0.0; t.M = 0.0; t.W = 0.0;
                    update(t, r.u, ph * r.W * Mcur, Mcur, 0.0);
                    float php = target(sh, pu);
                    update(t, pu, php * Wp * Mp, Mp, rng_next4(rng).y);
                    float pt = target(sh, t.u);
                    float Z = t.M;
                    if (u_bias_mode >= 1) {  // prior surface from the stored position/normal
                        Shading ps = sh;
                        ps.P = pp.xyz; ps.N = pn; ps.Ng = pn;
                        ps.V = normalize(u_camera_pos - pp.xyz);
                        ps.p = pp.xyz + pn * (1e-4 * (1.0 + length(pp.xyz)));
                        Z = (pt > 0.0 ? Mcur : 0.0) + (target(ps, t.u) > 0.0 ? Mp : 0.0);
                    }
                    r = t;
                    r.W = (pt > 0.0 && Z > 0.0) ? r.wsum / (Z * pt) : 0.0;
                }
            }
        }
        imageStore(o_u, px, r.u);
        imageStore(o_meta, px, vec4(r.W, r.M, 0.0, 0.0));
        return;
    }
    // STAGE 1: spatial reuse
    vec4 cu = u_finite(texelFetch(u_in_u, px, 0));
    vec4 cm = texelFetch(u_in_meta, px, 0);
    float Mc = max(cm.y, 0.0), Wc = max(cm.x, 0.0);
    update(r, cu, target(sh, cu) * Wc * Mc, Mc, 0.0);
    ivec2 nb[16];
    int n = 0;
    for (int k = 0; k < u_spatial && k < 16; ++k) {
        vec4 xi = rng_next4(rng);
        float a = 2.0 * PI * xi.x, rad = u_radius * sqrt(xi.y);
        ivec2 q = px + ivec2(round(vec2(cos(a), sin(a)) * rad));
        if (q == px || any(lessThan(q, ivec2(0))) || any(greaterThanEqual(q, size))) continue;
        vec4 pq = texelFetch(u_gb_position, q, 0);
        if (pq.w < 0.0) continue;
        vec3 nq = texelFetch(u_gb_normal, q, 0).xyz;
        float dq = length(pq.xyz - u_camera_pos), dp = length(sh.P - u_camera_pos);
        if (abs(dq - dp) > 0.1 * dp || dot(nq, sh.N) < 0.9) continue;  // depth / normal tests
        vec4 qu = u_finite(texelFetch(u_in_u, q, 0));
        vec4 qm = texelFetch(u_in_meta, q, 0);
        if (any(isnan(qm)) || any(isinf(qm))) continue;
        update(r, qu, target(sh, qu) * max(qm.x, 0.0) * max(qm.y, 0.0), max(qm.y, 0.0), xi.z);
        nb[n++] = q;
    }
    float ph = target(sh, r.u);
    float Z = r.M;
    if (u_bias_mode >= 1) {
        Z = ph > 0.0 ? Mc : 0.0;
        for (int k = 0; k < n; ++k) {
            Shading qs = load(nb[k]);
            float Mq = max(texelFetch(u_in_meta, nb[k], 0).y, 0.0);
            bool ok = target(qs, r.u) > 0.0;
            if (ok && u_bias_mode == 2) ok = visible(qs, r.u);
            if (ok) Z += Mq;
        }
    }
    r.W = (ph > 0.0 && Z > 0.0) ? r.wsum / (Z * ph) : 0.0;
    vec3 d; float t; bool casts;
    vec3 c = contrib(sh, r.u, d, t, casts);
    bool vis = max3(c) > 0.0 && !(casts && scene_occluded(sh.p, d, 0.0, t * (1.0 - 1e-4)));
    vec3 L = vis ? c * r.W : vec3(0.0);
    imageStore(o_color, px, vec4(sanitize(L) + sh.s.emission, 1.0));
    imageStore(o_u, px, r.u);
    imageStore(o_meta, px, vec4(r.W, r.M, 0.0, 0.0));
    imageStore(o_pos, px, vec4(sh.P, 0.0));
    imageStore(o_nrm, px, vec4(sh.N, 0.0));
}
