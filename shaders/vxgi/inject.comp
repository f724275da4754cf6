// inject.comp — VXGI light injection, one invocation per occupied voxel (the list the
// voxelisation appended; level 0 is cleared before).
// Reads the voxel's records (voxelize.frag: per orientation bucket, albedo, normal and plane
// distance averaged over the bucket's triangles overlapping the voxel; each bucket is lit on
// its own; they stay until the scene is voxelised again) and writes level 0
// of the six directional radiance volumes (vxgi/common.glsl): the outgoing radiance of the
// surface side facing each direction, L = rho/pi * E, with E in Cycles' units:
//  * direct light of every light (lib/lights.glsl light_irradiance: point/spot I cos/d^2 with
//    the spot cone, sun E cos, area and mesh lights by exact polygon irradiance) on each side
//    of the voxel's surface, shadowed by the shadow maps: the shadow atlas (lib/shadows.glsl: cube maps
//    of point/spot/area/mesh lights) and, for suns, whose atlas cascades only cover the
//    camera's frustum, the light's RSM view over the whole scene (passes/rsm.py);
//  * optional multi-bounce: six diffuse cones per side through last frame's volume
//    (history; its own cascade origins): last frame's indirect irradiance, plus the world's
//    radiance for the part of each cone that escapes (sky light). After a history reset the
//    pass runs this shader several times within the frame (passes/vxgi.py, reset_bounces),
//    each gathering from the volume the previous run wrote.
// Emission is not voxelised: every emissive instance is a mesh light (gpu_scene.EmitterSet)
// lighting the voxels like the other lights, and DIRECT draws emitters seen directly.
// Many lights (u_cull = 1; passes/vxgi.py, light_cull): each voxel loops exactly over the
// lights whose range of influence (passes/light_cull.light_ranges, as DIRECT's tiles) holds
// its centre, suns always; the others are estimated by u_cull_samples lights chosen by power
// among the lights that have a range, each counted only when it is not listed (unbiased).
// Direct light once per frame (u_direct_mode): a reset frame's first run stores each
// bucket's direct irradiance (Ep, Em) at the voxel's LIST position; the later runs load it
// and only gather again.
#define USE_SCENE_BUFFERS
#define VX_SAMPLING
#include "lib/common.glsl"
#include "lib/rng.glsl"
#include "lib/sampling.glsl"
#include "lib/brdf.glsl"
#include "lib/lights.glsl"
#include "lib/shadows.glsl"
#include "lib/world.glsl"
#include "raster3d/rsm_common.glsl"
#include "vxgi/common.glsl"

layout(local_size_x = 256) in;
layout(std430, binding = VX_BINDING_RECORDS) buffer VoxelRecords { uint vx_rec[]; };
layout(std430, binding = VX_BINDING_LIST) readonly buffer VoxelList { uint vx_list[]; };
layout(binding = 0, rgba16f) uniform writeonly image3D o_radiance;
#define VX_BINDING_CULL 6
#define VX_BINDING_DIRECT 7
#define VX_CULL_CHUNK 32  // listed lights gathered per shading loop (direct_irradiance)
// light culling table: [4i, 4i+4) light i's range (centre, radius; < 0: everywhere);
// [4n + i] the cdf of choosing lights 0..i among those with a range (by power); [5n + i] its probability
layout(std430, binding = VX_BINDING_CULL) readonly buffer VoxelLightCull { float vx_cull[]; };
// direct irradiance of a reset frame: 6 floats (Ep.rgb, Em.rgb) per bucket, 6 buckets per list entry
layout(std430, binding = VX_BINDING_DIRECT) buffer VoxelDirect { float vx_direct[]; };

uniform vec4 u_cur_origin[VX_MAX_CASCADES];  // this frame's grid (u_vx_origin: last frame's)
uniform int u_rsm_light[RSM_MAX_VIEWS];      // light index of each RSM view
uniform int u_bounce;                        // multi-bounce: gather last frame's volume
uniform int u_gather;                        // gather at all (multi-bounce or a lit world)
uniform float u_shadow_offset;               // voxels: shadow lookups start this far off the surface
uniform float u_normal_offset;               // voxels: cones start this far off the surface
uniform float u_step;
uniform float u_max_distance;
uniform int u_mesh_exact_max;
uniform uint u_sample;
uniform float u_edge_opacity;       // smallest level-0 opacity of an occupied voxel towards any direction
uniform float u_audit;  // > 0: energy audit, both sides of every surface show this radiance
uniform int u_cull;          // 1: lights out of a voxel's range by u_cull_samples power samples (else every light)
uniform int u_cull_samples;
uniform int u_direct_mode;   // 0: compute the direct light; 1: compute and store it; 2: load the stored one
uniform uint u_direct_capacity;  // list entries vx_direct holds (entries past it compute, whatever the mode)
#define VX_SIDE_CUT 0.5              // voxels: a record whose centre lies further off its plane shows one side

// Visibility of the light from the RSM view v (sun) for the surface side at ps (already
// moved off the surface along nf, the side's normal): 3x3 taps of the view's stored world
// positions q. A tap occludes when q lies on the light's side of the plane through ps
// (nf . (q - ps) > 0) and in front of ps along the light (depth within `bias`). The plane
// test is exact for a planar receiver whatever its slope (q on the receiver's own plane lies
// `offset` below it), so no depth bias lets the surface near an occluder be lit; a depth
// bias of a voxel (the former test) lit every point less than a voxel behind a roof or a
// thin wall (the inside of the sun-lit room's walls under the roof, the dark side of walls).
float rsm_visibility(int v, vec3 ps, vec3 nf, float bias) {
    vec4 c = u_rsm_vp[v] * vec4(ps, 1.0);
    if (c.w <= 1e-6) return 1.0;
    vec3 ndc = c.xyz / c.w;
    if (any(greaterThan(abs(ndc.xy), vec2(1.0)))) return 1.0;
    vec4 rect = u_rsm_rect[v];
    bool ortho = u_rsm_origin[v].w > 0.5;
    vec3 org = u_rsm_origin[v].xyz, fwd = u_rsm_fwd[v].xyz;
    float mp = ortho ? dot(ps - org, fwd) : length(ps - org);
    ivec2 base = ivec2(rect.xy), size = ivec2(rect.zw);
    ivec2 t0 = ivec2((ndc.xy * 0.5 + 0.5) * rect.zw);
    float lit = 0.0;
    for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
            ivec2 t = base + clamp(t0 + ivec2(dx, dy), ivec2(0), size - 1);
            vec4 q = texelFetch(u_rsm_pos, t, 0);
            if (q.w < 0.5) { lit += 1.0; continue; }
            float mq = ortho ? dot(q.xyz - org, fwd) : length(q.xyz - org);
            bool occ = mq < mp + bias && dot(nf, q.xyz - ps) > 0.0;
            lit += occ ? 0.0 : 1.0;
        }
    }
    return lit / 9.0;
}

int rsm_view_of(int li) {
    for (int v = 0; v < u_rsm_count; ++v)
        if (u_rsm_light[v] == li) return v;
    return -1;
}

// Visibility of light li from p on the side whose normal is nf.
float visibility(int li, Light L, vec3 p, vec3 nf, float vs) {
    vec3 ps = p + nf * (u_shadow_offset * vs);
    if (int(L.pos_type.w + 0.5) == LIGHT_SUN && L.axis_w.w > 0.5) {
        int v = rsm_view_of(li);
        if (v >= 0) return rsm_visibility(v, ps, nf, 2.0 * u_rsm_fwd[v].w);
    }
    return light_visibility(L, ps, nf, nf);
}

// Irradiance of light li on the two sides (+n: Ep, -n: Em) of the surface at p: the light's
// unshadowed irradiance on each side (lib/lights.glsl; both sides see the same triangles of a
// sampled mesh light), shadowed for that side.
void light_irradiance_sides(int li, vec3 p, vec3 n, float vs, inout Rng rng, inout vec3 Ep, inout vec3 Em) {
    Light L = lights[li];
    Rng rng_m = rng;
    vec3 sp = light_irradiance(L, p, n, u_mesh_exact_max, rng);
    vec3 sm = light_irradiance(L, p, -n, u_mesh_exact_max, rng_m);
    if (max3(sp) > 0.0) Ep += sp * visibility(li, L, p, n, vs);
    if (max3(sm) > 0.0) Em += sm * visibility(li, L, p, -n, vs);
}

// Does voxel centre c lie in light li's range (or does li reach everywhere)?
bool vx_listed(int li, vec3 c) {
    vec4 r = vec4(vx_cull[4 * li], vx_cull[4 * li + 1], vx_cull[4 * li + 2], vx_cull[4 * li + 3]);
    vec3 d = c - r.xyz;
    return r.w < 0.0 || dot(d, d) <= r.w * r.w;
}

// A light with a range, by power: the table's cdf, searched as every power table is
// (LIGHT_CDF_SEARCH, lib/lights.glsl).
#define VX_CULL_CDF(k) vx_cull[4 * u_light_count + (k)]
int vx_select_light(float u, out float prob) {
    int i;
    LIGHT_CDF_SEARCH(VX_CULL_CDF, u_light_count, u, i)
    prob = vx_cull[5 * u_light_count + i];
    return i;
}
#undef VX_CULL_CDF

// Direct irradiance on both sides of the bucket's surface (p, n) in the voxel centred at c:
// every light (u_cull = 0), or the lights listed for c plus u_cull_samples power samples of
// the others, each weighted 1 / (prob x samples) and counted only when not listed. Lights are
// gathered VX_CULL_CHUNK at a time, then shaded through one call site: a branch per light
// would shade a light whenever any voxel of the SIMD group (list order: scattered voxels)
// lists it, and a second call site doubled the shader's size (llvmpipe inlines it).
void direct_irradiance(vec3 c, vec3 p, vec3 n, float vs, inout Rng rng, inout vec3 Ep, inout vec3 Em) {
    int S = u_cull == 1 ? u_cull_samples : 0;
    int li = 0, s = 0;
    while (li < u_light_count || s < S) {
        int idx[VX_CULL_CHUNK];
        float w[VX_CULL_CHUNK];
        int m = 0;
        for (; li < u_light_count && m < VX_CULL_CHUNK; ++li)
            if (u_cull == 0 || vx_listed(li, c)) { idx[m] = li; w[m] = 1.0; ++m; }
        for (; li >= u_light_count && s < S && m < VX_CULL_CHUNK; ++s) {
            float sel;
            int j = vx_select_light(rng_next(rng), sel);
            if (sel > 0.0 && !vx_listed(j, c)) { idx[m] = j; w[m] = 1.0 / (sel * float(S)); ++m; }
        }
        for (int k = 0; k < m; ++k) {
            vec3 sp = vec3(0.0), sm = vec3(0.0);  // (x 1.0 for a listed light: the sum is unchanged bit for bit)
            light_irradiance_sides(idx[k], p, n, vs, rng, sp, sm);
            Ep += sp * w[k];
            Em += sm * w[k];
        }
    }
}

const vec3 FACE_DIR[6] = vec3[6](vec3(1, 0, 0), vec3(-1, 0, 0), vec3(0, 1, 0), vec3(0, -1, 0),
                                 vec3(0, 0, 1), vec3(0, 0, -1));

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= vx_list[0]) return;  // only the occupied voxels (level 0 was cleared)
    uint flat_index = vx_list[1u + i];
    int N = u_vx_n;
    int C = u_vx_cascades;
    ivec3 gid = ivec3(int(flat_index % uint(N)), int((flat_index / uint(N)) % uint(N)), int(flat_index / uint(N * N)));
    int c = gid.z / N;
    ivec3 v = ivec3(gid.xy, gid.z - c * N);
    uint vbase = flat_index * uint(VX_REC);
    uint mask = vx_rec[vbase];
    if (mask == 0u) return;
    vec4 o = u_cur_origin[c];
    float vs = o.w;
    vec3 centre = o.xyz + (vec3(v) + 0.5) * vs;
    Rng rng = rng_init(uvec2(gid.x + gid.z * N, gid.y), u_sample, 7u);
    float off = u_normal_offset * vs;
    // per direction D: the buckets facing D (their front side, n.D > 0) composited over those
    // facing away (their back side), each over its projected coverage |n.D|
    vec3 front[6], back[6];
    float af[6], ab[6];
    for (int f = 0; f < 6; ++f) { front[f] = back[f] = vec3(0.0); af[f] = ab[f] = 0.0; }
    // a loop over the set bits (not 0..5: Mesa unrolled that and inlined the lights and the
    // twelve cones six times; the shader took ~25 s to compile on llvmpipe)
    while (mask != 0u) {
        int b = findLSB(mask);
        mask &= mask - 1u;
        uint base = vbase + uint(vx_bucket_offset(b));
        uint count = vx_rec[base + 3u];
        float inv = 1.0 / float(max(count, 1u));
        vec3 rho = vec3(uintBitsToFloat(vx_rec[base]), uintBitsToFloat(vx_rec[base + 1u]),
                        uintBitsToFloat(vx_rec[base + 2u])) * inv;
        vec3 nsum = vec3(uintBitsToFloat(vx_rec[base + 4u]), uintBitsToFloat(vx_rec[base + 5u]),
                         uintBitsToFloat(vx_rec[base + 6u]));
        float dist = uintBitsToFloat(vx_rec[base + 7u]) * inv;
        float nl = length(nsum);
        vec3 n = nl > 1e-3 * float(count) ? nsum / nl : FACE_DIR[b];
        vec3 p = centre - n * (dist * vs);  // the bucket's surface point nearest the centre
        vec3 Ep = vec3(0.0), Em = vec3(0.0);
        if (u_audit > 0.0) {
            Ep = Em = vec3(PI * u_audit);  // with rho = 1 below: L = u_audit on both sides
            rho = vec3(1.0);
        } else if (u_direct_mode == 2 && i < u_direct_capacity) {
            uint d = (i * 6u + uint(b)) * 6u;
            Ep = vec3(vx_direct[d], vx_direct[d + 1u], vx_direct[d + 2u]);
            Em = vec3(vx_direct[d + 3u], vx_direct[d + 4u], vx_direct[d + 5u]);
        } else {
            direct_irradiance(centre, p, n, vs, rng, Ep, Em);
            if (u_direct_mode == 1 && i < u_direct_capacity) {
                uint d = (i * 6u + uint(b)) * 6u;
                vx_direct[d] = Ep.x; vx_direct[d + 1u] = Ep.y; vx_direct[d + 2u] = Ep.z;
                vx_direct[d + 3u] = Em.x; vx_direct[d + 4u] = Em.y; vx_direct[d + 5u] = Em.z;
            }
        }
        if (u_gather == 1 && u_audit <= 0.0) {
            float vis;
            Ep += vx_diffuse_cones(p + n * off, n, vs, u_max_distance, u_step, 1.0, float(u_bounce), vis, off);
            Em += vx_diffuse_cones(p - n * off, -n, vs, u_max_distance, u_step, 1.0, float(u_bounce), vis, off);
        }
        vec3 Lp = sanitize(rho * INV_PI * Ep), Lm = sanitize(rho * INV_PI * Em);
        // a dilated voxel (its centre more than half a voxel off the plane) lies on one side of
        // the surface: it shows that side only, and is dark (still opaque) from the other,
        // where the surface's own voxel layer stands in front of it (the sun-lit outside of a
        // roof otherwise shows inside the room in the layer the dilation adds there)
        if (dist > VX_SIDE_CUT) Lm = vec3(0.0);
        if (dist < -VX_SIDE_CUT) Lp = vec3(0.0);
        for (int f = 0; f < 6; ++f) {
            float s = dot(n, FACE_DIR[f]);
            if (s > 0.0) { front[f] += s * Lp; af[f] += s; }
            else { back[f] -= s * Lm; ab[f] -= s; }
        }
    }
    // Towards D the voxel shows the side of each surface facing D over its projected area
    // |n.D|: premultiplied radiance, never a mix of a surface's two sides. An edge-on surface
    // (n.D = 0: every wall of an axis-aligned room for four of the six directions) shows
    // nothing: the mean of its two sides would let a cone grazing a zero-thickness roof or
    // wall see half of its sun-lit outside (sunlit_room 2.7x Cycles) or of the lit room
    // behind it. Coverage sums over buckets are capped at 1 (radiance renormalised).
    // The opacity keeps a floor of u_edge_opacity: an edge-on wall shows black at that
    // opacity (0.05 let cones grazing walls and roofs through; 0.3 measured: sunlit_room
    // 1.80 -> 1.36x Cycles, thin-wall leak 0.047 -> 0.027).
    for (int f = 0; f < 6; ++f) {
        vec3 F = front[f] / max(af[f], 1.0), B = back[f] / max(ab[f], 1.0);
        float a1 = min(af[f], 1.0), a2 = min(ab[f], 1.0);
        vec3 L = F + (1.0 - a1) * B;
        float a = a1 + (1.0 - a1) * a2;
        a = max(a, u_edge_opacity);
        imageStore(o_radiance, ivec3(gid.xy, (f * C) * N + gid.z), vec4(L, a));
    }
}
