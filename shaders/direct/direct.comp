// direct.comp — DIRECT: direct lighting from every light type and emissive meshes, with
// shadow-map visibility, emission, and the world as background only (no ambient).
// Diffuse: exact (point/sphere/sun cosine law; polygon irradiance for area lights and
// emissive triangles). Glossy: Monte Carlo with multiple importance sampling (light
// sampling + GGX visible-normal sampling, power heuristic), converging over frames.
// The world: background, and a light like any other (as in Cycles' "direct" reference):
// uniform radiance times the lobes' albedos, shadowed by the world visibility from the
// orthographic maps the shadow pass renders along sampled directions each frame.
// Reads the G-buffer; writes color, GI_Direct, Emit and the world's glossy term (for SSR).
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/rng.glsl"
#include "lib/sampling.glsl"
#include "lib/brdf.glsl"
#include "lib/lights.glsl"
#include "lib/shadows.glsl"
#include "lib/albedo.glsl"

layout(local_size_x = 8, local_size_y = 8) in;

layout(binding = 0, rgba32f) uniform writeonly image2D o_color;
layout(binding = 1, rgba32f) uniform writeonly image2D o_direct;
layout(binding = 2, rgba32f) uniform writeonly image2D o_emit;
layout(binding = 3, rgba32f) uniform writeonly image2D o_world_spec;

uniform sampler2D u_gb_albedo;
uniform sampler2D u_gb_normal;
uniform sampler2D u_gb_position;
uniform sampler2D u_gb_geonormal;
uniform vec3 u_camera_pos;
uniform int u_ortho;
uniform vec3 u_camera_dir;
uniform vec3 u_world;
uniform uint u_sample;
uniform int u_glossy_samples;
uniform int u_mesh_exact_max;
uniform int u_world_first;
uniform int u_world_count;  // 0: the world lights nothing (black, or no world views)

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

// Diffuse BRDF constant (Lambert under the specular layer), i.e. f_d = this / 1.
vec3 diffuse_brdf(Surface s, vec3 N, vec3 V) {
    float layer = 1.0 - dielectric_layer_albedo(s, max(dot(N, V), 1e-4));
    return (1.0 - s.metallic) * s.base_color * INV_PI * layer;
}

vec3 shade_light(int li, Surface s, vec3 P, vec3 N, vec3 Ng, vec3 V, inout Rng rng) {
    Light L = lights[li];
    int type = int(L.pos_type.w + 0.5);
    vec3 result = vec3(0.0);
    bool has_glossy = (s.metallic > 0.0 || s.f0 > 0.0);
    if (type == LIGHT_POINT || type == LIGHT_SPOT) {
        vec3 d = L.pos_type.xyz - P;
        float dist2 = dot(d, d);
        float dist = sqrt(dist2);
        vec3 wi = d / dist;
        vec3 I = L.color.rgb;
        if (type == LIGHT_SPOT) I *= spot_attenuation(L, -wi);
        if (max3(I) <= 0.0) return vec3(0.0);
        float r = L.dir_radius.w;
        float NoL = dot(N, wi);
        if (r <= 0.0 || dist <= r * 1.0001) {
            BsdfEval e = eval_principled(s, N, V, wi);
            return I * (e.diffuse + e.glossy) / dist2;
        }
        // sphere light: diffuse by the cosine law (exact above the horizon)
        result += I * diffuse_brdf(s, N, V) * max(NoL, 0.0) / dist2;
        if (has_glossy) {
            vec3 Ls = I / (PI * r * r);
            float pl = cone_pdf(sqrt(max(0.0, 1.0 - r * r / dist2)));
            for (int k = 0; k < u_glossy_samples; ++k) {
                vec4 u = rng_next4(rng);
                result += glossy_light_sample(L, s, P, N, V, u.xyz);
                vec3 w2 = sample_glossy(s, N, V, u.zw);
                if (intersect_sphere(L.pos_type.xyz, r, P, w2) > 0.0) {
                    float pb2 = glossy_pdf(s, N, V, w2);
                    if (pb2 > 0.0)
                        result += Ls * glossy_fcos(s, N, V, w2) * power_heuristic(pb2, pl) / (pb2 * float(u_glossy_samples));
                }
            }
        }
        return result;
    }
    if (type == LIGHT_SUN) {
        vec3 wi = -L.dir_radius.xyz;
        vec3 E = L.color.rgb;
        float half_angle = L.dir_radius.w;
        if (half_angle < 1e-4) {
            BsdfEval e = eval_principled(s, N, V, wi);
            return E * (e.diffuse + e.glossy);
        }
        result += E * diffuse_brdf(s, N, V) * max(dot(N, wi), 0.0);
        if (has_glossy) {
            float sa = sin(half_angle);
            vec3 Ls = E / (PI * sa * sa);
            float cos_max = cos(half_angle);
            float pl = cone_pdf(cos_max);
            for (int k = 0; k < u_glossy_samples; ++k) {
                vec4 u = rng_next4(rng);
                result += glossy_light_sample(L, s, P, N, V, u.xyz);
                vec3 w2 = sample_glossy(s, N, V, u.zw);
                if (dot(w2, wi) >= cos_max) {
                    float pb2 = glossy_pdf(s, N, V, w2);
                    if (pb2 > 0.0)
                        result += Ls * glossy_fcos(s, N, V, w2) * power_heuristic(pb2, pl) / (pb2 * float(u_glossy_samples));
                }
            }
        }
        return result;
    }
    if (type == LIGHT_AREA) {
        vec3 Le = L.color.rgb;
        float area = max(L.axis_v.w, 1e-12);
        result += Le * diffuse_brdf(s, N, V) * area_light_irradiance_factor(L, P, N);
        if (has_glossy) {
            for (int k = 0; k < u_glossy_samples; ++k) {
                vec4 u = rng_next4(rng);
                result += glossy_light_sample(L, s, P, N, V, u.xyz);
                vec3 w2 = sample_glossy(s, N, V, u.zw);
                float t = intersect_area_light(L, P, w2);
                if (t > 0.0) {
                    float pb2 = glossy_pdf(s, N, V, w2);
                    float pl2 = area_to_solid_angle_pdf(P, P + t * w2, L.dir_radius.xyz, area);
                    if (pb2 > 0.0)
                        result += Le * glossy_fcos(s, N, V, w2) * power_heuristic(pb2, pl2) / (pb2 * float(u_glossy_samples));
                }
            }
        }
        return result;
    }
    if (type == LIGHT_MESH) {
        int first = int(L.axis_w.x + 0.5);
        int count = int(L.axis_w.y + 0.5);
        vec3 fd = diffuse_brdf(s, N, V);
        if (count <= u_mesh_exact_max) {
            for (int i = first; i < first + count; ++i) {
                Emitter e = emitters[i];
                result += e.radiance.rgb * fd * triangle_irradiance_factor(e.p0.xyz, e.p1.xyz, e.p2.xyz, P, N);
            }
        } else {
            const int K = 8;
            for (int k = 0; k < K; ++k) {
                float prob;
                int i = pick_emitter(L, rng_next(rng), prob);
                Emitter e = emitters[i];
                float f = triangle_irradiance_factor(e.p0.xyz, e.p1.xyz, e.p2.xyz, P, N);
                result += e.radiance.rgb * fd * f / (prob * float(K));
            }
        }
        if (has_glossy) {
            for (int k = 0; k < u_glossy_samples; ++k) {
                // light sampling only (no BSDF branch for meshes): weight 1
                vec4 u = rng_next4(rng);
                LightSample ls = sample_light(L, P, u.xy, u.z);
                if (ls.pdf > 0.0)
                    result += ls.Li * glossy_fcos(s, N, V, ls.dir) / (ls.pdf * float(u_glossy_samples));
            }
        }
        return result;
    }
    return vec3(0.0);
}

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    ivec2 size = imageSize(o_color);
    if (any(greaterThanEqual(px, size))) return;
    vec4 pos = texelFetch(u_gb_position, px, 0);
    if (pos.w < 0.0) {
        imageStore(o_color, px, vec4(sanitize(u_world), 1.0));
        imageStore(o_direct, px, vec4(0.0, 0.0, 0.0, 1.0));
        imageStore(o_emit, px, vec4(0.0, 0.0, 0.0, 1.0));
        imageStore(o_world_spec, px, vec4(0.0, 0.0, 0.0, 1.0));
        return;
    }
    int mid = int(pos.w + 0.5);
    vec3 P = pos.xyz;
    vec3 N = normalize(texelFetch(u_gb_normal, px, 0).xyz);
    vec3 Ng = normalize(texelFetch(u_gb_geonormal, px, 0).xyz);
    vec3 V = u_ortho == 1 ? -u_camera_dir : normalize(u_camera_pos - P);
    Surface s = make_surface(materials[mid], texelFetch(u_gb_albedo, px, 0).rgb);
    Rng rng = rng_init(uvec2(px), u_sample, 1u);
    vec3 direct = vec3(0.0);
    for (int i = 0; i < u_light_count; ++i) {
        vec3 c = shade_light(i, s, P, N, Ng, V, rng);
        if (max3(c) <= 0.0) continue;
        direct += c * light_visibility(lights[i], P, N, Ng);
    }
    vec3 world_spec = vec3(0.0);
    if (u_world_count > 0) {
        // the glossy lobe's dominant direction (Lagarde & de Rousiers 2014): R for smooth
        // surfaces, bending towards N as the roughness grows
        vec3 R = reflect(-V, N);
        float a = s.alpha;
        vec3 D = normalize(mix(N, R, (1.0 - a) * (sqrt(1.0 - a) + a)));
        float vis_d, vis_g;
        world_visibility(u_world_first, u_world_count, P, N, Ng, D, vis_d, vis_g);
        float NoV = max(dot(N, V), 1e-4);
        direct += u_world * diffuse_albedo(s, NoV) * vis_d;
        world_spec = sanitize(u_world * specular_albedo(s, NoV) * vis_g);
        direct += world_spec;
    }
    direct = sanitize(direct);
    vec3 emit = sanitize(s.emission);
    imageStore(o_color, px, vec4(direct + emit, 1.0));
    imageStore(o_direct, px, vec4(direct, 1.0));
    imageStore(o_emit, px, vec4(emit, 1.0));
    imageStore(o_world_spec, px, vec4(world_spec, 1.0));
}
