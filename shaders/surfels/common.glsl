// surfels/common.glsl — surfel GI (SURFEL, after EA SEED's GIBS, Halen et al. 2021): irradiance
// cached on surface elements spawned where the screen is poorly covered. Host side:
// addon/render/passes/surfels.py (SurfelSet: the uniforms and buffers).
//
// A surfel (SfSurfel) lives in the object space of the instance it was spawned on: its world
// position and normal are recomputed every frame from the instance's transform (a surfel on a
// moving object moves with it). info: x = instance + 1 (0: free), y = frame last seen by a
// pixel, z = frame made; wpos/wnrm: this frame's world position (w: radius) and normal (w: 1
// alive). Its state (sf_state, SF_STATE vec4s, double-buffered by the graph: the update reads
// last frame's) holds the mean irradiance E (rgb, w = samples), the variance (rgb) and the
// short-window mean (rgb) of the multiscale mean estimator, then its depth moments (4×4
// hemi-octahedral texels of the mean distance and mean squared distance its rays travelled,
// two texels per vec4), which give the Chebyshev visibility that keeps a surfel from lighting
// what a wall hides from it.
// Grid: camera-centred cascades of SF_GRID³ cells; cascade k has cells of u_sf_cell · 2^k, and a
// surfel is listed (up to SF_CELL_CAP per cell) in every cell of the finest cascade holding its
// centre that its sphere overlaps. Free surfels are a stack (sf_free, sf_free_count) at the head
// of the surfel buffer; SF_CAPACITY (a define from the host) is the pool's size.
#ifndef GI_SURFELS_GLSL
#define GI_SURFELS_GLSL

#define SF_GRID 16
#define SF_CASCADES 4
#define SF_CELL_CAP 32
#define SF_MOMENTS 4   // moment texels per side (hemi-octahedral)
#define SF_BINDING_SURFELS 18
#define SF_BINDING_CELLS 19
#define SF_BINDING_STATE 20
#define SF_BINDING_STATE_OUT 21
#define SF_STATE 11   // vec4s of state per surfel: mean (w: samples), variance, short mean, 8 x moments
#ifndef SF_CAPACITY
#define SF_CAPACITY 4096
#endif

struct SfSurfel {
    vec4 pos;    // object-space position, w: radius (world units)
    vec4 nrm;    // object-space normal
    uvec4 info;  // x: instance + 1 (0 free), y: frame last seen, z: frame made
    vec4 wpos;   // this frame's world position, w: radius
    vec4 wnrm;   // this frame's world normal, w: 1 alive
};

// the free stack, then the surfels
layout(std430, binding = SF_BINDING_SURFELS) coherent buffer SfSurfels {
    uint sf_free_count;
    uint sf_pad0, sf_pad1, sf_pad2;
    uint sf_free[SF_CAPACITY];
    SfSurfel sf_surfels[];
};
layout(std430, binding = SF_BINDING_CELLS) coherent buffer SfCells { uint sf_cells[]; }; // counts, then items

uniform float u_sf_cell;      // cascade 0's cell side (world units)
uniform vec3 u_sf_center;     // the grid's centre (the camera, snapped to cascade 3's cells)
uniform uint u_sf_frame;

int sf_cell_count() { return SF_GRID * SF_GRID * SF_GRID * SF_CASCADES; }

// The cascade whose extent holds p (-1: outside every cascade) and the cell there.
int sf_cascade(vec3 p) {
    for (int k = 0; k < SF_CASCADES; ++k) {
        float half_ext = 0.5 * float(SF_GRID) * u_sf_cell * exp2(float(k));
        if (all(lessThan(abs(p - u_sf_center), vec3(half_ext)))) return k;
    }
    return -1;
}

// A new surfel's radius at p: `want` (its pixel size at its depth) but at most the cell side of
// p's cascade, so that it is listed in every cell it overlaps (<= 3 per axis); 0 outside the grid.
float sf_spawn_radius(vec3 p, float want) {
    int k = sf_cascade(p);
    return k < 0 ? 0.0 : min(want, u_sf_cell * exp2(float(k)));
}

ivec3 sf_cell_of(vec3 p, int k) {
    float s = u_sf_cell * exp2(float(k));
    return ivec3(floor((p - u_sf_center) / s)) + SF_GRID / 2;
}

int sf_cell_index(ivec3 c, int k) {
    if (any(lessThan(c, ivec3(0))) || any(greaterThanEqual(c, ivec3(SF_GRID)))) return -1;
    return ((k * SF_GRID + c.z) * SF_GRID + c.y) * SF_GRID + c.x;
}

// the cell list of point p: first item offset and count (0 when outside the grid)
int sf_cell_at(vec3 p, out int count) {
    count = 0;
    int k = sf_cascade(p);
    if (k < 0) return 0;
    int ci = sf_cell_index(sf_cell_of(p, k), k);
    if (ci < 0) return 0;
    count = int(min(sf_cells[ci], uint(SF_CELL_CAP)));
    return sf_cell_count() + ci * SF_CELL_CAP;
}

// hemi-octahedral coordinates of direction d in the frame of normal n, in [0, 1]²
vec2 sf_hemi_oct(vec3 d, vec3 n) {
    vec3 t, b;
    make_basis(n, t, b);
    vec3 l = vec3(dot(d, t), dot(d, b), max(dot(d, n), 0.0));
    l /= (abs(l.x) + abs(l.y) + l.z + 1e-8);
    vec2 e = vec2(l.x + l.y, l.x - l.y);
    return clamp(e * 0.5 + 0.5, 0.0, 1.0);
}

int sf_moment_texel(vec3 d, vec3 n) {
    ivec2 c = min(ivec2(sf_hemi_oct(d, n) * float(SF_MOMENTS)), ivec2(SF_MOMENTS - 1));
    return c.x + c.y * SF_MOMENTS;
}

#ifdef SF_LOOKUP
layout(std430, binding = SF_BINDING_STATE) readonly buffer SfState { vec4 sf_state[]; };  // SF_STATE per surfel
uniform float u_sf_normal_power;

vec2 sf_moment(int i, int texel) {
    vec4 m = sf_state[i * SF_STATE + 3 + texel / 2];
    return (texel & 1) == 0 ? m.xy : m.zw;
}

// Weight of surfel i for the surface point P with normal N: a smooth falloff over its radius,
// the normals' agreement, and the Chebyshev bound of its depth moments in the direction of P
// (what the surfel's rays found nearer than P in that direction hides P from it).
float sf_weight(int i, vec3 P, vec3 N) {
    vec4 wp = sf_surfels[i].wpos, wn = sf_surfels[i].wnrm;
    if (wn.w < 0.5) return 0.0;
    vec3 d = P - wp.xyz;
    float dist = length(d);
    float r = wp.w;
    if (dist >= r) return 0.0;
    float w = 1.0 - smoothstep(0.0, r, dist);
    w *= pow(max(dot(wn.xyz, N), 0.0), u_sf_normal_power);
    if (w <= 0.0 || dist < 0.05 * r) return w;
    vec2 m = sf_moment(i, sf_moment_texel(d / dist, wn.xyz));
    if (m.x > 0.0 && dist > m.x) {
        float var = max(m.y - m.x * m.x, 1e-4 * r * r);
        w *= var / (var + (dist - m.x) * (dist - m.x));
    }
    return w;
}

// Irradiance at P (normal N) from the surfels around it; `coverage`: the summed weight. `mark`:
// the frame the surfels used are marked as last used by (raised to it, never lowered; 0: not
// marked): a pixel marks them with this frame, a surfel's ray with the frame that surfel was
// last used, so a cluster of surfels no pixel sees any more ages out together.
vec3 sf_irradiance(vec3 P, vec3 N, out float coverage, uint mark) {
    int count;
    int base = sf_cell_at(P, count);
    vec3 E = vec3(0.0);
    coverage = 0.0;
    for (int j = 0; j < count; ++j) {
        int i = int(sf_cells[base + j]);
        float w = sf_weight(i, P, N);
        if (w <= 0.0) continue;
        E += w * max(sf_state[i * SF_STATE].rgb, vec3(0.0));
        coverage += w;
        if (mark != 0u) atomicMax(sf_surfels[i].info.y, mark);
    }
    return coverage > 0.0 ? E / coverage : vec3(0.0);
}
#endif

#endif
