// scene_rt.glsl — the scene ray-tracing component every compute pass binds (PT, DIRECT's
// ray-traced shadows, later ReSTIR, probes, surfels, ...). Host side: addon/render/rt_scene.py
// (SceneRT, one per GPUScene: `rt = rc.scene.rt(); prog = programs.compute(path, rt.defines);
// rt.bind(prog)`).
//
// Include after: common.glsl (with USE_SCENE_BUFFERS), sampling.glsl, rng.glsl, brdf.glsl,
// lights.glsl; this file includes bvh.glsl and textures.glsl.
//
// API
//   Ray/scene intersection with the surface interaction, materials sampled as the G-buffer does:
//     SurfaceHit s;  bool hit = scene_trace(o, d, tmin, tmax, s);
//     bool blocked = scene_occluded(o, d, tmin, tmax);
//     Material m = scene_material(id);   vec3 base = scene_base_color(m, uv);
//   Light selection (lib/light_select.glsl): by a light tree at shading point p (normal n, or
//   vec3(0): none), suns by power outside it; by power alone without a shading point:
//     int i = select_light(u, p, n, prob);   float prob = light_pdf(i, p, n);
//     int i = select_light(u, prob);         float prob = light_pdf(i);
//     int li = mesh_light_of(instance);  // the mesh light built from an emissive instance, -1 none
//   Direct light at any surface point (next-event estimation: one light by the tree, or the world
//   map by its luminance, one point on it, one shadow ray through the BVH):
//     vec3 Ld = shade_direct(s, V, rng);              // alone: unbiased, light sampling only
//     vec3 Ld = shade_direct_mis(s, V, rng);          // weighted for MIS with a BSDF ray whose
//                                                     //   emission is taken by bsdf_hit_light_mis
//   Emission seen by a BSDF-sampled ray (lights crossed, sun disks and the world on a miss, an
//   emissive surface on a hit), MIS-weighted against shade_direct_mis's light sampling; the one
//   copy of that block (PT uses it for every bounce):
//     vec3 Le = bsdf_hit_light_mis(o, d, tmin, hit, s, bsdf_pdf, lights_visible);
// Conventions: SurfaceHit.geo_normal is the winding's normal (not flipped); surface_frame()
// gives the two-sided shading frame facing V, as Cycles shades back faces. Lights are
// transparent to rays (Cycles): scene_trace and scene_occluded see triangles only.
// Materials are sampled with lib/textures.glsl's sample_material (the G-buffer's function):
// SurfaceHit.normal is the normal-mapped shading normal. Alpha: when some material has holes
// (RT_SCENE_ALPHA, from SceneRT.defines), every candidate hit of every ray (closest and any-hit) is a hole with
// probability 1 - alpha (Cycles' stochastic transparency), decided by a hash of the ray and
// the triangle, so a ray meets the same holes in both queries.
#ifndef GI_SCENE_RT_GLSL
#define GI_SCENE_RT_GLSL

#ifdef RT_SCENE_ALPHA  // SceneRT.defines: some material has holes (the test costs traversal time)
#define RT_ALPHA_TEST
#endif
#include "lib/bvh.glsl"
#include "lib/textures.glsl"
#include "lib/world.glsl"

#ifndef RT_BINDING_LIGHT_SELECT
#define RT_BINDING_LIGHT_SELECT 15
#endif
// [0, n): cdf of selecting lights 0..i by power; [n, 2n): probability of light i;
// [2n, 2n + instances): the mesh light of each instance (-1: not emissive), as floats; the
// world map's tables (u_world_table); the light tree and light BVH (u_light_tree,
// lib/light_select.glsl)
layout(std430, binding = RT_BINDING_LIGHT_SELECT) readonly buffer RtLightSelect { float rt_light_select[]; };
#include "lib/light_select.glsl"

uniform sampler2DArray u_textures;
uniform int u_material_count;
// The world map as a light (lib/world.glsl): chosen by next-event estimation with probability
// u_world_select (0 for a uniform world: it is then reached by BSDF rays only), then a
// direction by the map's sampling tables at u_world_table in rt_light_select (marginal CDF
// over the u_world_grid.y rows, then one conditional CDF of u_world_grid.x cells per row;
// render/world_map.py builds them and samples the same way on the CPU).
uniform float u_world_select;
uniform int u_world_table;
uniform ivec2 u_world_grid;
uniform int u_alpha_test;  // 1 when some material has alpha < 1 or an alpha texture

// a material's lobe list (Mix/Add Shaders, glass, translucency): bsdf_eval / bsdf_pdf / bsdf_sample
#include "lib/bsdf.glsl"

int rt_hit_material(int instance, int prim) {
    int mat = rt_tri_info[prim].y;
    int off = rt_instances[instance].info.z;
    if (off >= 0 && mat >= 0) mat = rt_material_map[off + mat];
    return (mat < 0 || mat >= u_material_count) ? u_material_count : mat;
}

bool rt_alpha_skip(int instance, int prim, vec2 bary, vec3 o, vec3 inv_d) {
    if (u_alpha_test == 0) return false;
    Material m = materials[rt_hit_material(instance, prim)];
    if (m.emission.w >= 1.0 && m.maps[MAP_ALPHA].x < 0.0) return false;
    float b0 = 1.0 - bary.x - bary.y;
    vec2 uv = b0 * vec2(rt_normals[6 * prim].w, rt_verts[3 * prim].w)
            + bary.x * vec2(rt_normals[6 * prim + 2].w, rt_verts[3 * prim + 1].w)
            + bary.y * vec2(rt_normals[6 * prim + 4].w, rt_verts[3 * prim + 2].w);
    float a = material_alpha(u_textures, m, uv);
    if (a >= 1.0) return false;
    if (a <= 0.0) return true;
    uvec3 seed = floatBitsToUint(o) ^ (floatBitsToUint(inv_d) * 747796405u) ^ uvec3(uint(prim) * 2891336453u, uint(instance), 0x9E3779B9u);
    return alpha_hash_u01(seed) >= a;
}

struct SurfaceHit {
    float t;
    vec3 position;     // world space
    vec3 geo_normal;   // world, unit, from the triangle's winding (not flipped towards the ray)
    vec3 normal;       // world, unit, interpolated corner normal, normal-mapped (not flipped)
    vec2 uv;
    int material;      // index into the material buffer (out-of-range ids: the default record)
    int instance;      // SceneData.instances index
    int prim;          // triangle in BVH order
    int triangle;      // original triangle index within its mesh
    Surface bsdf;      // lib/brdf.glsl surface with the base colour textured (emission inside)
};

Material scene_material(int id) {
    if (id < 0 || id >= u_material_count) id = u_material_count;  // the default material record
    return materials[id];
}

vec3 scene_base_color(Material m, vec2 uv) { return material_base_color(u_textures, m, uv); }

bool scene_trace(vec3 o, vec3 d, float tmin, float tmax, out SurfaceHit s) {
    RtHit h = rt_miss();
    s.t = T_INF;
    s.instance = -1;
    s.prim = -1;
    if (!rt_trace_closest(o, d, tmin, tmax, h)) return false;
    RtSurface sf = rt_surface(h);
    s.t = h.t;
    s.position = sf.position;
    s.geo_normal = sf.geo_normal;
    s.uv = sf.uv;
    s.instance = h.instance;
    s.prim = h.prim;
    s.triangle = sf.triangle;
    int mid = (sf.material < 0 || sf.material >= u_material_count) ? u_material_count : sf.material;
    s.material = mid;
    Material m = materials[mid];
    g_vertex_color = sf.color;
    MaterialSample ms = sample_material(u_textures, m, sf.uv);
    s.normal = shading_normal(ms, sf.normal, sf.tangent, sf.dpdu, sf.dpdv);
    s.bsdf = make_surface(material_at(m, ms), ms.base_color);
#ifdef RT_EXACT_BSDF  // the path tracer: the material's lobe list rather than its blended record
    s.bsdf.material = mid;
    s.bsdf.uv = sf.uv;
    s.bsdf.backfacing = dot(sf.geo_normal, d) > 0.0;
    s.bsdf.transmits = m.bsdf.w > 0.5;
    if (ms.normal_map.w > 0.0 || ms.bump.z > 0.0) s.bsdf.ns = sf.normal;
    s.bsdf.coat_n = sf.normal;  // an unlinked Coat Normal is the smooth normal (Cycles' sd->N)
#endif
    return true;
}

bool scene_occluded(vec3 o, vec3 d, float tmin, float tmax) { return rt_trace_any(o, d, tmin, tmax); }

// Two-sided shading frame facing V: Ng and N flipped together to V's side; a shading normal
// still facing away falls back to Ng. p = the shading point moved off the surface along Ng
// (rays leave from there).
void surface_frame(SurfaceHit s, vec3 V, out vec3 N, out vec3 Ng, out vec3 p) {
    Ng = s.geo_normal;
    N = s.normal;
    if (dot(Ng, V) < 0.0) { Ng = -Ng; N = -N; }
    if (dot(N, V) <= 0.0) N = Ng;
    p = rt_offset_ray(s.position, Ng);
}

// ---------------------------------------------------------------- light selection
// select_light / light_pdf: lib/light_select.glsl (included above)
int mesh_light_of(int instance) {
    return instance < 0 ? -1 : int(floor(rt_light_select[2 * u_light_count + instance] + 0.5));
}

// Probability that next-event estimation from p picks light i (the world takes
// u_world_select): the light tree's, without the receiver's normal (see light_select.glsl).
float nee_light_prob(int i, vec3 p) { return light_pdf(i, p, vec3(0.0)) * (1.0 - u_world_select); }

// First index in [first, first + n) whose cdf entry exceeds u (n - 1 if none).
int world_cdf_search(int first, int n, float u) {
    int lo = 0, hi = n - 1;
    while (lo < hi) {
        int mid = (lo + hi) / 2;
        if (rt_light_select[first + mid] <= u) lo = mid + 1; else hi = mid;
    }
    return lo;
}

float world_cell_prob(int row, int col) {
    int gw = u_world_grid.x;
    float r1 = rt_light_select[u_world_table + row];
    float r0 = row > 0 ? rt_light_select[u_world_table + row - 1] : 0.0;
    int c = u_world_table + u_world_grid.y + row * gw;
    float c1 = rt_light_select[c + col];
    float c0 = col > 0 ? rt_light_select[c + col - 1] : 0.0;
    return (r1 - r0) * (c1 - c0);
}

// Solid-angle pdf with which world_sample produces direction d (map worlds only).
float world_pdf(vec3 d) {
    vec2 uv = world_uv(d);
    int col = clamp(int(uv.x * float(u_world_grid.x)), 0, u_world_grid.x - 1);
    int row = clamp(int(uv.y * float(u_world_grid.y)), 0, u_world_grid.y - 1);
    float ce = max(cos(PI * (uv.y - 0.5)), 1e-6);
    return world_cell_prob(row, col) * float(u_world_grid.x * u_world_grid.y) / (2.0 * PI * PI * ce);
}

// A direction towards the world map by its luminance (a cell by the tables, a uniform
// point in the cell's (u, v) rectangle); pdf in solid angle.
vec3 world_sample(vec2 u, out float pdf) {
    int gw = u_world_grid.x, gh = u_world_grid.y;
    int row = world_cdf_search(u_world_table, gh, u.x);
    float r0 = row > 0 ? rt_light_select[u_world_table + row - 1] : 0.0;
    float fy = (u.x - r0) / max(rt_light_select[u_world_table + row] - r0, 1e-30);
    int c = u_world_table + gh + row * gw;
    int col = world_cdf_search(c, gw, u.y);
    float c0 = col > 0 ? rt_light_select[c + col - 1] : 0.0;
    float fx = (u.y - c0) / max(rt_light_select[c + col] - c0, 1e-30);
    // the point stays a thousandth of a cell inside its cell, so that world_pdf, which finds
    // the cell again from the direction through world_uv's arc tangents, finds the same one
    // (at the edge itself float rounding could hand it the neighbour's probability)
    vec2 f = clamp(vec2(fx, fy), vec2(1e-3), vec2(1.0 - 1e-3));
    vec2 uv = vec2((float(col) + f.x) / float(gw), (float(row) + f.y) / float(gh));
    float ce = max(cos(PI * (uv.y - 0.5)), 1e-6);
    pdf = world_cell_prob(row, col) * float(gw * gh) / (2.0 * PI * PI * ce);
    return world_uv_to_dir(uv);
}

// ---------------------------------------------------------------- next-event estimation
// One light by the light tree (at p, no normal), one point on it (sample_light, from the offset origin p so the shadow
// ray ends exactly at the sample), a shadow ray for lights that cast shadows. Returns
// f * Li * w / pdf for the surface (bs, N, Ng) seen from V; w = power heuristic against
// the BSDF's pdf when mis (delta lights: 1), else 1. Consumes one rng_next4 when there are lights.
// shade_direct_split also returns the part the glossy lobe reflects and the distance to the
// light point (SSR's miss trace: a highlight is an image of the light, it moves like a point
// that far beyond the hit).
vec3 shade_direct_split(Surface bs, vec3 p, vec3 N, vec3 Ng, vec3 V, inout Rng rng, bool mis,
                        out vec3 glossy, out float ldist) {
    glossy = vec3(0.0);
    ldist = 0.0;
    if (u_light_count <= 0 && u_world_select <= 0.0) return vec3(0.0);
    vec4 ul = rng_next4(rng);
    float sel;
    LightSample ls;
    bool shadowed = true;
    if (ul.x < u_world_select) {  // the world map
        sel = u_world_select;
        ls.dir = world_sample(ul.yz, ls.pdf);
        ls.dist = T_INF;
        ls.delta = false;
        ls.Li = world_radiance(ls.dir);
    } else {
        int li = select_light((ul.x - u_world_select) / (1.0 - u_world_select), p, vec3(0.0), sel);
        sel *= 1.0 - u_world_select;
        Light L = lights[li];
        ls = sample_light(L, p, ul.yz, ul.w);
        shadowed = L.axis_w.w > 0.5;
    }
    // a light below the surface lights it only through a transmitting lobe; the shadow ray
    // then leaves from the far side
    bool below = dot(ls.dir, Ng) <= 0.0;
    if (ls.pdf <= 0.0 || sel <= 0.0 || (below && !bs.transmits)) return vec3(0.0);
    BsdfEval fe = bsdf_eval(bs, N, V, ls.dir);
    vec3 f = fe.diffuse + fe.glossy;
    if (max3(f) <= 0.0 || max3(ls.Li) <= 0.0) return vec3(0.0);
    vec3 po = below ? rt_offset_ray(rt_offset_ray(p, -Ng), -Ng) : p;
    if (shadowed && scene_occluded(po, ls.dir, 0.0, ls.dist * (1.0 - 1e-4))) return vec3(0.0);
    float lpdf = sel * ls.pdf;
    float w = (ls.delta || !mis) ? 1.0 : power_heuristic(lpdf, bsdf_pdf(bs, N, V, ls.dir));
    glossy = fe.glossy * ls.Li * (w / lpdf);
    ldist = ls.dist;
    return f * ls.Li * (w / lpdf);
}

vec3 shade_direct_at(Surface bs, vec3 p, vec3 N, vec3 Ng, vec3 V, inout Rng rng, bool mis) {
    vec3 glossy;
    float ldist;
    return shade_direct_split(bs, p, N, Ng, V, rng, mis, glossy, ldist);
}

vec3 shade_direct(SurfaceHit s, vec3 V, inout Rng rng) {
    vec3 N, Ng, p;
    surface_frame(s, V, N, Ng, p);
    return shade_direct_at(s.bsdf, p, N, Ng, V, rng, false);
}

vec3 shade_direct_mis(SurfaceHit s, vec3 V, inout Rng rng) {
    vec3 N, Ng, p;
    surface_frame(s, V, N, Ng, p);
    return shade_direct_at(s.bsdf, p, N, Ng, V, rng, true);
}

// ---------------------------------------------------------------- BSDF rays hitting lights
// Emission a BSDF-sampled ray (o, d) from tmin collects: lights crossed before the surface
// (area, sphere), on a miss the sun disks and the world, on a hit the surface's emission
// (two-sided; MIS against its mesh light). bsdf_pdf = the pdf the direction was sampled with
// (0: a camera ray, no MIS). lights_visible = false skips light objects (Blender's default
// for camera rays: light objects are not visible to the camera).
vec3 bsdf_hit_light_mis(vec3 o, vec3 d, float tmin, bool hit, SurfaceHit s, float bsdf_pdf, bool lights_visible) {
    vec3 sum = vec3(0.0);
    float t_surf = hit ? s.t : T_INF;
    // area and sphere lights crossed: through the light BVH
#define RT_VISIT_CROSSED(i) {                                                                   \
        vec3 Le_;                                                                               \
        float lpdf_;                                                                            \
        if (light_ray_hit(lights[i], o, d, tmin, t_surf, Le_, lpdf_))                           \
            sum += Le_ * (bsdf_pdf > 0.0 ? power_heuristic(bsdf_pdf, nee_light_prob(i, o) * lpdf_) : 1.0); \
    }
    if (lights_visible) LIGHT_BVH_TRAVERSE(o, d, tmin, t_surf, RT_VISIT_CROSSED)
#undef RT_VISIT_CROSSED
    if (!hit && lights_visible && u_light_tree >= 0) {  // sun disks: the suns' list
        int suns = int(rt_light_select[u_light_tree + 4]);
        int ns = int(rt_light_select[u_light_tree + 5]);
        for (int k = 0; k < ns; ++k) {
            int i = int(rt_light_select[suns + k] + 0.5);
            vec3 Le;
            float lpdf;
            if (light_ray_hit(lights[i], o, d, tmin, t_surf, Le, lpdf))
                sum += Le * (bsdf_pdf > 0.0 ? power_heuristic(bsdf_pdf, nee_light_prob(i, o) * lpdf) : 1.0);
        }
    }
    if (!hit) {
        if (bsdf_pdf <= 0.0 && u_film_transparent != 0) return sum;  // a camera ray: no world seen
        float w = (bsdf_pdf > 0.0 && u_world_select > 0.0)
                ? power_heuristic(bsdf_pdf, u_world_select * world_pdf(d)) : 1.0;
        return sum + world_radiance(d) * w;
    }
    vec3 E = s.bsdf.emission;
    if (max3(E) > 0.0) {
        float w = 1.0;
        int li = bsdf_pdf > 0.0 ? mesh_light_of(s.instance) : -1;
        if (li >= 0) {
            Light L = lights[li];
            RtInstance inst = rt_instances[s.instance];
            vec3 p0 = (inst.object_to_world * vec4(rt_verts[3 * s.prim].xyz, 1.0)).xyz;
            vec3 p1 = (inst.object_to_world * vec4(rt_verts[3 * s.prim + 1].xyz, 1.0)).xyz;
            vec3 p2 = (inst.object_to_world * vec4(rt_verts[3 * s.prim + 2].xyz, 1.0)).xyz;
            float area = 0.5 * length(cross(p1 - p0, p2 - p0));
            vec3 Em = materials[s.material].emission.rgb;  // what EmitterSet weighted the triangle by
            float tri_power = area * (Em.r + Em.g + Em.b) / 3.0 * PI;
            float tri_prob = tri_power / max(L.color.w, 1e-20);
            float lpdf = nee_light_prob(li, o) * tri_prob * area_to_solid_angle_pdf(o, s.position, s.geo_normal, area);
            w = power_heuristic(bsdf_pdf, lpdf);
        }
        sum += E * w;
    }
    return sum;
}

// The BSDF half of MIS at a surface point p (Principled lobes): one direction from the BSDF,
// the lights, emitters and world map it meets (bsdf_hit_light_mis; a uniform world is left
// out: callers light by it with a cosine ray of their own). Returns f · Le / pdf; `glossy` the
// glossy lobe's part of it, `dir` the direction, `t` the distance to what it hit (T_INF:
// escaped; 0 with no sample). Consumes one rng_next4.
vec3 bsdf_sample_lights(Surface bs, vec3 p, vec3 N, vec3 Ng, vec3 V, inout Rng rng,
                        out vec3 glossy, out vec3 dir, out float t) {
    glossy = vec3(0.0);
    t = 0.0;
    float bpdf;
    dir = sample_principled(bs, N, V, rng_next4(rng).xyz, bpdf);
    if (!(bpdf > 0.0) || dot(dir, Ng) <= 0.0) return vec3(0.0);
    BsdfEval fe = eval_principled(bs, N, V, dir);
    vec3 f = fe.diffuse + fe.glossy;
    if (max3(f) <= 0.0) return vec3(0.0);
    SurfaceHit sb;
    bool hb = scene_trace(p, dir, 0.0, T_INF, sb);
    t = hb ? sb.t : T_INF;
    vec3 Le = max(bsdf_hit_light_mis(p, dir, 0.0, hb, sb, bpdf, true)
                  - ((hb || u_world_select > 0.0) ? vec3(0.0) : u_world_color), vec3(0.0));
    glossy = fe.glossy * Le / bpdf;
    return f * Le / bpdf;
}

#endif
