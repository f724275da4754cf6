// pt.comp — PT: unidirectional path tracer on the software two-level BVH (lib/bvh.glsl).
// References: Kajiya 1986 (the rendering equation); Veach & Guibas 1995 (MIS, power
// heuristic); Heitz 2018 (GGX visible-normal sampling, via lib/brdf.glsl).
// One invocation = one pixel, u_spp samples (box-filter jitter over the pixel square).
// Every light type in Cycles' units with next-event estimation + MIS against BSDF sampling;
// lights do not occlude (Cycles' lights are transparent to rays); world colour seen and
// lighting through BSDF sampling; Russian roulette after u_rr_start bounces.
// Writes the per-frame mean of its samples: colour and three effect AOVs
// (direct = paths with one scattering, indirect diffuse / glossy by the first lobe).
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/sampling.glsl"
#include "lib/rng.glsl"
#include "lib/brdf.glsl"
#include "lib/lights.glsl"
#include "lib/bvh.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform writeonly image2D o_color;
layout(binding = 1, rgba32f) uniform writeonly image2D o_direct;
layout(binding = 2, rgba32f) uniform writeonly image2D o_ind_diffuse;
layout(binding = 3, rgba32f) uniform writeonly image2D o_ind_glossy;

#ifndef BIND_LIGHT_CDF
#define BIND_LIGHT_CDF 15
#endif
// light selection: cdf[i] = P(select light <= i); cdf[u_light_count + i] = P(select light i)
layout(std430, binding = BIND_LIGHT_CDF) readonly buffer LightCdf { float light_cdf[]; };

uniform sampler2DArray u_textures;
uniform int u_material_count;
uniform mat4 u_cam_to_world;
uniform mat4 u_inv_proj;
uniform int u_ortho;
uniform float u_clip_start;
uniform vec3 u_world;
uniform uint u_sample;     // frame index within the accumulation (seeds)
uniform uint u_seed;
uniform int u_spp;
uniform int u_max_bounces;
uniform int u_max_diffuse;
uniform int u_max_glossy;
uniform int u_rr_start;
uniform ivec2 u_offset;
uniform int u_lights_visible_camera;  // Blender's default for light objects: 0    // tile origin (dispatches are tiled to stay short)

Material fetch_material(int id) {
    if (id < 0 || id >= u_material_count) id = u_material_count;  // the default material record
    return materials[id];
}

// Image textures as Cycles samples them with Linear interpolation and Repeat extension:
// bilinear between texel centres of the full-resolution image (x * width - 0.5), wrapping.
// Done by hand with texelFetch so no sampler state (mipmaps, anisotropy) can blur it.
vec3 texture_bilinear(vec2 uv, int layer) {
    ivec2 size = textureSize(u_textures, 0).xy;
    vec2 x = uv * vec2(size) - 0.5;
    vec2 f = floor(x);
    vec2 t = x - f;
    ivec2 i0 = ivec2(f);
    ivec2 a = ((i0 % size) + size) % size;
    ivec2 b = (((i0 + 1) % size) + size) % size;
    vec3 c00 = texelFetch(u_textures, ivec3(a.x, a.y, layer), 0).rgb;
    vec3 c10 = texelFetch(u_textures, ivec3(b.x, a.y, layer), 0).rgb;
    vec3 c01 = texelFetch(u_textures, ivec3(a.x, b.y, layer), 0).rgb;
    vec3 c11 = texelFetch(u_textures, ivec3(b.x, b.y, layer), 0).rgb;
    return mix(mix(c00, c10, t.x), mix(c01, c11, t.x), t.y);
}

// ---------------------------------------------------------------- light selection (sample_light: lib/lights.glsl)
int select_light(float u, out float prob) {
    int n = u_light_count;
    int lo = 0, hi = n - 1;
    while (lo < hi) {
        int mid = (lo + hi) / 2;
        if (light_cdf[mid] <= u) lo = mid + 1; else hi = mid;
    }
    prob = light_cdf[n + lo];
    return lo;
}

float light_select_prob(int i) { return light_cdf[u_light_count + i]; }

// ---------------------------------------------------------------- MIS pdfs of lights hit by BSDF rays
// Light index of the mesh light built from `instance`, -1 if none.
int mesh_light_of(int instance) {
    for (int i = 0; i < u_light_count; ++i) {
        Light L = lights[i];
        if (int(L.pos_type.w + 0.5) == LIGHT_MESH && int(emitters[int(L.axis_w.x + 0.5)].p1.w + 0.5) == instance)
            return i;
    }
    return -1;
}

// ---------------------------------------------------------------- path tracing
struct PathOut { vec3 color; vec3 direct; vec3 ind_diffuse; vec3 ind_glossy; };

void add(inout PathOut o, vec3 c, int depth, int first_lobe) {
    o.color += c;
    if (depth <= 1) o.direct += c;
    else if (first_lobe == 0) o.ind_diffuse += c;
    else o.ind_glossy += c;
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
    vec3 o, d;
    float tmin;
    camera_ray(pix, o, d, tmin);
    vec3 beta = vec3(1.0);
    float bsdf_pdf = 0.0;  // pdf of the last BSDF sample (0 = camera ray: no MIS)
    int depth = 0;         // scatterings so far
    int n_diffuse = 0, n_glossy = 0;
    int first_lobe = 0;
    bool last = false;     // a bounce limit was passed: collect emission at the next hit, then stop
    for (int iter = 0; iter < 64; ++iter) {
        RtHit h = rt_miss();
        bool hit = rt_trace_closest(o, d, tmin, T_INF, h);
        float t_surf = hit ? h.t : T_INF;
        // analytic lights crossed before the surface (area and sphere lights; transparent).
        // Blender light objects default to visible_camera = False: camera rays skip them.
        for (int i = 0; i < u_light_count && (depth > 0 || u_lights_visible_camera != 0); ++i) {
            Light L = lights[i];
            int type = int(L.pos_type.w + 0.5);
            vec3 Le = vec3(0.0);
            float lpdf = 0.0;
            if (type == LIGHT_AREA) {
                float t = intersect_area_light(L, o, d);
                if (t > tmin && t < t_surf) {
                    Le = L.color.rgb;
                    vec3 q = o + t * d;
                    lpdf = area_to_solid_angle_pdf(o, q, L.dir_radius.xyz, L.axis_v.w);
                }
            } else if ((type == LIGHT_POINT || type == LIGHT_SPOT) && L.dir_radius.w > 0.0) {
                float r = L.dir_radius.w;
                float t = intersect_sphere(L.pos_type.xyz, r, o, d);
                if (t > tmin && t < t_surf) {
                    vec3 toc = L.pos_type.xyz - o;
                    float d2 = dot(toc, toc);
                    if (d2 > r * r) {
                        float atten = type == LIGHT_SPOT ? spot_attenuation(L, normalize(-toc)) : 1.0;
                        Le = L.color.rgb * atten / (PI * r * r);
                        lpdf = cone_pdf(sqrt(max(0.0, 1.0 - r * r / d2)));
                    }
                }
            }
            if (lpdf > 0.0) {
                float w = bsdf_pdf > 0.0 ? power_heuristic(bsdf_pdf, light_select_prob(i) * lpdf) : 1.0;
                add(out_, beta * Le * w, depth, first_lobe);
            }
        }
        if (!hit) {
            vec3 Le = u_world;
            // suns with a size are seen by rays that leave the scene inside their disk
            for (int i = 0; i < u_light_count && (depth > 0 || u_lights_visible_camera != 0); ++i) {
                Light L = lights[i];
                if (int(L.pos_type.w + 0.5) != LIGHT_SUN || L.dir_radius.w <= 1e-6) continue;
                float cos_max = cos(L.dir_radius.w);
                if (dot(d, -L.dir_radius.xyz) < cos_max) continue;
                float sin_a = sin(L.dir_radius.w);
                vec3 Ls = L.color.rgb / (PI * sin_a * sin_a);
                float w = bsdf_pdf > 0.0 ? power_heuristic(bsdf_pdf, light_select_prob(i) * cone_pdf(cos_max)) : 1.0;
                add(out_, beta * Ls * w, depth, first_lobe);
            }
            add(out_, beta * Le, depth, first_lobe);
            break;
        }
        RtSurface sf = rt_surface(h);
        Material m = fetch_material(sf.material);
        vec3 base = m.base_color.rgb;
        if (m.base_color.w >= 0.0) base = texture_bilinear(sf.uv, int(m.base_color.w + 0.5));
        Surface s = make_surface(m, base);
        vec3 V = -d;
        vec3 Ng = sf.geo_normal;
        vec3 N = sf.normal;
        if (dot(Ng, V) < 0.0) { Ng = -Ng; N = -N; }  // two-sided shading, like Cycles' backfaces
        if (dot(N, V) <= 0.0) N = Ng;
        // emission (two-sided), MIS against the mesh light's sampling
        if (max3(s.emission) > 0.0) {
            float w = 1.0;
            if (bsdf_pdf > 0.0) {
                int li = mesh_light_of(h.instance);
                if (li >= 0) {
                    Light L = lights[li];
                    vec3 p0 = (rt_instances[h.instance].object_to_world * vec4(rt_verts[3 * h.prim].xyz, 1.0)).xyz;
                    vec3 p1 = (rt_instances[h.instance].object_to_world * vec4(rt_verts[3 * h.prim + 1].xyz, 1.0)).xyz;
                    vec3 p2 = (rt_instances[h.instance].object_to_world * vec4(rt_verts[3 * h.prim + 2].xyz, 1.0)).xyz;
                    float area = 0.5 * length(cross(p1 - p0, p2 - p0));
                    float tri_power = area * (s.emission.r + s.emission.g + s.emission.b) / 3.0 * PI;
                    float tri_prob = tri_power / max(L.color.w, 1e-20);
                    float lpdf = light_select_prob(li) * tri_prob *
                                 area_to_solid_angle_pdf(o, sf.position, sf.geo_normal, area);
                    w = power_heuristic(bsdf_pdf, lpdf);
                }
            }
            add(out_, beta * s.emission * w, depth, first_lobe);
        }
        if (last) break;
        vec3 p = rt_offset_ray(sf.position, Ng);
        // next-event estimation: one light by power
        if (u_light_count > 0) {
            vec4 ul = rng_next4(rng);
            float sel;
            int li = select_light(ul.x, sel);
            Light L = lights[li];
            LightSample ls = sample_light(L, p, ul.yz, ul.w);  // from the offset origin: the shadow ray ends exactly at the sample
            if (ls.pdf > 0.0 && sel > 0.0 && dot(ls.dir, Ng) > 0.0) {
                BsdfEval fe = eval_principled(s, N, V, ls.dir);
                vec3 f = fe.diffuse + fe.glossy;
                if (max3(f) > 0.0 && max3(ls.Li) > 0.0) {
                    bool blocked = L.axis_w.w > 0.5 && rt_trace_any(p, ls.dir, 0.0, ls.dist * (1.0 - 1e-4));
                    if (!blocked) {
                        float lpdf = sel * ls.pdf;
                        float w = ls.delta ? 1.0 : power_heuristic(lpdf, pdf_principled(s, N, V, ls.dir));
                        // NEE contributes to path depth + 1 with the lobe mix of this vertex
                        vec3 c = beta * f * ls.Li * (w / lpdf);
                        if (depth == 0) {
                            out_.color += c;
                            out_.direct += c;
                        } else {
                            add(out_, c, depth + 1, first_lobe);
                        }
                    }
                }
            }
        }
        // BSDF sampling (also at the last vertex: the MIS companion of its light sample)
        vec4 ub = rng_next4(rng);
        float NoV = max(dot(N, V), 1e-4);
        vec2 lw = lobe_weights(s, NoV);
        int lobe = ub.z < lw.x ? 0 : 1;
        float pdf;
        vec3 L = sample_principled(s, N, V, ub.xyz, pdf);
        if (pdf <= 0.0 || dot(L, Ng) <= 0.0) break;
        BsdfEval fe = eval_principled(s, N, V, L);
        vec3 f = fe.diffuse + fe.glossy;
        if (max3(f) <= 0.0) break;
        if (lobe == 0) ++n_diffuse; else ++n_glossy;
        if (depth == 0) first_lobe = lobe;
        beta *= f / pdf;
        bsdf_pdf = pdf;
        depth += 1;
        last = depth > u_max_bounces || n_diffuse > u_max_diffuse || n_glossy > u_max_glossy;
        o = p;
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

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy) + u_offset;
    ivec2 size = imageSize(o_color);
    if (px.x >= size.x || px.y >= size.y) return;
    PathOut acc;
    acc.color = vec3(0.0); acc.direct = vec3(0.0); acc.ind_diffuse = vec3(0.0); acc.ind_glossy = vec3(0.0);
    for (int k = 0; k < u_spp; ++k) {
        Rng rng = rng_init(uvec2(px), u_sample * uint(u_spp) + uint(k), u_seed);
        vec2 j = rng_next2(rng);
        PathOut r = trace_path(vec2(px) + j, rng);
        acc.color += sanitize(r.color);
        acc.direct += sanitize(r.direct);
        acc.ind_diffuse += sanitize(r.ind_diffuse);
        acc.ind_glossy += sanitize(r.ind_glossy);
    }
    float inv = 1.0 / float(max(u_spp, 1));
    imageStore(o_color, px, vec4(acc.color * inv, 1.0));
    imageStore(o_direct, px, vec4(acc.direct * inv, 1.0));
    imageStore(o_ind_diffuse, px, vec4(acc.ind_diffuse * inv, 1.0));
    imageStore(o_ind_glossy, px, vec4(acc.ind_glossy * inv, 1.0));
}
