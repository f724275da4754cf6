// lib/bvh.glsl — two-level BVH traversal shared by every ray-tracing and probe technique.
//
// References:
//   S. Woop, C. Benthin, I. Wald, "Watertight Ray/Triangle Intersection", JCGT 2(1), 2013.
//   C. Wächter, N. Binder, "A Fast and Robust Method for Avoiding Self-Intersection",
//     Ray Tracing Gems, ch. 6, 2019.
//   T. Ize, "Robust BVH Ray Traversal", JCGT 2(2), 2013 (the 1 + 2*gamma(3) slab bound).
//
// Data (built by addon/render/bvh.py, uploaded by addon/render/rt_scene.py): a top-level
// BVH over instances (one instance per leaf) and the bottom-level BVHs of all meshes in one
// node array. A node is two vec4: (min.xyz, left_or_first), (max.xyz, count) with the ints
// stored as float bits; count > 0 = leaf. Rays are traced in world space; at a TLAS leaf the
// ray is moved into the instance's object space with an *unnormalised* direction, so t is
// the same parameter in both spaces and hits of all instances compare directly.
//
// API:
//   RtHit h = rt_miss();  bool hit = rt_trace_closest(o, d, tmin, tmax, h);
//   bool blocked = rt_trace_any(o, d, tmin, tmax);
//   RtSurface s = rt_surface(h);          // world position, normals, uv, material
//   vec3 o2 = rt_offset_ray(s.position, dot(s.geo_normal, d2) > 0 ? s.geo_normal : -s.geo_normal);
// Binding points are #defines a shader may override before including this file.

#ifndef RT_LIB_BVH
#define RT_LIB_BVH

#ifndef RT_BINDING_BLAS_NODES
#define RT_BINDING_BLAS_NODES 8
#endif
#ifndef RT_BINDING_TLAS_NODES
#define RT_BINDING_TLAS_NODES 9
#endif
#ifndef RT_BINDING_VERTS
#define RT_BINDING_VERTS 10
#endif
#ifndef RT_BINDING_NORMALS
#define RT_BINDING_NORMALS 11
#endif
#ifndef RT_BINDING_TRI_INFO
#define RT_BINDING_TRI_INFO 12
#endif
#ifndef RT_BINDING_INSTANCES
#define RT_BINDING_INSTANCES 13
#endif
#ifndef RT_BINDING_MATERIAL_MAP
#define RT_BINDING_MATERIAL_MAP 14
#endif
#ifndef RT_STACK_SIZE
#define RT_STACK_SIZE 64
#endif

struct RtNode {
    vec4 lo;  // min.xyz, w = intBitsToFloat(left child or first primitive)
    vec4 hi;  // max.xyz, w = intBitsToFloat(primitive count; 0 = interior)
};

struct RtInstance {
    mat4 world_to_object;
    mat4 object_to_world;
    ivec4 info;  // x: BLAS root node, y: mesh, z: material map offset (-1: none), w: first triangle
};

layout(std430, binding = RT_BINDING_BLAS_NODES) readonly buffer RtBlasNodes { RtNode rt_blas[]; };
layout(std430, binding = RT_BINDING_TLAS_NODES) readonly buffer RtTlasNodes { RtNode rt_tlas[]; };
layout(std430, binding = RT_BINDING_VERTS) readonly buffer RtVerts { vec4 rt_verts[]; };      // xyz, w = uv.y
// two vec4 per corner: (normal xyz, uv.x), (tangent xyz, bitangent sign; zero without one)
layout(std430, binding = RT_BINDING_NORMALS) readonly buffer RtNormals { vec4 rt_normals[]; };
#ifndef RT_BINDING_COLORS
#define RT_BINDING_COLORS 16
#endif
// corner colour attribute, 3 per triangle in BVH order (one zero entry when no mesh has one)
layout(std430, binding = RT_BINDING_COLORS) readonly buffer RtColors { vec4 rt_colors[]; };
layout(std430, binding = RT_BINDING_TRI_INFO) readonly buffer RtTriInfo { ivec2 rt_tri_info[]; }; // orig tri, material
layout(std430, binding = RT_BINDING_INSTANCES) readonly buffer RtInstances { RtInstance rt_instances[]; };
layout(std430, binding = RT_BINDING_MATERIAL_MAP) readonly buffer RtMaterialMap { int rt_material_map[]; };

struct RtHit {
    float t;
    int instance;  // index into SceneData.instances, -1 = miss
    int prim;      // triangle in BVH order (global); rt_surface() maps it back
    vec2 bary;     // weights of corners 1 and 2
};

struct RtSurface {
    vec3 position;    // world space
    vec3 geo_normal;  // world space, unit, from the winding (not flipped towards the ray)
    vec3 normal;      // world space, unit, interpolated corner normal
    vec2 uv;
    vec4 tangent;     // world-space interpolated tangent xyz (not normalised), w = bitangent sign
    vec3 dpdu;        // world-space dP/du, dP/dv of the triangle (zero without a UV map)
    vec3 dpdv;
    vec4 color;       // the interpolated colour attribute (zero when the mesh has none)
    int material;     // index into SceneData.materials, -1 = default
    int triangle;     // original triangle index within its mesh
    int mesh;
};

#ifdef RT_ALPHA_TEST
// Defined by the includer (lib/scene_rt.glsl): true when the hit of the ray with object-space
// origin/inverse direction (o, inv_d) on triangle prim of instance at barycentrics bary
// passes through the surface (alpha transparency).
bool rt_alpha_skip(int instance, int prim, vec2 bary, vec3 o, vec3 inv_d);
#endif

RtHit rt_miss() { return RtHit(3.0e38, -1, -1, vec2(0.0)); }

// ---------------------------------------------------------------- ray offset (Wächter & Binder)
vec3 rt_offset_ray(vec3 p, vec3 n) {
    const float origin = 1.0 / 32.0;
    const float float_scale = 1.0 / 65536.0;
    const float int_scale = 256.0;
    ivec3 of_i = ivec3(int_scale * n);
    vec3 p_i = vec3(
        intBitsToFloat(floatBitsToInt(p.x) + ((p.x < 0.0) ? -of_i.x : of_i.x)),
        intBitsToFloat(floatBitsToInt(p.y) + ((p.y < 0.0) ? -of_i.y : of_i.y)),
        intBitsToFloat(floatBitsToInt(p.z) + ((p.z < 0.0) ? -of_i.z : of_i.z)));
    return vec3(abs(p.x) < origin ? p.x + float_scale * n.x : p_i.x,
                abs(p.y) < origin ? p.y + float_scale * n.y : p_i.y,
                abs(p.z) < origin ? p.z + float_scale * n.z : p_i.z);
}

// ---------------------------------------------------------------- per-ray precomputation
struct RtRay {
    vec3 o;
    vec3 inv_d;
    mat3 shear;  // Woop's permutation + shear as a matrix of 0, 1, -Sx, -Sy, Sz (exact)
};

vec3 rt_safe_dir(vec3 d) {
    const float eps = 1e-30;
    return vec3(abs(d.x) < eps ? (d.x < 0.0 ? -eps : eps) : d.x,
                abs(d.y) < eps ? (d.y < 0.0 ? -eps : eps) : d.y,
                abs(d.z) < eps ? (d.z < 0.0 ? -eps : eps) : d.z);
}

RtRay rt_make_ray(vec3 o, vec3 d) {
    RtRay r;
    r.o = o;
    r.inv_d = 1.0 / rt_safe_dir(d);
    vec3 ad = abs(d);
    int kz = (ad.x > ad.y) ? ((ad.x > ad.z) ? 0 : 2) : ((ad.y > ad.z) ? 1 : 2);
    int kx = (kz + 1) % 3;
    int ky = (kx + 1) % 3;
    if (d[kz] < 0.0) { int tmp = kx; kx = ky; ky = tmp; }  // keep the winding
    float sz = 1.0 / d[kz];
    float sx = d[kx] * sz;
    float sy = d[ky] * sz;
    // rows: x' = p[kx] - sx p[kz], y' = p[ky] - sy p[kz], z' = sz p[kz] (GLSL mat3 is column-major)
    mat3 m = mat3(0.0);
    m[kx][0] = 1.0; m[kz][0] = -sx;
    m[ky][1] = 1.0; m[kz][1] = -sy;
    m[kz][2] = sz;
    r.shear = m;
    return r;
}

// slab test; returns entry distance or 3e38 when missed. tmax scaled by 1 + 2 gamma(3) (Ize).
float rt_box(RtRay r, vec3 lo, vec3 hi, float tmin, float tmax) {
    vec3 t0 = (lo - r.o) * r.inv_d;
    vec3 t1 = (hi - r.o) * r.inv_d;
    vec3 tn = min(t0, t1);
    vec3 tf = max(t0, t1);
    float enter = max(max(tn.x, tn.y), max(tn.z, tmin));
    float leave = min(min(tf.x, tf.y), min(tf.z, tmax)) * 1.00000036;
    return enter <= leave ? enter : 3.0e38;
}

// Woop et al. watertight test. On a hit closer than tmax, returns true with t and barycentrics.
bool rt_triangle(RtRay r, vec3 p0, vec3 p1, vec3 p2, float tmin, float tmax, out float t, out vec2 bary) {
    vec3 a = r.shear * (p0 - r.o);
    vec3 b = r.shear * (p1 - r.o);
    vec3 c = r.shear * (p2 - r.o);
    float u = c.x * b.y - c.y * b.x;
    float v = a.x * c.y - a.y * c.x;
    float w = b.x * a.y - b.y * a.x;
    t = 0.0;
    bary = vec2(0.0);
    if ((u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0)) return false;
    float det = u + v + w;
    if (det == 0.0) return false;
    float tt = u * a.z + v * b.z + w * c.z;
    if (det < 0.0) { det = -det; tt = -tt; u = -u; v = -v; w = -w; }
    if (tt <= tmin * det || tt >= tmax * det) return false;
    float inv = 1.0 / det;
    t = tt * inv;
    bary = vec2(v, w) * inv;
    return true;
}

// ---------------------------------------------------------------- bottom level
// Traverse one BLAS with an object-space ray. Updates hit (closest) or returns at the first
// hit (any_hit). Returns true when something was hit.
bool rt_trace_blas(RtRay r, int root, int instance, float tmin, bool any_hit, inout RtHit hit) {
    int stack[RT_STACK_SIZE];
    int sp = 0;
    int node = root;
    bool found = false;
    RtNode nd = rt_blas[node];
    if (rt_box(r, nd.lo.xyz, nd.hi.xyz, tmin, hit.t) == 3.0e38) return false;
    while (true) {
        int count = floatBitsToInt(nd.hi.w);
        int first = floatBitsToInt(nd.lo.w);
        if (count > 0) {
            for (int i = first; i < first + count; ++i) {
                float t;
                vec2 bc;
                if (rt_triangle(r, rt_verts[3 * i].xyz, rt_verts[3 * i + 1].xyz, rt_verts[3 * i + 2].xyz,
                                tmin, hit.t, t, bc)) {
#ifdef RT_ALPHA_TEST
                    if (rt_alpha_skip(instance, i, bc, r.o, r.inv_d)) continue;
#endif
                    hit.t = t;
                    hit.instance = instance;
                    hit.prim = i;
                    hit.bary = bc;
                    found = true;
                    if (any_hit) return true;
                }
            }
        } else {
            RtNode c0 = rt_blas[first];
            RtNode c1 = rt_blas[first + 1];
            float d0 = rt_box(r, c0.lo.xyz, c0.hi.xyz, tmin, hit.t);
            float d1 = rt_box(r, c1.lo.xyz, c1.hi.xyz, tmin, hit.t);
            if (d0 != 3.0e38 || d1 != 3.0e38) {
                if (d0 == 3.0e38) { nd = c1; continue; }
                if (d1 == 3.0e38) { nd = c0; continue; }
                // both: go to the nearer, push the farther
                if (d0 <= d1) { stack[sp++] = first + 1; nd = c0; }
                else { stack[sp++] = first; nd = c1; }
                if (sp >= RT_STACK_SIZE) sp = RT_STACK_SIZE - 1;  // never with MAX_DEPTH < 64
                continue;
            }
        }
        // pop (skipping nodes now farther than the closest hit)
        bool popped = false;
        while (sp > 0) {
            RtNode cand = rt_blas[stack[--sp]];
            if (rt_box(r, cand.lo.xyz, cand.hi.xyz, tmin, hit.t) != 3.0e38) { nd = cand; popped = true; break; }
        }
        if (!popped) break;
    }
    return found;
}

// ---------------------------------------------------------------- top level
bool rt_trace(vec3 o, vec3 d, float tmin, float tmax, bool any_hit, inout RtHit hit) {
    hit.t = min(hit.t, tmax);
    RtRay wr = rt_make_ray(o, d);
    int stack[RT_STACK_SIZE];
    int sp = 0;
    bool found = false;
    RtNode nd = rt_tlas[0];
    if (rt_box(wr, nd.lo.xyz, nd.hi.xyz, tmin, hit.t) == 3.0e38) return false;
    while (true) {
        int count = floatBitsToInt(nd.hi.w);
        int first = floatBitsToInt(nd.lo.w);
        if (count > 0) {
            for (int i = first; i < first + count; ++i) {
                RtInstance inst = rt_instances[i];
                vec3 oo = (inst.world_to_object * vec4(o, 1.0)).xyz;
                vec3 od = mat3(inst.world_to_object) * d;
                if (rt_trace_blas(rt_make_ray(oo, od), inst.info.x, i, tmin, any_hit, hit)) {
                    found = true;
                    if (any_hit) return true;
                }
            }
        } else {
            RtNode c0 = rt_tlas[first];
            RtNode c1 = rt_tlas[first + 1];
            float d0 = rt_box(wr, c0.lo.xyz, c0.hi.xyz, tmin, hit.t);
            float d1 = rt_box(wr, c1.lo.xyz, c1.hi.xyz, tmin, hit.t);
            if (d0 != 3.0e38 || d1 != 3.0e38) {
                if (d0 == 3.0e38) { nd = c1; continue; }
                if (d1 == 3.0e38) { nd = c0; continue; }
                if (d0 <= d1) { stack[sp++] = first + 1; nd = c0; }
                else { stack[sp++] = first; nd = c1; }
                if (sp >= RT_STACK_SIZE) sp = RT_STACK_SIZE - 1;
                continue;
            }
        }
        bool popped = false;
        while (sp > 0) {
            RtNode cand = rt_tlas[stack[--sp]];
            if (rt_box(wr, cand.lo.xyz, cand.hi.xyz, tmin, hit.t) != 3.0e38) { nd = cand; popped = true; break; }
        }
        if (!popped) break;
    }
    return found;
}

bool rt_trace_closest(vec3 o, vec3 d, float tmin, float tmax, inout RtHit hit) {
    return rt_trace(o, d, tmin, tmax, false, hit);
}

// Shadow query: is anything between tmin and tmax?
bool rt_trace_any(vec3 o, vec3 d, float tmin, float tmax) {
    RtHit h = rt_miss();
    return rt_trace(o, d, tmin, tmax, true, h);
}

// ---------------------------------------------------------------- hit attributes
RtSurface rt_surface(RtHit h) {
    RtSurface s;
    RtInstance inst = rt_instances[h.instance];
    int i = h.prim;
    vec4 v0 = rt_verts[3 * i], v1 = rt_verts[3 * i + 1], v2 = rt_verts[3 * i + 2];
    vec4 n0 = rt_normals[6 * i], n1 = rt_normals[6 * i + 2], n2 = rt_normals[6 * i + 4];
    vec4 t0 = rt_normals[6 * i + 1], t1 = rt_normals[6 * i + 3], t2 = rt_normals[6 * i + 5];
    float b0 = 1.0 - h.bary.x - h.bary.y;
    vec3 p_obj = b0 * v0.xyz + h.bary.x * v1.xyz + h.bary.y * v2.xyz;
    s.position = (inst.object_to_world * vec4(p_obj, 1.0)).xyz;
    mat3 n_to_world = transpose(mat3(inst.world_to_object));
    vec3 ng = cross(v1.xyz - v0.xyz, v2.xyz - v0.xyz);
    s.geo_normal = normalize(n_to_world * ng);
    vec3 ns = n_to_world * (b0 * n0.xyz + h.bary.x * n1.xyz + h.bary.y * n2.xyz);
    float len = length(ns);
    s.normal = len > 0.0 ? ns / len : s.geo_normal;
    s.uv = b0 * vec2(n0.w, v0.w) + h.bary.x * vec2(n1.w, v1.w) + h.bary.y * vec2(n2.w, v2.w);
    vec4 tg = b0 * t0 + h.bary.x * t1 + h.bary.y * t2;
    s.tangent = vec4(mat3(inst.object_to_world) * tg.xyz, tg.w);
    {
        vec2 t0 = vec2(n0.w, v0.w), t1 = vec2(n1.w, v1.w), t2 = vec2(n2.w, v2.w);
        vec3 e1 = v1.xyz - v0.xyz, e2 = v2.xyz - v0.xyz;
        vec2 d1 = t1 - t0, d2 = t2 - t0;
        float det = d1.x * d2.y - d1.y * d2.x;
        float r = abs(det) < 1e-20 ? 0.0 : 1.0 / det;
        s.dpdu = mat3(inst.object_to_world) * ((e1 * d2.y - e2 * d1.y) * r);
        s.dpdv = mat3(inst.object_to_world) * ((e2 * d1.x - e1 * d2.x) * r);
    }
    s.color = vec4(0.0);
    if (rt_colors.length() > 3 * i + 2)
        s.color = b0 * rt_colors[3 * i] + h.bary.x * rt_colors[3 * i + 1] + h.bary.y * rt_colors[3 * i + 2];
    ivec2 info = rt_tri_info[i];
    s.triangle = info.x;
    s.mesh = inst.info.y;
    int mat = info.y;
    if (inst.info.z >= 0 && mat >= 0) mat = rt_material_map[inst.info.z + mat];
    s.material = mat;
    return s;
}

#endif  // RT_LIB_BVH
