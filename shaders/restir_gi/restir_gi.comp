// restir_gi.comp — ReSTIR GI (Ouyang et al. 2021, "ReSTIR GI: Path resampling for real-time
// path tracing"): one secondary path sample per pixel, resampled over time and space.
//
// Sample: a point x_s seen from the visible point x_v (G-buffer), its geometric normal n_s
// (oriented towards the point the sample was made for) and the radiance L_o leaving x_s
// towards x_v. L_o = next-event estimation at x_s plus a short path continuation from x_s
// (the shared ray tracer: shade_direct_at with MIS, BSDF rays, bsdf_hit_light_mis for lights,
// emitters and the world they meet, Russian roulette, u_max_bounces total bounces as Cycles
// counts them). The emission of x_s itself and the world seen by the first ray are NOT in
// L_o: DIRECT (which this technique adds to) already lights x_v with every light, emitter
// and the world; counting them here would count direct light twice.
// Sample space: solid angle at the visible point. A reservoir holds (x_s, n_s, L_o), its
// unbiased contribution weight W (~ 1 / pdf in solid angle at the pixel it was made for),
// and its candidate count M. Target p^_r(y) = luminance(f_r(w) cos * L_o) * V(x_r, x_s): the
// contribution, with visibility (a sample made at r is visible by construction; a reused
// sample is checked by a validation ray, so the final sample needs no shadow ray).
// Reusing a reservoir made at visible point x_q at x_r multiplies its W by the reconnection
// Jacobian J = |dw_r/dw_q| = (cos_r / cos_q) * (|x_q - x_s|^2 / |x_r - x_s|^2) (solid angle
// at x_r per solid angle at x_q of the same patch around x_s; a pdf divides by it), cos the
// angle at x_s between n_s and the direction to the visible point; reuse is refused when it
// lies outside [1/u_jacobian_max, u_jacobian_max] (grazing reconnections, fireflies).
// Bias correction u_bias_mode: 0 = 1/M (sum of all M: dark where a reused sample is not
// visible from every domain); 1 = the balance heuristic over the domains (Bitterli et al.
// 2020, Alg. 6): m_i(y) = M_i p^_i(y) / sum_j M_j p^_j(y), each domain's target evaluated at
// its own visible point and brought into this pixel's solid angle (p^_i / J: a density,
// while W, an inverse density, is multiplied by J), with visibility by a ray from there;
// unbiased for a static scene and robust where the targets differ (glossy).
//
// STAGE 0: the fresh sample (BSDF-sampled direction at x_v, trace, L_o); temporal reuse of
//   last frame's history reservoir reprojected through gbuffer.motion (plane/normal tests,
//   validation ray, Jacobian), its M capped at u_m_cap -> temporal reservoirs.
// STAGE 1: spatial reuse of the temporal reservoirs of u_spatial neighbours in a
//   u_radius-pixel disk (depth/normal tests, validation ray, Jacobian) -> spatial reservoirs.
// Both stages also write the visible point the reservoirs are made for. Which set is next
// frame's history is the host's choice (pass parameter feedback): the spatial reservoirs
// (1, as RTXDI does) or the temporal ones (0, as in the ReSTIR GI paper).
// STAGE 2: shading: color += f * L_o * W split into the diffuse and glossy lobes of x_v
//   (GI_IndirectDiffuse / GI_IndirectGlossy), debug views W and M.
// Sample age (RTXDI): frames since the sample was traced, carried by temporal and spatial
// reuse; a history reservoir older than u_max_age is not reused (its L_o is stale once the
// scene changed, and an old sample would otherwise keep winning). Boiling filter (RTXDI,
// u_boiling > 0): after temporal reuse, a reservoir whose contribution p^ W is above
// (10 / u_boiling - 9) times the mean nonzero contribution of its 8x8 tile is dropped, so a
// rare very bright sample does not spread through spatial and temporal reuse as a blotch.
// Every history texel is checked for finiteness before use: NaN in history is dropped.
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/sampling.glsl"
#include "lib/rng.glsl"
#include "lib/brdf.glsl"
#include "lib/lights.glsl"
#include "lib/scene_rt.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
// STAGE 0 and 1: reservoir pos, nrm, rad and the visible point vpos, vnrm;
// STAGE 2: color (read-modify-write), diffuse, glossy, debug W, debug M
layout(binding = 0, rgba32f) uniform image2D o_0;
layout(binding = 1, rgba32f) uniform writeonly image2D o_1;
layout(binding = 2, rgba32f) uniform writeonly image2D o_2;
layout(binding = 3, rgba32f) uniform writeonly image2D o_3;
layout(binding = 4, rgba32f) uniform writeonly image2D o_4;

const float MIN_ROUGHNESS = 0.1;  // the smoothest lobe the reservoirs evaluate (see load)
uniform sampler2D u_gb_albedo;
uniform sampler2D u_gb_position;
uniform sampler2D u_gb_normal;
uniform sampler2D u_gb_geonormal;
uniform sampler2D u_gb_motion;
// reservoirs read: STAGE 0 last frame's final (+ vpos/vnrm), STAGE 1 tmp, STAGE 2 final
uniform sampler2D u_in_pos;   // x_s, w = M
uniform sampler2D u_in_nrm;   // n_s, w = W
uniform sampler2D u_in_rad;   // L_o, w = 1 + the sample's age holds a sample, 0 none
uniform sampler2D u_in_vpos;  // visible point the reservoir was made for, w = -1: none
uniform sampler2D u_in_vnrm;  // its shading normal
uniform int u_stage;
uniform int u_reset;
uniform int u_temporal;
uniform int u_spatial;
uniform float u_radius;
uniform float u_m_cap;
uniform int u_bias_mode;
uniform float u_jacobian_max;
uniform int u_max_bounces;
uniform int u_rr_start;
uniform uint u_sample;
uniform uint u_seed;
uniform vec3 u_camera_pos;
uniform float u_max_age;  // history reservoirs older than this are not reused (0: no cap)
uniform float u_boiling;  // boiling filter strength in (0, 1]; 0 = off

shared float s_contrib[64];
shared float s_nonzero[64];

struct Shading { Surface s; vec3 P; vec3 N; vec3 Ng; vec3 V; vec3 p; bool valid; };

Shading load(ivec2 q) {
    Shading sh;
    vec4 pos = texelFetch(u_gb_position, q, 0);
    sh.valid = pos.w >= 0.0;
    sh.P = pos.xyz;
    sh.V = normalize(u_camera_pos - pos.xyz);
    sh.N = normalize(texelFetch(u_gb_normal, q, 0).xyz + vec3(0.0, 0.0, 1e-12));
    sh.Ng = normalize(texelFetch(u_gb_geonormal, q, 0).xyz + vec3(0.0, 0.0, 1e-12));
    // the two-sided frame of surface_frame(): both normals to V's side
    if (dot(sh.Ng, sh.V) < 0.0) { sh.Ng = -sh.Ng; sh.N = -sh.N; }
    if (dot(sh.N, sh.V) <= 0.0) sh.N = sh.Ng;
    Material m = scene_material(int(pos.w + 0.5));
    sh.s = gbuffer_surface(m, texelFetch(u_gb_albedo, q, 0), texelFetch(u_gb_normal, q, 0),
                           texelFetch(u_gb_geonormal, q, 0), m.emission.rgb);
    // reuse evaluates this pixel's BSDF at other pixels' sample points: a near-mirror lobe
    // (alpha 1e-4) is not evaluable there in float32 (its target function is noise and one
    // reused sample can weigh 10x the image), so the reservoirs see it as roughness MIN_ROUGHNESS
    sh.s.roughness = max(sh.s.roughness, MIN_ROUGHNESS);
    sh.s.alpha = max(sh.s.alpha, MIN_ROUGHNESS * MIN_ROUGHNESS);
    sh.p = rt_offset_ray(sh.P, sh.Ng);
    return sh;
}

struct Reservoir { vec3 xs; vec3 ns; vec3 Lo; float W; float M; float age; bool ok; };

Reservoir empty_reservoir() {
    Reservoir r;
    r.xs = vec3(0.0); r.ns = vec3(0.0, 0.0, 1.0); r.Lo = vec3(0.0); r.W = 0.0; r.M = 0.0; r.age = 0.0; r.ok = false;
    return r;
}

bool finite4(vec4 v) { return !any(isnan(v)) && !any(isinf(v)); }

Reservoir fetch_reservoir(ivec2 q) {
    Reservoir r = empty_reservoir();
    vec4 a = texelFetch(u_in_pos, q, 0), b = texelFetch(u_in_nrm, q, 0), c = texelFetch(u_in_rad, q, 0);
    if (!finite4(a) || !finite4(b) || !finite4(c)) return r;  // NaN in history: dropped
    r.M = max(a.w, 0.0);
    bool ok = c.w > 0.5 && b.w > 0.0 && max3(c.rgb) > 0.0 && dot(b.xyz, b.xyz) > 0.25;
    if (!ok) return r;
    r.xs = a.xyz; r.ns = normalize(b.xyz); r.Lo = max(c.rgb, vec3(0.0)); r.W = b.w; r.age = c.w - 1.0; r.ok = true;
    return r;
}

void store_reservoir(ivec2 px, Reservoir r) {
    imageStore(o_0, px, vec4(r.xs, r.M));
    imageStore(o_1, px, vec4(r.ns, r.ok ? r.W : 0.0));
    imageStore(o_2, px, vec4(r.Lo, r.ok ? 1.0 + r.age : 0.0));
}

// target function without visibility: luminance of the contribution f cos L_o at sh
float phat_unshadowed(Shading sh, Reservoir y) {
    if (!y.ok || !sh.valid) return 0.0;
    vec3 d = y.xs - sh.P;
    float dist = length(d);
    if (dist <= 0.0) return 0.0;
    vec3 wi = d / dist;
    if (dot(wi, sh.Ng) <= 0.0 || dot(y.ns, -wi) <= 0.0) return 0.0;  // x_s must face sh (one-sided L_o)
    BsdfEval fe = eval_principled(sh.s, sh.N, sh.V, wi);
    float p = luminance((fe.diffuse + fe.glossy) * y.Lo);
    return (isnan(p) || isinf(p)) ? 0.0 : max(p, 0.0);
}

// validation ray: x_s seen from sh
bool visible(Shading sh, Reservoir y) {
    vec3 e = rt_offset_ray(y.xs, y.ns);
    vec3 d = e - sh.p;
    float dist = length(d);
    if (dist <= 0.0) return false;
    return !scene_occluded(sh.p, d / dist, 0.0, dist * (1.0 - 1e-4));
}

float phat(Shading sh, Reservoir y) {
    float p = phat_unshadowed(sh, y);
    return (p > 0.0 && visible(sh, y)) ? p : 0.0;
}

// reconnection Jacobian J = |dw_r / dw_q| for a sample made at visible point xq reused at xr
// (W_r = W_q J, a density p_r = p_q / J);
// 0 when it is outside the accepted range
float jacobian(Reservoir y, vec3 xq, vec3 xr) {
    vec3 dq = xq - y.xs, dr = xr - y.xs;
    float lq2 = dot(dq, dq), lr2 = dot(dr, dr);
    if (lq2 <= 0.0 || lr2 <= 0.0) return 0.0;
    float cq = dot(y.ns, dq) * inversesqrt(lq2), cr = dot(y.ns, dr) * inversesqrt(lr2);
    if (cq <= 1e-4 || cr <= 1e-4) return 0.0;
    float J = (cr / cq) * (lq2 / lr2);
    return (J > u_jacobian_max || J * u_jacobian_max < 1.0 || isnan(J) || isinf(J)) ? 0.0 : J;
}

// radiance leaving the hit h towards -d (d = direction of the ray that found it): NEE at h and
// a path continuation, without h's own emission (DIRECT counts it at the visible point)
vec3 radiance_out(SurfaceHit h, vec3 d, inout Rng rng) {
    vec3 L = vec3(0.0);
    vec3 beta = vec3(1.0);
    SurfaceHit sh = h;
    int depth = 1;  // scatterings before sh (the visible point's); PT's bounce counting
    if (depth > u_max_bounces) return L;
    for (int iter = 0; iter < 64; ++iter) {
        vec3 V = -d;
        vec3 N, Ng, p;
        surface_frame(sh, V, N, Ng, p);
        Surface s = sh.bsdf;
        L += beta * shade_direct_at(s, p, N, Ng, V, rng, true);  // NEE, MIS with the BSDF ray below
        vec4 ub = rng_next4(rng);
        float pdf;
        vec3 wi = sample_principled(s, N, V, ub.xyz, pdf);
        if (pdf <= 0.0 || dot(wi, Ng) <= 0.0) break;
        BsdfEval fe = eval_principled(s, N, V, wi);
        vec3 f = fe.diffuse + fe.glossy;
        if (max3(f) <= 0.0) break;
        beta *= f / pdf;
        depth += 1;
        bool last = depth > u_max_bounces;  // collect the emission this ray meets, then stop
        SurfaceHit nh;
        bool hit = scene_trace(p, wi, 0.0, T_INF, nh);
        L += beta * bsdf_hit_light_mis(p, wi, 0.0, hit, nh, pdf, true);
        if (!hit || last) break;
        if (depth >= u_rr_start) {
            float q = min(max3(beta), 1.0);
            if (ub.w >= q) break;
            beta /= q;
        }
        sh = nh;
        d = wi;
    }
    return sanitize(L);
}

// the fresh sample and temporal reuse at a valid pixel; ph_sel = p^ of the chosen sample here
Reservoir temporal_reservoir(ivec2 px, ivec2 size, Shading sh, inout Rng rng, out float ph_sel) {
    // ---- the fresh sample: one BSDF-sampled direction, its hit and L_o there
    Reservoir r = empty_reservoir();
    r.M = 1.0;
    float wsum = 0.0;
    ph_sel = 0.0;
    vec4 ub = rng_next4(rng);
    float pdf;
    vec3 wi = sample_principled(sh.s, sh.N, sh.V, ub.xyz, pdf);
    if (pdf > 0.0 && dot(wi, sh.Ng) > 0.0 && u_light_count + int(max3(u_world_color) > 0.0) > 0) {
        SurfaceHit h;
        if (scene_trace(sh.p, wi, 0.0, T_INF, h)) {
            Reservoir y = empty_reservoir();
            y.xs = h.position;
            y.ns = dot(h.geo_normal, wi) > 0.0 ? -h.geo_normal : h.geo_normal;
            y.Lo = radiance_out(h, wi, rng);
            y.ok = max3(y.Lo) > 0.0;
            float ph = phat_unshadowed(sh, y);  // visible by construction
            if (ph > 0.0) {
                y.W = 1.0 / pdf;  // = (ph / pdf) / (M ph) with M = 1
                y.M = 1.0;
                r = y;
                wsum = ph / pdf;
                ph_sel = ph;
            }
        }
    }
    // ---- temporal reuse
    if (u_temporal == 1 && u_reset == 0) {
        // the previous pixel: the one holding the reprojected point, else the nearest other
        // pixel of its 2x2 bilinear footprint on the same surface (plane and normal tests).
        // Only the nearest one, an edge pixel under motion lands on the neighbouring face
        // every frame and restarts from one sample (flicker along every depth edge).
        vec2 prev = vec2(px) + 0.5 - texelFetch(u_gb_motion, px, 0).xy;
        ivec2 q0 = ivec2(floor(prev));
        vec2 fr = prev - vec2(q0) - 0.5;  // offset from that pixel's centre, (-0.5, 0.5]
        ivec2 sx = ivec2(fr.x >= 0.0 ? 1 : -1, 0), sy = ivec2(0, fr.y >= 0.0 ? 1 : -1);
        ivec2 cand[4] = ivec2[4](q0, abs(fr.x) >= abs(fr.y) ? q0 + sx : q0 + sy,
                                 abs(fr.x) >= abs(fr.y) ? q0 + sy : q0 + sx, q0 + sx + sy);
        float plane_tol = 0.02 * (1.0 + length(sh.P - u_camera_pos));
        ivec2 q = ivec2(-1);
        vec4 vp = vec4(0.0, 0.0, 0.0, -1.0), vn = vec4(0.0);
        for (int c = 0; c < 4; ++c) {
            ivec2 qc = cand[c];
            if (any(lessThan(qc, ivec2(0))) || any(greaterThanEqual(qc, size))) continue;
            vec4 a = texelFetch(u_in_vpos, qc, 0), b = texelFetch(u_in_vnrm, qc, 0);
            if (finite4(a) && finite4(b) && a.w >= 0.0 && dot(b.xyz, b.xyz) > 0.25
                && abs(dot(sh.N, a.xyz - sh.P)) < plane_tol && dot(normalize(b.xyz), sh.N) > 0.9) {
                q = qc; vp = a; vn = b;
                break;
            }
        }
        {
            bool ok = q.x >= 0;
            if (ok) {
                Reservoir pr = fetch_reservoir(q);
                if (u_max_age > 0.0 && pr.ok && pr.age >= u_max_age) pr = empty_reservoir();  // too old
                float Mp = min(pr.M, u_m_cap);
                bool picked_prev = false;
                if (pr.ok && Mp > 0.0) {
                    float J = jacobian(pr, vp.xyz, sh.P);
                    float ph = J > 0.0 ? phat(sh, pr) : 0.0;  // validation ray
                    float w = ph * pr.W * Mp * J;
                    if (w > 0.0 && !isinf(w)) {
                        wsum += w;
                        if (rng_next4(rng).x * wsum < w) { r.xs = pr.xs; r.ns = pr.ns; r.Lo = pr.Lo; r.ok = true;
                                                          r.age = pr.age + 1.0; ph_sel = ph; picked_prev = true; }
                    }
                }
                float W = (r.ok && ph_sel > 0.0) ? wsum / ((1.0 + Mp) * ph_sel) : 0.0;  // 1/M
                if (u_bias_mode == 1 && W > 0.0) {
                    // balance heuristic over the two domains (Bitterli 2020, Alg. 6): this
                    // frame's (M = 1, target p^_r) and last frame's (M = Mp, its target at
                    // its visible point, in this pixel's solid angle: / J, with visibility
                    // from there)
                    Shading ps = sh;
                    ps.P = vp.xyz; ps.N = normalize(vn.xyz); ps.Ng = ps.N;
                    ps.V = normalize(u_camera_pos - vp.xyz);
                    ps.p = rt_offset_ray(vp.xyz, ps.N);
                    float Jq = jacobian(r, vp.xyz, sh.P);
                    float pq = Jq > 0.0 ? (picked_prev ? phat_unshadowed(ps, r) : phat(ps, r)) / Jq : 0.0;
                    float pi = picked_prev ? pq : ph_sel;
                    float den = ph_sel + Mp * pq;
                    W = den > 0.0 ? wsum * pi / (ph_sel * den) : 0.0;
                }
                r.M = 1.0 + Mp;
                r.W = W;
            }
        }
    }
    if (isnan(r.W) || isinf(r.W) || r.W <= 0.0) { r.ok = false; r.W = 0.0; }
    return r;
}

// STAGE 0: the fresh sample, temporal reuse, the boiling filter. Invocations outside the
// image or on the background take part in the tile's reduction with nothing.
void stage_temporal(ivec2 px, ivec2 size) {
    bool inside = all(lessThan(px, size));
    Rng rng = rng_init(uvec2(px), u_sample * 3u, u_seed);
    Shading sh;
    sh.valid = false;
    if (inside) sh = load(px);
    Reservoir r = empty_reservoir();
    float ph_sel = 0.0;
    if (sh.valid) r = temporal_reservoir(px, size, sh, rng, ph_sel);
    if (u_boiling > 0.0) {
        uint li = gl_LocalInvocationIndex;
        float w = r.ok ? ph_sel * r.W : 0.0;
        s_contrib[li] = w;
        s_nonzero[li] = w > 0.0 ? 1.0 : 0.0;
        barrier();
        for (uint k = 32u; k > 0u; k >>= 1u) {
            if (li < k) {
                s_contrib[li] += s_contrib[li + k];
                s_nonzero[li] += s_nonzero[li + k];
            }
            barrier();
        }
        float mean = s_nonzero[0] > 0.0 ? s_contrib[0] / s_nonzero[0] : 0.0;
        if (w > (10.0 / clamp(u_boiling, 1e-6, 1.0) - 9.0) * mean) {
            float M = r.M;
            r = empty_reservoir();
            r.M = M;
        }
    }
    if (!inside) return;
    if (!sh.valid) {
        store_reservoir(px, empty_reservoir());
        imageStore(o_3, px, vec4(0.0, 0.0, 0.0, -1.0));
        imageStore(o_4, px, vec4(0.0));
        return;
    }
    store_reservoir(px, r);
    imageStore(o_3, px, vec4(sh.P, 0.0));
    imageStore(o_4, px, vec4(sh.N, 0.0));
}

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    ivec2 size = imageSize(o_0);
    if (u_stage == 0) {  // every invocation of the tile reaches the boiling filter's barriers
        stage_temporal(px, size);
        return;
    }
    if (any(greaterThanEqual(px, size))) return;
    Rng rng = rng_init(uvec2(px), u_sample * 3u + uint(u_stage), u_seed);
    Shading sh = load(px);
    if (u_stage == 2) {
        vec3 d = vec3(0.0), g = vec3(0.0);
        Reservoir r = empty_reservoir();
        if (sh.valid) {
            r = fetch_reservoir(px);
            if (r.ok && phat_unshadowed(sh, r) > 0.0) {
                BsdfEval fe = eval_principled(sh.s, sh.N, sh.V, normalize(r.xs - sh.P));
                d = sanitize(fe.diffuse * r.Lo * r.W);
                g = sanitize(fe.glossy * r.Lo * r.W);
            }
        }
        vec4 c = imageLoad(o_0, px);
        imageStore(o_0, px, vec4(sanitize(c.rgb) + d + g, c.a));
        imageStore(o_1, px, vec4(d, 1.0));
        imageStore(o_2, px, vec4(g, 1.0));
        imageStore(o_3, px, vec4(vec3(r.ok ? r.W : 0.0), 1.0));
        imageStore(o_4, px, vec4(vec3(r.M), 1.0));
        return;
    }
    if (!sh.valid) {
        store_reservoir(px, empty_reservoir());
        imageStore(o_3, px, vec4(0.0, 0.0, 0.0, -1.0));
        imageStore(o_4, px, vec4(0.0));
        return;
    }
    // ---- STAGE 1: spatial reuse of this frame's tmp reservoirs
    Reservoir c = fetch_reservoir(px);
    Reservoir r = c;
    float Mc = c.M;
    float ph_sel = c.ok ? phat_unshadowed(sh, c) : 0.0;  // visible (made or validated here)
    float wsum = ph_sel * c.W * Mc;
    if (!(wsum > 0.0) || isinf(wsum)) { wsum = 0.0; r.ok = false; ph_sel = 0.0; }
    ivec2 nb[16];
    float nm[16];
    int n = 0, sel = -1;
    float Mtot = Mc;
    float dp = length(sh.P - u_camera_pos);
    for (int k = 0; k < u_spatial && k < 16; ++k) {
        vec4 xi = rng_next4(rng);
        float a = 2.0 * PI * xi.x, rad = u_radius * sqrt(xi.y);
        ivec2 q = px + ivec2(round(vec2(cos(a), sin(a)) * rad));
        if (q == px || any(lessThan(q, ivec2(0))) || any(greaterThanEqual(q, size))) continue;
        vec4 pq = texelFetch(u_gb_position, q, 0);
        if (pq.w < 0.0) continue;
        vec3 nq = texelFetch(u_gb_normal, q, 0).xyz;
        float dq = length(pq.xyz - u_camera_pos);
        if (abs(dq - dp) > 0.1 * dp || dot(normalize(nq + vec3(0.0, 0.0, 1e-12)), sh.N) < 0.9) continue;
        Reservoir y = fetch_reservoir(q);
        nb[n] = q;
        nm[n] = y.M;
        Mtot += y.M;
        if (y.ok) {
            float J = jacobian(y, pq.xyz, sh.P);
            float ph = J > 0.0 ? phat(sh, y) : 0.0;  // validation ray
            float w = ph * y.W * y.M * J;
            if (w > 0.0 && !isinf(w)) {
                wsum += w;
                if (xi.z * wsum < w) { r = y; ph_sel = ph; sel = n; }
            }
        }
        ++n;
    }
    r.M = Mtot;
    r.W = (wsum > 0.0 && ph_sel > 0.0) ? wsum / (Mtot * ph_sel) : 0.0;  // 1/M
    if (u_bias_mode == 1 && r.W > 0.0) {
        // balance heuristic over this pixel's domain and the neighbours' (Bitterli 2020,
        // Alg. 6): each neighbour's target at its own visible point (visibility by a ray from
        // there; the chosen sample's own domain saw it), in this pixel's solid angle (/ J)
        float den = Mc * ph_sel, pi = ph_sel;
        for (int k = 0; k < n; ++k) {
            if (nm[k] <= 0.0) continue;
            Shading qs = load(nb[k]);
            float Jk = jacobian(r, qs.P, sh.P);
            if (Jk <= 0.0) continue;
            float pk = (k == sel ? phat_unshadowed(qs, r) : phat(qs, r)) / Jk;
            den += nm[k] * pk;
            if (k == sel) pi = pk;
        }
        r.W = den > 0.0 ? wsum * pi / (ph_sel * den) : 0.0;
    }
    if (isnan(r.W) || isinf(r.W) || r.W <= 0.0) { r.ok = false; r.W = 0.0; }
    store_reservoir(px, r);
    imageStore(o_3, px, vec4(sh.P, 0.0));
    imageStore(o_4, px, vec4(sh.N, 0.0));
}
