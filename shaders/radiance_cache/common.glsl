// radiance_cache/common.glsl — the world-space radiance cache (a spatial hash grid, after
// GI-1.0's world cache): indirect irradiance stored per cell of a grid whose cell size grows
// with the distance to the camera, looked up (and requested) at any surface point.
// Host side: addon/render/passes/radiance_cache.py (RadianceCache: the uniforms and buffers).
//
// Cells. A point p with normal n falls in the cell of side s(p) = u_rc_cell_min · 2^k, the
// smallest power-of-two multiple of u_rc_cell_min not below u_rc_cell_scale · distance(p,
// camera) (far cells are coarse, as a pixel's footprint is), and in one of six normal buckets
// (the dominant axis of n and its sign), so the two sides of a thin wall are separate cells.
// Storage. u_rc_buckets buckets of RC_BUCKET entries; a cell hashes (pcg4d of its integer
// coordinates, level and normal bucket) to one bucket and a 32-bit checksum (never 0), which
// is the entry's key. An entry (RcEntry) holds the key (0: empty), the frame it was last
// used, the frame it was made, and the point and normal it was made for (the update traces
// from there). rc_irr[i] is the entry's irradiance E (rgb, W/m²) and its sample count (w):
// the indirect light arriving at the cell (light that has bounced at least once; the direct
// light of lights, emitters and the world at the cell is not in it), double-buffered by the
// graph (the update reads last frame's, every other pass this frame's).
// Lookups request the cells they miss: a free entry of the bucket is claimed by an atomic
// compare-and-swap of its key, and the update pass fills it from the next frame on. Entries not
// used for u_rc_max_age frames are freed by the update (least recently used eviction).
#ifndef GI_RADIANCE_CACHE_GLSL
#define GI_RADIANCE_CACHE_GLSL

#define RC_BUCKET 16
#define RC_BINDING_ENTRIES 18
#define RC_BINDING_IRR 19
#define RC_BINDING_IRR_OUT 20

struct RcEntry {
    uvec4 key;   // x: checksum (0 = empty), y: frame last used, z: frame made, w: level
    vec4 pos;    // xyz: the point the entry was made for, w: cell side
    vec4 nrm;    // xyz: its normal
};

layout(std430, binding = RC_BINDING_ENTRIES) coherent buffer RcEntries { RcEntry rc_entries[]; };
layout(std430, binding = RC_BINDING_IRR) readonly buffer RcIrr { vec4 rc_irr[]; };

uniform int u_rc_buckets;
uniform float u_rc_cell_min;    // smallest cell side (world units)
uniform float u_rc_cell_scale;  // cell side per unit of distance to the camera
uniform vec3 u_rc_camera;
uniform uint u_rc_frame;        // the cache's own frame counter (ages)

int rc_capacity() { return u_rc_buckets * RC_BUCKET; }

int rc_level(vec3 p) {
    float want = u_rc_cell_scale * distance(p, u_rc_camera);
    return int(clamp(ceil(log2(max(want / u_rc_cell_min, 1.0))), 0.0, 24.0));
}

float rc_cell_side(int level) { return u_rc_cell_min * exp2(float(level)); }

int rc_normal_bucket(vec3 n) {
    vec3 a = abs(n);
    int axis = (a.x >= a.y && a.x >= a.z) ? 0 : (a.y >= a.z ? 1 : 2);
    return axis * 2 + (n[axis] < 0.0 ? 1 : 0);
}

// (bucket, checksum) of the cell of p, n.
uvec2 rc_hash(vec3 p, vec3 n, out int level) {
    level = rc_level(p);
    ivec3 c = ivec3(floor(p / rc_cell_side(level)));
    uvec4 h = pcg4d(uvec4(uvec3(c), uint(level) | (uint(rc_normal_bucket(n)) << 8u)));
    return uvec2(h.x % uint(u_rc_buckets), h.y | 1u);
}

// The entry of the cell of (p, n), or -1. `request`: claim a free entry of the bucket when the
// cell has none (-1 when the bucket is full). A found entry is marked used this frame.
int rc_find(vec3 p, vec3 n, bool request) {
    int level;
    uvec2 h = rc_hash(p, n, level);
    int base = int(h.x) * RC_BUCKET;
    for (int i = 0; i < RC_BUCKET; ++i) {
        if (rc_entries[base + i].key.x == h.y) {
            rc_entries[base + i].key.y = u_rc_frame;
            return base + i;
        }
    }
    if (!request) return -1;
    for (int i = 0; i < RC_BUCKET; ++i) {
        if (rc_entries[base + i].key.x != 0u) continue;
        uint prev = atomicCompSwap(rc_entries[base + i].key.x, 0u, h.y);
        if (prev == 0u) {
            rc_entries[base + i].key.yzw = uvec3(u_rc_frame, u_rc_frame, uint(level));
            rc_entries[base + i].pos = vec4(p, rc_cell_side(level));
            rc_entries[base + i].nrm = vec4(n, 0.0);
            return base + i;
        }
        if (prev == h.y) return base + i;  // another invocation claimed it for this cell
    }
    return -1;
}

// Indirect irradiance at (p, n) from the cache; `samples`: the entry's sample count (0: none
// yet, or not usable here: the irradiance is then 0). With the ray tracer (lib/scene_rt.glsl
// included before this file) an entry is used only when the point it traces from is visible
// from p: a cell straddling a thin wall (a floor cell under it, a side wall's cell along it)
// holds the light of the side its point is on, which must not leak to the other side.
// rc_lookup: the cell of q, the visibility from p (q = p but for the jitter below).
vec3 rc_lookup(vec3 p, vec3 q, vec3 n, bool request, out float samples) {
    int i = rc_find(q, n, request);
    samples = 0.0;
    if (i < 0) return vec3(0.0);
#ifdef GI_SCENE_RT_GLSL
    vec4 ep = rc_entries[i].pos;
    vec3 o = p + n * (1e-3 * ep.w), e_o = ep.xyz + n * (1e-3 * ep.w);
    float dq = distance(o, e_o);
    if (dq > 1e-3 * ep.w && scene_occluded(o, (e_o - o) / dq, 0.0, dq)) return vec3(0.0);
#endif
    vec4 e = finite_or_zero(rc_irr[i]);
    samples = e.w;
    return max(e.rgb, vec3(0.0));
}

vec3 rc_irradiance(vec3 p, vec3 n, bool request, out float samples) { return rc_lookup(p, p, n, request, samples); }

// The same with the lookup point jittered inside the tangent plane by up to half a cell (hides
// the cells' edges at the price of noise the callers' temporal filters remove).
vec3 rc_irradiance_jittered(vec3 p, vec3 n, vec2 u, bool request, out float samples) {
    vec3 t, b;
    make_basis(n, t, b);
    float s = rc_cell_side(rc_level(p));
    vec3 q = p + (u.x - 0.5) * s * t + (u.y - 0.5) * s * b;
    return rc_lookup(p, q, n, request, samples);
}

#endif
