// voxelize.frag — one column of voxels under a (conservatively enlarged) projected
// triangle: every voxel of the column within the triangle plane's depth range over the
// pixel is tested exactly against the triangle (Akenine-Möller's triangle/box separating
// axis test, box dilated by u_thickness voxels) and, if it overlaps, the fragment adds the
// triangle's diffuse albedo, normal and its plane's point nearest the voxel centre to the
// voxel's record of the triangle's orientation bucket (SSBO, atomics; vxgi/common.glsl):
// the average over the overlapping triangles of each bucket is taken by the injection pass. Conservative: every voxel a triangle touches is marked. Emission is
// not stored: emitters are mesh lights (see inject.comp).
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/textures.glsl"
#include "lib/sampling.glsl"
#include "lib/brdf.glsl"
#include "lib/albedo.glsl"
#include "vxgi/common.glsl"

layout(std430, binding = VX_BINDING_RECORDS) buffer VoxelRecords { uint vx_rec[]; };
layout(std430, binding = VX_BINDING_LIST) buffer VoxelList { uint vx_list[]; };

in vec2 g_uv;
in vec4 g_color;
in vec3 g_normal;
flat in int g_material;
flat in int g_axis;
flat in vec3 g_v0;
flat in vec3 g_v1;
flat in vec3 g_v2;
flat in vec4 g_box;

uniform sampler2DArray u_textures;
uniform int u_material_count;
uniform int u_cascade;
uniform float u_thickness;

void atomic_add_f(uint i, float v) {
    uint old = vx_rec[i];
    uint assumed;
    do {
        assumed = old;
        old = atomicCompSwap(vx_rec[i], assumed, floatBitsToUint(uintBitsToFloat(assumed) + v));
    } while (old != assumed);
}

bool axis_test(vec3 ax, vec3 v0, vec3 v1, vec3 v2, vec3 h) {
    float p0 = dot(ax, v0), p1 = dot(ax, v1), p2 = dot(ax, v2);
    float r = dot(h, abs(ax));
    return !(min(p0, min(p1, p2)) > r || max(p0, max(p1, p2)) < -r);
}

// Akenine-Möller 2001: does the triangle (a, b, c) overlap the box (centre, half size h)?
bool tri_box(vec3 centre, vec3 h, vec3 a, vec3 b, vec3 c) {
    vec3 v0 = a - centre, v1 = b - centre, v2 = c - centre;
    vec3 mn = min(v0, min(v1, v2)), mx = max(v0, max(v1, v2));
    if (any(greaterThan(mn, h)) || any(lessThan(mx, -h))) return false;
    vec3 e0 = v1 - v0, e1 = v2 - v1, e2 = v0 - v2;
    vec3 nrm = cross(e0, e1);
    if (abs(dot(nrm, v0)) > dot(h, abs(nrm))) return false;
    vec3 E[3] = vec3[3](e0, e1, e2);
    for (int i = 0; i < 3; ++i) {
        if (!axis_test(vec3(0.0, -E[i].z, E[i].y), v0, v1, v2, h)) return false;
        if (!axis_test(vec3(E[i].z, 0.0, -E[i].x), v0, v1, v2, h)) return false;
        if (!axis_test(vec3(-E[i].y, E[i].x, 0.0), v0, v1, v2, h)) return false;
    }
    return true;
}

// (u, v, w) of the projection back to (x, y, z)
vec3 unproj(vec2 uv, float w, int axis) {
    return axis == 0 ? vec3(w, uv.x, uv.y) : (axis == 1 ? vec3(uv.y, w, uv.x) : vec3(uv.x, uv.y, w));
}
float depth_of(vec3 g, int axis) { return axis == 0 ? g.x : (axis == 1 ? g.y : g.z); }

void main() {
    vec2 pix = floor(gl_FragCoord.xy);
    if (pix.x + 1.0 < g_box.x || pix.y + 1.0 < g_box.y || pix.x > g_box.z || pix.y > g_box.w) discard;
    int N = u_vx_n;
    float t = u_thickness;
    vec3 nrm = cross(g_v1 - g_v0, g_v2 - g_v0);
    vec3 un = normalize(nrm);
    // plane depth over the dilated pixel footprint
    float wn = depth_of(nrm, g_axis);
    float d = dot(nrm, g_v0);
    float wmin = 1e30, wmax = -1e30;
    for (int k = 0; k < 4; ++k) {
        vec2 c = pix + vec2(k & 1, k >> 1) * (1.0 + 2.0 * t) - t;
        vec3 q = unproj(c, 0.0, g_axis);
        float w = (d - dot(nrm, q)) / wn;  // q has depth 0, so dot(nrm, q) skips the depth axis
        wmin = min(wmin, w);
        wmax = max(wmax, w);
    }
    float tlo = min(depth_of(g_v0, g_axis), min(depth_of(g_v1, g_axis), depth_of(g_v2, g_axis)));
    float thi = max(depth_of(g_v0, g_axis), max(depth_of(g_v1, g_axis), depth_of(g_v2, g_axis)));
    wmin = max(wmin, tlo) - t;
    wmax = min(wmax, thi) + t;
    int k0 = max(int(floor(wmin)), 0), k1 = min(int(floor(wmax)), N - 1);
    if (k1 < k0) discard;
    int mid = (g_material >= 0 && g_material < u_material_count) ? g_material : u_material_count;
    Material m = materials[mid];
    g_vertex_color = g_color;
    MaterialSample ms = sample_material(u_textures, m, g_uv);
    Surface s = make_surface(material_at(m, ms), ms.base_color);
    vec3 rho = diffuse_albedo(s, 0.5);  // the Lambertian layer's albedo at 60 degrees (see the page)
    vec3 n = normalize(g_normal);
    if (dot(n, n) < 0.5) n = un;
    // the mesh's own orientation (not flipped to a canonical side): the injection lights both
    // sides of each record. One record per orientation bucket (vx_bucket: dominant axis and
    // sign of the normal): a voxel where a roof and a wall meet keeps two records, each with
    // its own plane, lit and shadowed on its own (one averaged normal and point lay off both
    // planes and let the sun-lit outside of a roof light the room: sunlit_room 2.2x Cycles)
    vec3 uno = dot(un, n) < 0.0 ? -un : un;  // the plane's normal, oriented as the mesh
    int b = vx_bucket(n);
    vec3 h = vec3(0.5 + t);
    for (int k = k0; k <= min(k1, k0 + 15); ++k) {
        vec3 g = unproj(pix, float(k), g_axis);  // voxel corner
        if (any(lessThan(g, vec3(0.0))) || any(greaterThanEqual(g, vec3(float(N))))) continue;
        vec3 centre = g + 0.5;
        if (!tri_box(centre, h, g_v0, g_v1, g_v2)) continue;
        ivec3 v = ivec3(g);
        uint flat_index = uint(((u_cascade * N + v.z) * N + v.y) * N + v.x);
        uint vbase = flat_index * uint(VX_REC);
        uint base = vbase + uint(vx_bucket_offset(b));
        float dist = dot(centre - g_v0, uno);  // the voxel centre's height over the plane
        atomic_add_f(base + 0u, rho.r);
        atomic_add_f(base + 1u, rho.g);
        atomic_add_f(base + 2u, rho.b);
        atomicAdd(vx_rec[base + 3u], 1u);
        atomic_add_f(base + 4u, n.x);
        atomic_add_f(base + 5u, n.y);
        atomic_add_f(base + 6u, n.z);
        atomic_add_f(base + 7u, dist);
        if (atomicOr(vx_rec[vbase], 1u << uint(b)) == 0u) vx_list[1u + atomicAdd(vx_list[0], 1u)] = flat_index;
    }
}
