// pt.comp — PT: unidirectional path tracer on the software two-level BVH (lib/bvh.glsl).
// References: Kajiya 1986 (the rendering equation); Veach & Guibas 1995 (MIS, power
// heuristic); Heitz 2018 (GGX visible-normal sampling, via lib/brdf.glsl).
// One invocation = one pixel, u_spp samples (box-filter jitter over the pixel square): the
// in-pixel position is white noise (u_pixel_sequence 0) or Halton(2,3) indexed by the frame
// counter u_sample (x u_spp + k), Cranley-Patterson rotated per pixel (u_pixel_sequence 1; the
// pass chooses per frame: param pixel_sequence, techniques/pt.py).
// Every light type in Cycles' units with next-event estimation + MIS against BSDF sampling;
// lights do not occlude (Cycles' lights are transparent to rays); world colour seen and
// lighting through BSDF sampling; Russian roulette after u_rr_start bounces.
// Materials: every lobe of the material's lobe list (RT_EXACT_BSDF: lib/bsdf.glsl), refraction
// and diffuse transmission leaving from the far side of the surface; transmission bounces
// counted against u_max_transmission as Cycles counts them.
// Writes the per-frame mean of its samples: colour and three effect AOVs
// (direct = paths with one scattering, indirect diffuse / glossy by the first lobe).
// With PT_SHARES (render/effect_shares.py) three more: what camera rays see directly on a
// surface (emission) and on a miss (environment), and the indirect paths whose first lobe is
// transmission (a part of the glossy AOV).
// Ray tracing, materials, light selection, NEE and the MIS of BSDF rays hitting lights are
// the shared component lib/scene_rt.glsl (host side: render/rt_scene.py SceneRT).
#define USE_SCENE_BUFFERS
#define RT_EXACT_BSDF
#include "lib/common.glsl"
#include "lib/sampling.glsl"
#include "lib/rng.glsl"
#include "lib/brdf.glsl"
#include "lib/lights.glsl"
// the shared ray-tracing component: scene_trace, shade_direct_at, bsdf_hit_light_mis
#include "lib/scene_rt.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform writeonly image2D o_color;
layout(binding = 1, rgba32f) uniform writeonly image2D o_direct;
layout(binding = 2, rgba32f) uniform writeonly image2D o_ind_diffuse;
layout(binding = 3, rgba32f) uniform writeonly image2D o_ind_glossy;
#ifdef PT_SHARES
layout(binding = 4, rgba32f) uniform writeonly image2D o_emission;
layout(binding = 5, rgba32f) uniform writeonly image2D o_environment;
layout(binding = 6, rgba32f) uniform writeonly image2D o_ind_transmission;
#endif

uniform mat4 u_cam_to_world;
uniform mat4 u_inv_proj;
uniform int u_ortho;
uniform float u_clip_start;
uniform uint u_sample;     // frame index within the accumulation (seeds)
uniform uint u_seed;
uniform int u_spp;
uniform int u_max_bounces;
uniform int u_max_diffuse;
uniform int u_max_glossy;
uniform int u_max_transmission;
uniform int u_rr_start;
uniform ivec2 u_offset;    // tile origin (dispatches are tiled to stay short)
uniform int u_pixel_sequence;  // in-pixel position: 0 white noise, 1 Halton(2,3) over u_sample, rotated per pixel
uniform int u_lights_visible_camera;  // Blender's default for light objects: 0

// ---------------------------------------------------------------- path tracing
struct PathOut {
    vec3 color; vec3 direct; vec3 ind_diffuse; vec3 ind_glossy; float coverage;
#ifdef PT_SHARES
    vec3 emission; vec3 environment; vec3 ind_transmission;
#endif
};

// first_lobe: 0 diffuse, 1 glossy, 2 transmission (counted as glossy)
void add(inout PathOut o, vec3 c, int depth, int first_lobe) {
    o.color += c;
    if (depth <= 1) o.direct += c;
    else if (first_lobe == 0) o.ind_diffuse += c;
    else {
        o.ind_glossy += c;
#ifdef PT_SHARES
        if (first_lobe == 2) o.ind_transmission += c;
#endif
    }
}

void camera_ray(vec2 pix, out vec3 o, out vec3 d, out float tmin) {
    vec2 size = vec2(imageSize(o_color));
    vec2 ndc = pix / size * 2.0 - 1.0;
    if (u_ortho == 1) {
        vec4 a = u_inv_proj * vec4(ndc, -1.0, 1.0);
        o = (u_cam_to_world * vec4(a.xyz / a.w, 1.0)).xyz;
        d = normalize(-u_cam_to_world[2].xyz);
        tmin = 0.0;
    } else {
        vec4 v = u_inv_proj * vec4(ndc, 1.0, 1.0);
        vec3 vd = normalize(v.xyz / v.w);
        o = u_cam_to_world[3].xyz;
        d = normalize(mat3(u_cam_to_world) * vd);
        tmin = u_clip_start / max(-vd.z, 1e-6);
    }
}

PathOut trace_path(vec2 pix, inout Rng rng) {
    PathOut out_;
    out_.color = vec3(0.0); out_.direct = vec3(0.0); out_.ind_diffuse = vec3(0.0); out_.ind_glossy = vec3(0.0);
    out_.coverage = 0.0;
#ifdef PT_SHARES
    out_.emission = vec3(0.0); out_.environment = vec3(0.0); out_.ind_transmission = vec3(0.0);
#endif
    vec3 o, d;
    float tmin;
    camera_ray(pix, o, d, tmin);
    vec3 beta = vec3(1.0);
    float last_pdf = 0.0;  // pdf of the last BSDF sample (0 = camera ray: no MIS)
    int depth = 0;         // scatterings so far
    int n_diffuse = 0, n_glossy = 0, n_transmission = 0;
    int first_lobe = 0;
    bool last = false;     // a bounce limit was passed: collect emission at the next hit, then stop
    for (int iter = 0; iter < 64; ++iter) {
        SurfaceHit sh;
        bool hit = scene_trace(o, d, tmin, T_INF, sh);
        // emission along the ray: lights crossed (transparent), sun disks and the world on a
        // miss, the surface's emission on a hit; MIS-weighted against NEE (the shared block)
        vec3 Le = bsdf_hit_light_mis(o, d, tmin, hit, sh, last_pdf, depth > 0 || u_lights_visible_camera != 0);
        if (max3(Le) > 0.0) add(out_, beta * Le, depth, first_lobe);
#ifdef PT_SHARES
        if (depth == 0) {
            if (hit) out_.emission += Le;
            else out_.environment += Le;
        }
#endif
        if (depth == 0 && hit) out_.coverage = 1.0;
        if (!hit || last) break;
        Surface s = sh.bsdf;
        bsdf_begin(s);  // the material's lobes, once per vertex
        vec3 V = -d;
        vec3 N, Ng, p;
        surface_frame(sh, V, N, Ng, p);
        // next-event estimation: one light by power, MIS with the BSDF ray below
        vec3 c = beta * shade_direct_at(s, p, N, Ng, V, rng, true);
        if (max3(c) > 0.0) {
            // NEE contributes to path depth + 1 with the lobe mix of this vertex
            if (depth == 0) {
                out_.color += c;
                out_.direct += c;
            } else {
                add(out_, c, depth + 1, first_lobe);
            }
        }
        // BSDF sampling (also at the last vertex: the MIS companion of its light sample)
        vec4 ub = rng_next4(rng);
        int lobe;
        vec3 L = bsdf_sample(s, N, V, ub.xyz, lobe);
        bool through = dot(L, Ng) < 0.0;  // refraction / translucency: below the surface
        if (through != (lobe == LOBE_TRANSMISSION)) break;
        float pdf = bsdf_pdf(s, N, V, L);
        if (pdf <= 0.0) break;
        BsdfEval fe = bsdf_eval(s, N, V, L);
        vec3 f = fe.diffuse + fe.glossy;
        if (max3(f) <= 0.0) break;
        if (lobe == LOBE_DIFFUSE) ++n_diffuse;
        else if (lobe == LOBE_GLOSSY) ++n_glossy;
        else ++n_transmission;
        if (depth == 0) first_lobe = lobe == LOBE_DIFFUSE ? 0 : (lobe == LOBE_TRANSMISSION ? 2 : 1);
        beta *= f / pdf;
        last_pdf = pdf;
        depth += 1;
        last = depth > u_max_bounces || n_diffuse > u_max_diffuse || n_glossy > u_max_glossy
            || n_transmission > u_max_transmission;
        o = through ? rt_offset_ray(sh.position, -Ng) : p;
        d = L;
        tmin = 0.0;
        if (depth >= u_rr_start) {
            float q = min(max3(beta), 1.0);
            if (ub.w >= q) break;
            beta /= q;
        }
    }
    return out_;
}

// The in-pixel position of sample `index` of pixel px: Halton(2,3) with a per-pixel
// Cranley-Patterson rotation (a hash of the pixel alone, so it stays fixed over frames and the
// pixel's own positions stay stratified; neighbours do not move together).
vec2 pixel_halton(ivec2 px, uint index) {
    uvec4 h = pcg4d(uvec4(uvec2(px), 0x2545F491u, 0x9E3779B9u));
    vec2 rot = vec2(h.xy >> 8u) * (1.0 / 16777216.0);
    return fract(halton23(index) + rot);
}

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy) + u_offset;
    ivec2 size = imageSize(o_color);
    if (px.x >= size.x || px.y >= size.y) return;
    PathOut acc;
    acc.color = vec3(0.0); acc.direct = vec3(0.0); acc.ind_diffuse = vec3(0.0); acc.ind_glossy = vec3(0.0);
    acc.coverage = 0.0;
#ifdef PT_SHARES
    vec3 a_emission = vec3(0.0), a_environment = vec3(0.0), a_transmission = vec3(0.0);
#endif
    for (int k = 0; k < u_spp; ++k) {
        Rng rng = rng_init(uvec2(px), u_sample * uint(u_spp) + uint(k), u_seed);
        vec2 j = rng_next2(rng);  // drawn in both modes: the path's random numbers stay the same
        if (u_pixel_sequence >= 1) j = pixel_halton(px, u_sample * uint(u_spp) + uint(k));
        PathOut r = trace_path(vec2(px) + j, rng);
        acc.color += sanitize(r.color);
        acc.direct += sanitize(r.direct);
        acc.ind_diffuse += sanitize(r.ind_diffuse);
        acc.ind_glossy += sanitize(r.ind_glossy);
        acc.coverage += r.coverage;
#ifdef PT_SHARES
        a_emission += sanitize(r.emission);
        a_environment += sanitize(r.environment);
        a_transmission += sanitize(r.ind_transmission);
#endif
    }
    float inv = 1.0 / float(max(u_spp, 1));
    // alpha: with a transparent film, the camera rays' coverage (the session's alpha)
    imageStore(o_color, px, vec4(acc.color * inv, u_film_transparent != 0 ? acc.coverage * inv : 1.0));
    imageStore(o_direct, px, vec4(acc.direct * inv, 1.0));
    imageStore(o_ind_diffuse, px, vec4(acc.ind_diffuse * inv, 1.0));
    imageStore(o_ind_glossy, px, vec4(acc.ind_glossy * inv, 1.0));
#ifdef PT_SHARES
    imageStore(o_emission, px, vec4(a_emission * inv, 1.0));
    imageStore(o_environment, px, vec4(a_environment * inv, 1.0));
    imageStore(o_ind_transmission, px, vec4(a_transmission * inv, 1.0));
#endif
}
