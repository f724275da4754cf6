// restir_di.comp — ReSTIR DI (Bitterli et al. 2020, "Spatiotemporal reservoir resampling for
// real-time ray tracing with dynamic direct lighting") on the shared ray tracer.
//
// SAMPLE. A reservoir holds one light sample y as a point that means the same thing at every
// pixel: a point on a light's surface (sphere, area, emissive triangle: position, light
// normal, radiance), a delta point light's position, or a direction (sun, and the world
// reached by a BSDF ray: light id -1). Its contribution at a shading point x is
//   c_x(y) = f_x(w) Le(y, -w) G(x, y),   G = |cos_y| / d^2 (surfaces), 1 / d^2 (delta points),
//   1 (directions),
// in the area (or discrete, or solid-angle) measure of y, so reusing y at another pixel needs
// no Jacobian. Target p^_x(y) = mean of c_x(y)'s channels (unshadowed).
// CANDIDATES (STAGE 0). u_light_cands light samples by power (the shared select_light +
// sample_light: every light type, emissive triangles) and u_bsdf_cands BSDF samples (a ray
// through the BVH; the nearest area/sphere light it crosses, else the emissive triangle it
// hits, else on a miss a sun disk or the world; area/sphere/sun lights only while the scene
// has at most bsdf_light_max of them), weighted for RIS with MIS'd candidate pdfs
// (balance heuristic over both strategies, Talbot 2005):
//   w = p^(y) / (M_L p_L(y) + M_B p_B(y)),   W = sum w / p^(y),   M = M_L + M_B.
// VISIBILITY REUSE: the chosen sample's shadow ray; occluded -> W = 0.
// TEMPORAL REUSE (u_temporal, STAGE 0): last frame's final reservoir at the pixel reprojected
//   through gbuffer.motion (plane distance and normal tests against the surface it was made
//   for, restir.pos/nrm@prev), its M capped at u_m_cap x M. Reservoirs are stored
//   light-relative (see fetch); after a light edit (u_lights_edited) last frame's reservoir is
//   weighted with last frame's lights (lights_prev).
// SPATIAL REUSE (STAGE 1): u_spatial neighbours in a u_radius-pixel disk (depth within 10 %,
//   normals within ~25 deg).
// COMBINING reservoirs r_i (sample y_i, W_i, M_i, made at surface x_i) at pixel x: resampling
//   weights w_i = p^_x(y_i) W_i M_i, one is selected (s), and
//   u_bias_mode 0 (1/M):            W = sum w / (p^_x(y) sum M_i)                 biased
//   u_bias_mode 1 (MIS-normalised):  W = sum w p^_s(y) / (p^_x(y) sum M_i p^_i(y))
//   u_bias_mode 2 (ray-traced visibility): as 1 with p^_i(y) V_i(y) (a shadow ray from each
//     other surface): the balance heuristic over the supports the W_i are valid for
//     (visibility reuse makes a reservoir's support the part of the light visible from its
//     own surface), hence unbiased. Modes 0 and 1 count reservoirs that could not have
//     produced y where it is visible here but hidden there: darker near shadow edges.
// FINAL (STAGE 1): shade c_x(y) V W with one shadow ray; an occluded sample is kept with
//   W = 0 (final visibility), so hidden samples do not live on in the history and make it dark.
// BASELINE (STAGE 2, u_baseline_spp > 0): the mean of u_baseline_spp samples of the shared
//   light sampler by power (shade_direct_at), no reuse: the equal-time comparison.
//   u_baseline_bsdf 1 (default): plus one BSDF ray per sample for the world light (which light
//   sampling does not cover; an any-hit ray); 0: light samples only (misses the world);
//   2: MIS'd with a BSDF ray whose emission bsdf_hit_light_mis collects (PT's estimator: it
//   tests every light per ray, slow with hundreds of lights).
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/sampling.glsl"
#include "lib/rng.glsl"
#include "lib/brdf.glsl"
#include "lib/lights.glsl"
#include "lib/scene_rt.glsl"
#include "lib/octahedral.glsl"

#ifndef RESTIR_STAGE
#define RESTIR_STAGE 0
#endif

layout(local_size_x = 8, local_size_y = 8) in;
#if RESTIR_STAGE == 0
layout(binding = 0, rgba32f) uniform writeonly image2D o_y;      // sample: y (point or direction), light id
layout(binding = 1, rgba32f) uniform writeonly image2D o_meta;   // W, M, octahedral light normal
layout(binding = 2, rgba32f) uniform writeonly image2D o_le;     // radiance at y (without spot falloff)
layout(binding = 3, rgba32f) uniform writeonly image2D o_pos;    // surface the reservoir is for: xyz, w = 0 | -1 none
layout(binding = 4, rgba32f) uniform writeonly image2D o_nrm;    // its shading, geometric normal (octahedral)
layout(binding = 5, rgba32f) uniform writeonly image2D o_emit;   // emission seen (Emit pass)
#elif RESTIR_STAGE == 1
layout(binding = 0, rgba32f) uniform writeonly image2D o_y;
layout(binding = 1, rgba32f) uniform writeonly image2D o_meta;
layout(binding = 2, rgba32f) uniform writeonly image2D o_le;
layout(binding = 3, rgba32f) uniform writeonly image2D o_color;
layout(binding = 4, rgba32f) uniform writeonly image2D o_direct; // direct light (GI_Direct)
layout(binding = 5, rgba32f) uniform writeonly image2D o_dbg_w;  // debug: W
layout(binding = 6, rgba32f) uniform writeonly image2D o_dbg_m;  // debug: M
#else
layout(binding = 3, rgba32f) uniform writeonly image2D o_color;
layout(binding = 4, rgba32f) uniform writeonly image2D o_direct;
layout(binding = 5, rgba32f) uniform writeonly image2D o_emit;
#endif

uniform sampler2D u_gb_albedo;
uniform sampler2D u_gb_position;
uniform sampler2D u_gb_normal;
uniform sampler2D u_gb_geonormal;
uniform sampler2D u_gb_emission;
uniform sampler2D u_gb_motion;
uniform sampler2D u_in_y;       // STAGE 0: last frame's final reservoirs; STAGE 1: this frame's
uniform sampler2D u_in_meta;
uniform sampler2D u_in_le;
uniform sampler2D u_prev_pos;
uniform sampler2D u_prev_nrm;
uniform int u_reset;
uniform int u_light_cands;
uniform int u_bsdf_cands;
uniform int u_bsdf_analytic;  // 1: BSDF candidates see area, sphere and sun-disk lights
uniform int u_bsdf_glossy;    // BSDF candidates on glossy pixels (they always see those lights)
uniform float u_glossy_rough; // a pixel is glossy below this roughness with a mostly specular lobe
uniform int u_temporal;
uniform int u_lights_edited;  // 1: a light or an emissive object changed since last frame
uniform int u_spatial;
uniform int u_shade_all;
uniform float u_radius;      // spatial radius, a fraction of the image's larger side
uniform float u_radius_min;  // pixels
uniform float u_m_cap;
uniform int u_bias_mode;
uniform int u_baseline_spp;
uniform int u_baseline_bsdf;
uniform uint u_sample;
uniform uint u_seed;
uniform vec3 u_camera_pos;

// ------------------------------------------------------------------ shading points
struct Shading { Surface s; vec3 P; vec3 N; vec3 Ng; vec3 V; vec3 p; bool valid; };

Shading make_shading(vec3 P, vec3 N, vec3 Ng, Surface s, bool valid) {
    Shading sh;
    sh.valid = valid;
    sh.P = P;
    sh.V = normalize(u_camera_pos - P);
    sh.N = normalize(N + vec3(0.0, 0.0, 1e-12));
    sh.Ng = normalize(Ng + vec3(0.0, 0.0, 1e-12));
    if (dot(sh.Ng, sh.V) < 0.0) sh.Ng = -sh.Ng;
    if (dot(sh.N, sh.V) <= 0.0) sh.N = sh.Ng;
    sh.s = s;
    sh.p = rt_offset_ray(P, sh.Ng);  // rays leave from a point off the surface
    return sh;
}

Shading load(ivec2 q) {
    vec4 pos = texelFetch(u_gb_position, q, 0);
    Material m = scene_material(int(pos.w + 0.5));
    Surface s = gbuffer_surface(m, texelFetch(u_gb_albedo, q, 0), texelFetch(u_gb_normal, q, 0),
                                texelFetch(u_gb_geonormal, q, 0), texelFetch(u_gb_emission, q, 0).rgb);
    return make_shading(pos.xyz, texelFetch(u_gb_normal, q, 0).xyz, texelFetch(u_gb_geonormal, q, 0).xyz, s,
                        pos.w >= 0.0);
}

// ------------------------------------------------------------------ samples
struct Sample { vec3 y; int li; vec3 n; vec3 Le; bool prev; };  // prev: y is on lights_prev[li] (last frame's)
struct Reservoir { Sample x; float wsum; float M; float W; float own; };  // own: p^ at the surface it was made for

bool finite4(vec4 v) { return !any(isnan(v)) && !any(isinf(v)); }

// Reservoirs are stored light-relative (store_reservoir, fetch): a sample on a light keeps its
// coordinates in the light's frame (lib/lights.glsl light_to_local), a sample on an emissive
// mesh its point and normal in the instance's object space, and each is rebuilt from the light
// as it is now when read. Moving, turning, scaling or recolouring a light (or moving an
// emissive object) keeps temporal reuse: the samples follow the light, and the reuse weights
// are evaluated with its new radiance. Only a change of which lights there are (the host's
// "light_set" event: lights added, removed or changed in type, the emissive instances, the
// world) resets the reservoirs. The world's samples (li = -1) are directions with their
// radiance.
layout(std430, binding = 17) readonly buffer PrevLightBuffer { Light lights_prev[]; };  // last frame's

// The same light-relative sample on the light as it was last frame (mesh lights and the world:
// unchanged).
Sample sample_on_prev_light(Sample x) {
    if (x.li < 0 || int(lights[x.li].pos_type.w + 0.5) == LIGHT_MESH) return x;
    Sample o = x;
    light_from_local(lights_prev[x.li], light_to_local(lights[x.li], x.y), o.y, o.n, o.Le);
    o.prev = true;
    return o;
}

int mesh_instance(Light L) { return int(emitters[int(L.axis_w.x + 0.5)].p1.w + 0.5); }

void sample_from_stored(inout Sample x, vec3 local, vec3 n_stored) {
    if (x.li < 0) { x.n = n_stored; return; }
    Light L = lights[x.li];
    if (int(L.pos_type.w + 0.5) == LIGHT_MESH) {
        RtInstance inst = rt_instances[mesh_instance(L)];
        x.y = (inst.object_to_world * vec4(local, 1.0)).xyz;
        x.n = normalize(transpose(mat3(inst.world_to_object)) * n_stored);
        return;  // x.Le: the stored radiance (an emission edit is a material edit)
    }
    light_from_local(L, local, x.y, x.n, x.Le);
}

// A stored reservoir; anything non-finite or out of range reads as empty (NaN in history is
// gone after one frame).
Reservoir fetch(ivec2 q) {
    Reservoir r;
    vec4 a = texelFetch(u_in_y, q, 0), m = texelFetch(u_in_meta, q, 0), l = texelFetch(u_in_le, q, 0);
    r.x.y = a.xyz; r.x.li = int(floor(a.w + 0.5)); r.x.n = oct_decode(m.zw); r.x.Le = l.rgb; r.x.prev = false;
    r.wsum = 0.0; r.W = m.x; r.M = m.y; r.own = l.w;
    if (!finite4(a) || !finite4(m) || !finite4(l) || r.x.li < -1 || r.x.li >= u_light_count || m.x <= 0.0
        || m.y <= 0.0 || any(lessThan(l, vec4(0.0)))) {
        r.W = 0.0; r.M = (finite4(m) && m.y > 0.0) ? m.y : 0.0; r.x.li = -1; r.x.Le = vec3(0.0);
        return r;
    }
    sample_from_stored(r.x, a.xyz, r.x.n);
    return r;
}

// Contribution c_x(y) (unshadowed) at a shading point, with the shadow ray it needs.
// G = the geometry factor in it (1 / d^2 for delta points, 1 for directions).
vec3 contrib_g(Shading sh, Sample x, out vec3 dir, out float dist, out bool casts, out float G) {
    dir = vec3(0.0, 0.0, 1.0); dist = 0.0; casts = false; G = 1.0;
    if (!sh.valid || max3(x.Le) <= 0.0) return vec3(0.0);
    vec3 Le = x.Le;
    if (x.li < 0) {                       // the world, reached by a BSDF ray
        dir = x.y; dist = T_INF; casts = true;
    } else {
        Light L = x.prev ? lights_prev[x.li] : lights[x.li];
        casts = L.axis_w.w > 0.5;
        Le *= light_eval_point(L, sh.p, x.y, x.n, dir, dist, G);
        if (max3(Le) <= 0.0) return vec3(0.0);
    }
    if (dot(dir, sh.Ng) <= 0.0) return vec3(0.0);
    BsdfEval fe = eval_principled(sh.s, sh.N, sh.V, dir);
    vec3 c = (fe.diffuse + fe.glossy) * Le * G;
    return (any(isnan(c)) || any(isinf(c))) ? vec3(0.0) : max(c, vec3(0.0));
}

vec3 contrib(Shading sh, Sample x, out vec3 dir, out float dist, out bool casts) {
    float G;
    return contrib_g(sh, x, dir, dist, casts, G);
}

// p^: the mean of the channels (not luminance: a blue light's contribution is 14x its
// luminance, so luminance-proportional resampling leaves most of the per-channel variance)
float tgt(vec3 c) { return (c.r + c.g + c.b) * (1.0 / 3.0); }

float target(Shading sh, Sample x) {
    vec3 d; float t; bool cs;
    return tgt(contrib(sh, x, d, t, cs));
}

bool visible(Shading sh, Sample x) {
    vec3 d; float t; bool casts;
    vec3 c = contrib(sh, x, d, t, casts);
    if (max3(c) <= 0.0) return false;
    return !(casts && scene_occluded(sh.p, d, 0.0, t >= T_INF ? T_INF : t * (1.0 - 1e-4)));
}

// p^ with visibility at another surface (bias mode 2)
float target_vis(Shading sh, Sample x, bool trace) {
    vec3 d; float t; bool casts;
    float ph = tgt(contrib(sh, x, d, t, casts));
    if (ph > 0.0 && trace && casts && scene_occluded(sh.p, d, 0.0, t >= T_INF ? T_INF : t * (1.0 - 1e-4))) return 0.0;
    return ph;
}

bool update(inout Reservoir r, Sample x, float w, float M, float xi) {
    r.wsum += w;
    r.M += M;
    if (w > 0.0 && xi * r.wsum < w) { r.x = x; return true; }
    return false;
}

Reservoir empty_reservoir() {
    Reservoir r;
    r.x.y = vec3(0.0); r.x.li = -1; r.x.n = vec3(0.0, 0.0, 1.0); r.x.Le = vec3(0.0); r.x.prev = false;
    r.wsum = 0.0; r.M = 0.0; r.W = 0.0; r.own = 0.0;
    return r;
}

// ------------------------------------------------------------------ candidates
// Sphere lights in bias mode 1/M: a share SPHERE_AREA_MIX of their candidates is a uniform point
// on the whole sphere (defensive sampling), the rest the shared cone sample. The cone's density
// per unit *area* of the sphere, cone_pdf cos_y / d^2, goes to 0 at the silhouette, so a
// candidate there gets W ~ 1 / (M p_area) without bound; at its own pixel p^ ~ cos_y cancels
// that, but 1/M reuse hands the same W to a neighbour the point faces (measured: one pixel
// 1100x too bright, mean 6.67x Cycles). The mixture keeps p_area >= SPHERE_AREA_MIX / (4 pi r^2)
// and so W bounded. The MIS'd modes cancel the blow-up through p^ at the reservoir's own
// surface and keep the pure cone sample.
#define SPHERE_AREA_MIX 0.25
float sphere_area_mix() { return u_bias_mode == 0 ? SPHERE_AREA_MIX : 0.0; }

// Probability that the light strategy picks light li at sh: by power (select_light(u, prob)
// of lib/light_select.glsl), the world taking u_world_select. Candidates stay this cheap on
// purpose: the light tree's walk (select_light(u, p, n, prob), with sh.Ng) gave 16 frames a
// lower relMSE (300/1000/3000 mixed lights: 0.0285/0.0380/0.0419 -> 0.0240/0.0323/0.0323)
// but 32 walks per pixel cost 1.3-2.4x the frame time, and resampling by the target
// function already weights the candidates by distance and orientation.
float restir_light_prob(int li, Shading sh) { return light_pdf(li) * (1.0 - u_world_select); }

// Solid-angle pdf with which light sampling (select_light + sample_light) produces sample x
// from sh (delta lights: the selection probability). Emissive triangles: 0 (their pdf needs the
// triangle; bsdf_candidate computes it where it finds one).
float light_strategy_pdf(Shading sh, Sample x) {
    if (x.li < 0) return u_world_select > 0.0 ? u_world_select * world_pdf(x.y) : 0.0;  // the world map
    Light L = lights[x.li];
    float sel = restir_light_prob(x.li, sh);
    float pl = light_sample_pdf(L, sh.p, x.y, x.n);
    float a = light_is_sphere(L) ? sphere_area_mix() : 0.0;
    if (a <= 0.0 || pl <= 0.0) return sel * pl;
    float r = L.dir_radius.w;
    vec3 dy = sh.p - x.y;
    float cy = dot(x.n, normalize(dy));
    float pa = cy > 0.0 ? dot(dy, dy) / (cy * 4.0 * PI * r * r) : 0.0;  // area-uniform, as solid angle
    return sel * ((1.0 - a) * pl + a * pa);
}

bool is_delta(Sample x) { return x.li >= 0 && light_is_delta(lights[x.li]); }

// Can a BSDF candidate produce x? Emissive triangles (found through the BVH) always; area,
// sphere and sun-disk lights only when u_bsdf_analytic (the host turns it off above
// bsdf_light_max such lights: each BSDF ray would test them all); delta lights never. A
// strategy that cannot produce a sample has pdf 0 for it, so the MIS'd weights stay unbiased.
bool bsdf_finds(Sample x, bool analytic) {
    if (x.li < 0) return true;
    Light L = lights[x.li];
    return light_has_shape(L) ? analytic : !light_is_delta(L);  // shapeless, not delta: triangles
}

// Glossy pixels (roughness < u_glossy_rough, specular lobe >= half the sampling weight) get
// u_bsdf_glossy BSDF candidates that test every area/sphere/sun-disk light: a small light's
// highlight on a glossy surface is a narrow peak that light sampling by power finds in a few
// percent of frames (a heavy tail: on many_lights' metal sphere it held most of the error of
// 16 accumulated frames); BSDF sampling finds it. Per-pixel strategy counts keep the MIS'd
// candidate weights consistent (both strategies' pdfs use the same counts and flags).
bool is_glossy(Shading sh) {
    return sh.s.roughness < u_glossy_rough && lobe_weights(sh.s, max(dot(sh.N, sh.V), 1e-4)).y >= 0.5;
}

// One light sample by power (or a direction towards the world map by its luminance, with
// the probability shade_direct gives it) as a Sample; pl = its solid-angle pdf (delta:
// selection prob.)
bool light_candidate(Shading sh, vec4 u, out Sample x, out float pl) {
    x.li = -1; x.y = vec3(0.0); x.n = vec3(0.0, 0.0, 1.0); x.Le = vec3(0.0); x.prev = false; pl = 0.0;
    if (u.x < u_world_select) {
        float pw;
        x.y = world_sample(u.yz, pw);
        x.Le = world_radiance(x.y);
        pl = u_world_select * pw;
        return pl > 0.0 && max3(x.Le) > 0.0;
    }
    if (u_light_count <= 0) return false;
    float sel;
    int li = select_light((u.x - u_world_select) / (1.0 - u_world_select), sel);
    sel *= 1.0 - u_world_select;
    Light L = lights[li];
    float amix = light_is_sphere(L) ? sphere_area_mix() : 0.0;
    if (amix > 0.0 && u.w < amix) {  // defensive area-uniform point on a sphere light (u.w unused by spheres)
        float r = L.dir_radius.w;
        vec3 toc = L.pos_type.xyz - sh.p;
        if (dot(toc, toc) <= r * r || sel <= 0.0) return false;
        x.li = li;
        x.y = L.pos_type.xyz + r * sample_uniform_sphere(u.yz);
        light_shape_point(L, x.y, x.n, x.Le);
        pl = light_strategy_pdf(sh, x);  // 0 on the far side: contrib is 0 there too
        return pl > 0.0;
    }
    LightSample ls = sample_light(L, sh.p, u.yz, u.w);
    if (ls.pdf <= 0.0 || sel <= 0.0) return false;
    x.li = li;
    x.y = ls.y; x.n = ls.ny; x.Le = ls.Le;
    pl = amix > 0.0 ? light_strategy_pdf(sh, x) : sel * ls.pdf;  // spheres: the mixture's pdf
    return true;
}

// One BSDF sample as a Sample: the nearest area/sphere light the ray crosses before the first
// surface, else the emissive triangle it hits (its mesh light), else on a miss a sun disk or
// the world. pb = BSDF pdf (solid angle), pl = the light strategy's pdf of the same sample.
bool bsdf_candidate(Shading sh, vec3 u, bool analytic, out Sample x, out float pb, out float pl) {
    x.li = -1; x.y = vec3(0.0); x.n = vec3(0.0, 0.0, 1.0); x.Le = vec3(0.0); x.prev = false; pl = 0.0;
    vec3 d = sample_principled(sh.s, sh.N, sh.V, u, pb);
    if (pb <= 0.0 || dot(d, sh.Ng) <= 0.0) return false;
    SurfaceHit hs;
    bool hit = scene_trace(sh.p, d, 0.0, T_INF, hs);
    float tbest = hit ? hs.t : T_INF;
    int best = -1;
    // the nearest area/sphere light the ray crosses: through the light BVH (lib/light_select.glsl)
#define RESTIR_VISIT_NEAREST(i) {                                                              \
        float t_ = light_ray_distance(lights[i], sh.p, d);                                     \
        if (t_ > 0.0 && t_ < tbest) { tbest = t_; best = i; }                                   \
    }
    if (analytic) LIGHT_BVH_TRAVERSE(sh.p, d, 0.0, tbest, RESTIR_VISIT_NEAREST)
#undef RESTIR_VISIT_NEAREST
    if (best >= 0) {
        x.li = best;
        x.y = sh.p + d * tbest;
        light_shape_point(lights[best], x.y, x.n, x.Le);
        pl = light_strategy_pdf(sh, x);
        return true;
    }
    if (hit) {
        int li = mesh_light_of(hs.instance);
        if (li < 0 || max3(hs.bsdf.emission) <= 0.0) return false;
        Light L = lights[li];
        RtInstance inst = rt_instances[hs.instance];
        vec3 p0 = (inst.object_to_world * vec4(rt_verts[3 * hs.prim].xyz, 1.0)).xyz;
        vec3 p1 = (inst.object_to_world * vec4(rt_verts[3 * hs.prim + 1].xyz, 1.0)).xyz;
        vec3 p2 = (inst.object_to_world * vec4(rt_verts[3 * hs.prim + 2].xyz, 1.0)).xyz;
        float area = 0.5 * length(cross(p1 - p0, p2 - p0));
        vec3 E = hs.bsdf.emission;
        float tri_prob = area * (E.r + E.g + E.b) / 3.0 * PI / max(L.color.w, 1e-20);
        x.li = li; x.y = hs.position; x.n = hs.geo_normal; x.Le = E;
        pl = restir_light_prob(li, sh) * tri_prob * area_to_solid_angle_pdf(sh.p, hs.position, hs.geo_normal, area);
        return true;
    }
    int suns = u_light_tree >= 0 ? int(rt_light_select[u_light_tree + 4]) : 0;
    int ns = u_light_tree >= 0 ? int(rt_light_select[u_light_tree + 5]) : 0;
    for (int k = 0; k < ns && analytic; ++k) {  // a miss: sun disks (the suns' list), then the world
        int i = int(rt_light_select[suns + k] + 0.5);
        vec3 Le;
        float pdf;
        if (light_ray_hit(lights[i], sh.p, d, 0.0, T_INF, Le, pdf)) {
            x.li = i; x.y = d; x.Le = Le;
            pl = light_strategy_pdf(sh, x);
            return true;
        }
    }
    x.Le = world_radiance(d);
    if (max3(x.Le) <= 0.0) return false;
    x.li = -1; x.y = d;
    pl = light_strategy_pdf(sh, x);  // a world map is also light-sampled
    return true;
}

// RIS over the candidates with MIS'd candidate pdfs (balance heuristic over the strategies)
Reservoir candidates(Shading sh, inout Rng rng) {
    Reservoir r = empty_reservoir();
    bool glossy = u_bsdf_glossy > 0 && is_glossy(sh);
    bool analytic = u_bsdf_analytic == 1 || glossy;
    float ML = float(u_light_count > 0 || u_world_select > 0.0 ? u_light_cands : 0);
    float MB = float(glossy ? max(u_bsdf_cands, u_bsdf_glossy) : u_bsdf_cands);
    for (int k = 0; k < int(ML); ++k) {
        vec4 u = rng_next4(rng);
        float xi = rng_next4(rng).x;
        Sample x; float pl;
        float w = 0.0;
        if (light_candidate(sh, u, x, pl)) {
            vec3 d; float t, G; bool cs;
            vec3 c = contrib_g(sh, x, d, t, cs, G);
            if (max3(c) > 0.0) {
                if (is_delta(x)) {
                    w = tgt(c) / (ML * pl);  // discrete measure; BSDF rays never find it
                } else {
                    // p^ / (M_L p_L + M_B p_B) in y's measure; both pdfs are solid-angle, times G
                    float pb = (MB > 0.0 && bsdf_finds(x, analytic)) ? pdf_principled(sh.s, sh.N, sh.V, d) : 0.0;
                    w = tgt(c) / (G * (ML * pl + MB * pb));
                }
            }
        }
        update(r, x, w, 1.0, xi);
    }
    for (int k = 0; k < int(MB); ++k) {
        vec4 u = rng_next4(rng);
        Sample x; float pb, pl;
        float w = 0.0;
        if (bsdf_candidate(sh, u.xyz, analytic, x, pb, pl)) {
            vec3 d; float t, G; bool cs;
            vec3 c = contrib_g(sh, x, d, t, cs, G);
            if (max3(c) > 0.0) w = tgt(c) / (G * (ML * pl + MB * pb));
        }
        update(r, x, w, 1.0, u.w);
    }
    float ph = target(sh, r.x);
    r.W = ph > 0.0 ? r.wsum / ph : 0.0;  // the 1/M is inside the balance-heuristic weights
    return r;
}

#if RESTIR_STAGE < 2
void store_reservoir(ivec2 px, Reservoir r) {
    bool ok = r.W > 0.0 && r.x.li >= -1;
    vec3 local = r.x.y, n = r.x.n;  // light-relative, as fetch reads it
    if (ok && r.x.li >= 0) {
        Light L = lights[r.x.li];
        if (int(L.pos_type.w + 0.5) == LIGHT_MESH) {
            RtInstance inst = rt_instances[mesh_instance(L)];
            local = (inst.world_to_object * vec4(r.x.y, 1.0)).xyz;
            n = normalize(transpose(mat3(inst.object_to_world)) * r.x.n);
        } else {
            local = light_to_local(L, r.x.y);
        }
    }
    imageStore(o_y, px, vec4(local, float(r.x.li)));
    imageStore(o_meta, px, vec4(ok ? r.W : 0.0, r.M, oct_encode(n)));
    imageStore(o_le, px, vec4(r.x.Le, ok ? r.own : 0.0));
}
#endif

// Pairwise MIS weights (Bitterli 2022, Lin et al. 2022) for combining a canonical reservoir c
// (this pixel, M_c) with n others (M_i, made at surfaces x_i): for a sample y,
//   A_i = M_i p^_i(y) [V_i(y)],  B = (M_c / n) p^_c(y),
//   m_i(y) = A_i / (n (A_i + B)),   m_c(y) = sum_i B / (n (B + A_i)),
// which sum to 1 wherever p^_c(y) > 0: unbiased over the supports the A_i describe (with
// V_i: the visible parts, which is what visibility reuse leaves a reservoir; without it, a
// sample hidden at x_i is still counted there, so the estimate is darker near shadows).
// Bias mode 0 (1/M) uses m_i = M_i / sum M instead (biased: darker wherever another surface
// cannot produce the sample).
float pair_other(float Ai, float B, float n) { return Ai + B > 0.0 ? Ai / (n * (Ai + B)) : 0.0; }
float pair_canon(float Ai, float B, float n) { return Ai + B > 0.0 ? B / (n * (B + Ai)) : 1.0 / n; }

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    ivec2 size = textureSize(u_gb_position, 0);
    if (any(greaterThanEqual(px, size))) return;
    Rng rng = rng_init(uvec2(px), u_sample * 3u + uint(RESTIR_STAGE), u_seed);
    Shading sh = load(px);
#if RESTIR_STAGE == 0
    imageStore(o_emit, px, vec4(sh.valid ? sh.s.emission : vec3(0.0), 1.0));
    if (!sh.valid) {
        store_reservoir(px, empty_reservoir());
        imageStore(o_pos, px, vec4(0.0, 0.0, 0.0, -1.0));
        imageStore(o_nrm, px, vec4(0.0));
        return;
    }
    Reservoir r = candidates(sh, rng);
    if (r.W > 0.0 && !visible(sh, r.x)) r.W = 0.0;  // visibility reuse
    float Mc = r.M;
    if (u_temporal == 1 && u_reset == 0) {
        vec2 prev = vec2(px) + 0.5 - texelFetch(u_gb_motion, px, 0).xy;
        ivec2 q = ivec2(floor(prev));
        if (all(greaterThanEqual(q, ivec2(0))) && all(lessThan(q, size))) {
            vec4 pp = texelFetch(u_prev_pos, q, 0);
            vec4 pnn = texelFetch(u_prev_nrm, q, 0);  // octahedral shading and geometric normals
            vec3 pn = oct_decode(pnn.xy), png = oct_decode(pnn.zw);
            float dist = length(sh.P - u_camera_pos);
            bool ok = finite4(pp) && finite4(pnn) && pp.w >= 0.0
                      && abs(dot(sh.N, pp.xyz - sh.P)) < 0.02 * (1.0 + dist)   // plane distance
                      && length(pp.xyz - sh.P) < 0.1 * dist                     // same neighbourhood
                      && dot(pn, sh.N) > 0.9;                                   // normal
            Reservoir p = fetch(q);
            if (ok && p.M > 0.0) {
                if (u_lights_edited == 1 && p.x.li >= 0) p.W *= light_local_jacobian(lights[p.x.li], lights_prev[p.x.li]);
                float Mp = min(p.M, u_m_cap * Mc);
                Shading ps = make_shading(pp.xyz, pn, png, sh.s, true);  // the surface it was made for
                float pc_c = target(sh, r.x), pc_p = target(sh, p.x);
                float mc = Mc / (Mc + Mp), mp = Mp / (Mc + Mp);  // 1/M
                if (u_bias_mode >= 1) {
                    // two reservoirs: the pairwise weights reduce to the balance heuristic
                    // Ap: how likely last frame's reservoir was to hold r.x, so with last frame's
                    // lights (after a light edit: the same light-relative sample on the light as
                    // it was); p.own: p^ where p.x was kept (visible there), last frame
                    Sample xr = u_lights_edited == 1 ? sample_on_prev_light(r.x) : r.x;
                    float Ac = Mc * pc_c, Ap = Mp * target_vis(ps, xr, u_bias_mode == 2);
                    mc = Ac + Ap > 0.0 ? Ac / (Ac + Ap) : 0.0;
                    float Bp = Mp * p.own, Bc = Mc * pc_p;
                    mp = Bp + Bc > 0.0 ? Bp / (Bp + Bc) : 0.0;
                }
                Reservoir t = empty_reservoir();
                update(t, r.x, mc * pc_c * r.W, Mc, 0.0);
                update(t, p.x, mp * pc_p * p.W, Mp, rng_next4(rng).x);
                float ph = target(sh, t.x);
                t.W = ph > 0.0 ? t.wsum / ph : 0.0;
                r = t;
            }
        }
    }
    r.own = target(sh, r.x);
    store_reservoir(px, r);
    imageStore(o_pos, px, vec4(sh.P, 0.0));
    imageStore(o_nrm, px, vec4(oct_encode(sh.N), oct_encode(sh.Ng)));
#elif RESTIR_STAGE == 1
    if (!sh.valid) {
        store_reservoir(px, empty_reservoir());
        imageStore(o_color, px, vec4(world_background(px, imageSize(o_color)), 1.0));
        imageStore(o_direct, px, vec4(0.0, 0.0, 0.0, 1.0));
        imageStore(o_dbg_w, px, vec4(0.0, 0.0, 0.0, 1.0));
        imageStore(o_dbg_m, px, vec4(0.0, 0.0, 0.0, 1.0));
        return;
    }
    // spatial reuse: the canonical reservoir c (this pixel, after temporal reuse) and up to
    // u_spatial neighbours' (this frame's, after theirs)
    Reservoir c = fetch(px);
    Reservoir nbr[16];
    Shading nsh[16];
    int n = 0;
    float dp = length(sh.P - u_camera_pos);
    float Msum = c.M;
    for (int k = 0; k < u_spatial && k < 16; ++k) {
        vec4 xi = rng_next4(rng);
        float a = 2.0 * PI * xi.x, rad = max(u_radius_min, u_radius * float(max(size.x, size.y))) * sqrt(xi.y);
        ivec2 q = px + ivec2(round(vec2(cos(a), sin(a)) * rad));
        if (q == px || any(lessThan(q, ivec2(0))) || any(greaterThanEqual(q, size))) continue;
        vec4 pq = texelFetch(u_gb_position, q, 0);
        if (pq.w < 0.0) continue;
        vec3 nq = texelFetch(u_gb_normal, q, 0).xyz;
        if (abs(length(pq.xyz - u_camera_pos) - dp) > 0.1 * dp || dot(nq, sh.N) < 0.9) continue;  // depth, normal
        Reservoir rq = fetch(q);
        if (rq.M <= 0.0) continue;
        nbr[n] = rq;
        nsh[n] = load(q);
        Msum += rq.M;
        ++n;
    }
    float fn = float(max(n, 1));
    float Bc = (c.M / fn);
    // canonical sample: its weight against every neighbour
    vec3 dc; float tc; bool csc;
    vec3 cc = contrib(sh, c.x, dc, tc, csc);
    float pcc = tgt(cc);
    float m_c = n == 0 ? 1.0 : 0.0;
    if (u_bias_mode == 0) m_c = c.M / Msum;
    else if (pcc > 0.0) for (int k = 0; k < n; ++k)
        m_c += pair_canon(nbr[k].M * target_vis(nsh[k], c.x, u_bias_mode == 2), Bc * pcc, fn);
    Reservoir r = empty_reservoir();
    update(r, c.x, m_c * pcc * c.W, c.M, 0.0);
    // shading: every input sample weighted by its MIS weight (the expectation of the
    // resampled estimate over which input is kept: same mean, less noise), or only the kept one
    vec3 L = vec3(0.0);
    bool shade_all = u_shade_all == 1;
    bool sel_vis = false;  // visibility of the kept sample, when shade_all traced it
    if (shade_all && c.W > 0.0 && pcc > 0.0) {
        sel_vis = !(csc && scene_occluded(sh.p, dc, 0.0, tc >= T_INF ? T_INF : tc * (1.0 - 1e-4)));
        if (sel_vis) L += m_c * cc * c.W;
    }
    for (int k = 0; k < n; ++k) {
        vec3 d; float t; bool cs;
        vec3 ck = contrib(sh, nbr[k].x, d, t, cs);
        float pck = tgt(ck);
        float m_k = u_bias_mode == 0 ? nbr[k].M / Msum : pair_other(nbr[k].M * nbr[k].own, Bc * pck, fn);
        float xi = rng_next4(rng).x;
        bool vk = false;
        if (shade_all && nbr[k].W > 0.0 && pck > 0.0 && m_k > 0.0) {
            vk = !(cs && scene_occluded(sh.p, d, 0.0, t >= T_INF ? T_INF : t * (1.0 - 1e-4)));
            if (vk) L += m_k * ck * nbr[k].W;
        }
        if (update(r, nbr[k].x, m_k * pck * nbr[k].W, nbr[k].M, xi)) sel_vis = vk;
    }
    r.M = Msum;
    float ph = target(sh, r.x);
    r.W = ph > 0.0 ? r.wsum / ph : 0.0;
    r.own = ph;
    bool vis = r.W > 0.0 && sel_vis;
    if (!shade_all) {
        vec3 d; float t; bool casts;
        vec3 cr = contrib(sh, r.x, d, t, casts);
        vis = r.W > 0.0 && max3(cr) > 0.0
              && !(casts && scene_occluded(sh.p, d, 0.0, t >= T_INF ? T_INF : t * (1.0 - 1e-4)));
        L = vis ? cr * r.W : vec3(0.0);
    }
    L = sanitize(L);
    imageStore(o_color, px, vec4(L + sh.s.emission, 1.0));
    imageStore(o_direct, px, vec4(L, 1.0));
    imageStore(o_dbg_w, px, vec4(vec3(r.W), 1.0));
    imageStore(o_dbg_m, px, vec4(vec3(r.M), 1.0));
    if (!vis) r.W = 0.0;  // final visibility: a hidden sample does not live on in the history
    store_reservoir(px, r);
#else
    if (!sh.valid) {
        imageStore(o_color, px, vec4(world_background(px, imageSize(o_color)), 1.0));
        imageStore(o_direct, px, vec4(0.0, 0.0, 0.0, 1.0));
        imageStore(o_emit, px, vec4(0.0, 0.0, 0.0, 1.0));
        return;
    }
    vec3 acc = vec3(0.0);
    int spp = max(u_baseline_spp, 1);
    for (int k = 0; k < spp; ++k) {
        acc += shade_direct_at(sh.s, sh.p, sh.N, sh.Ng, sh.V, rng, u_baseline_bsdf == 2);
        if (u_baseline_bsdf == 1) {  // a uniform world, which light sampling does not cover, by one BSDF ray
            float pdf;
            vec3 dir = sample_principled(sh.s, sh.N, sh.V, rng_next4(rng).xyz, pdf);
            if (u_world_select <= 0.0 && pdf > 0.0 && dot(dir, sh.Ng) > 0.0 && max3(u_world_color) > 0.0
                && !scene_occluded(sh.p, dir, 0.0, T_INF)) {
                BsdfEval fe = eval_principled(sh.s, sh.N, sh.V, dir);
                acc += sanitize((fe.diffuse + fe.glossy) * world_radiance(dir) / pdf);
            }
        } else if (u_baseline_bsdf == 2) {  // the BSDF half of MIS: lights crossed, emissive surfaces, the world
            float pdf;
            vec3 dir = sample_principled(sh.s, sh.N, sh.V, rng_next4(rng).xyz, pdf);
            if (pdf > 0.0 && dot(dir, sh.Ng) > 0.0) {
                SurfaceHit hs;
                bool hit = scene_trace(sh.p, dir, 0.0, T_INF, hs);
                BsdfEval fe = eval_principled(sh.s, sh.N, sh.V, dir);
                acc += sanitize((fe.diffuse + fe.glossy) * bsdf_hit_light_mis(sh.p, dir, 0.0, hit, hs, pdf, true) / pdf);
            }
        }
    }
    vec3 L = sanitize(acc / float(spp));
    imageStore(o_color, px, vec4(L + sh.s.emission, 1.0));
    imageStore(o_direct, px, vec4(L, 1.0));
    imageStore(o_emit, px, vec4(sh.s.emission, 1.0));
#endif
}
