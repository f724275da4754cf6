// probes/common.glsl — the probe volume every probe technique shares (IRRADIANCE_VOLUME,
// DDGI, RTXGI): grid addressing, atlas addressing, and the irradiance lookup at a surface.
// Host side: addon/render/passes/probes.py (ProbeVolume: the uniforms below).
//
// Grid. Probes sit on a lattice anchored at u_probe_anchor with spacing u_probe_spacing; the
// volume is the u_probe_counts probes starting at the absolute lattice cell u_probe_cell0
// (0 for a volume fitted to the scene; the camera's cell minus half the counts for a
// camera-following volume). A probe's storage slot is its absolute cell modulo the counts
// (toroidal addressing), so scrolling the volume keeps every probe that stays inside it.
// Storage slot s (ivec3) -> linear index s.x + cx*(s.y + cy*s.z) (rows of the ray texture),
// -> atlas tile (s.x + cx*s.y, s.z) (irradiance tiles u_irr_size texels, distance tiles
// u_dist_size texels, both with a one-texel octahedral border), -> texel (s.x + cx*s.y, s.z)
// of the state texture (xyz = relocation offset in world units, w = state: 0 active,
// 1 inactive, -1 active and moved this frame).
// Atlases hold irradiance E (W/m^2, rgb; a = updates since reset) and the mean distance and
// mean squared distance (rg) to the first surface, float32 (nothing clamped).
#ifndef GI_PROBES_COMMON_GLSL
#define GI_PROBES_COMMON_GLSL

#include "lib/octahedral.glsl"

uniform vec3 u_probe_anchor;
uniform vec3 u_probe_spacing;
uniform ivec3 u_probe_counts;
uniform ivec3 u_probe_cell0;
uniform ivec3 u_probe_cell0_prev;  // last frame's (scrolling: slots whose cell changed are new)
uniform int u_irr_size;
uniform int u_dist_size;

ivec3 imod3(ivec3 a, ivec3 n) { return ((a % n) + n) % n; }

int probe_count() { return u_probe_counts.x * u_probe_counts.y * u_probe_counts.z; }

ivec3 slot_of_cell(ivec3 a) { return imod3(a, u_probe_counts); }

// The absolute cell that storage slot s holds for a volume starting at cell0.
ivec3 cell_of_slot(ivec3 s, ivec3 cell0) { return cell0 + imod3(s - cell0, u_probe_counts); }

int slot_index(ivec3 s) { return s.x + u_probe_counts.x * (s.y + u_probe_counts.y * s.z); }

ivec3 slot_from_index(int i) {
    int cx = u_probe_counts.x, cy = u_probe_counts.y;
    return ivec3(i % cx, (i / cx) % cy, i / (cx * cy));
}

ivec2 slot_tile(ivec3 s) { return ivec2(s.x + u_probe_counts.x * s.y, s.z); }

ivec3 slot_from_tile(ivec2 tile) {
    return ivec3(tile.x % u_probe_counts.x, tile.x / u_probe_counts.x, tile.y);
}

bool slot_is_new(ivec3 s) { return cell_of_slot(s, u_probe_cell0) != cell_of_slot(s, u_probe_cell0_prev); }

vec3 cell_position(ivec3 a) { return u_probe_anchor + vec3(a) * u_probe_spacing; }

#ifdef PROBE_LOOKUP
// ---------------------------------------------------------------- irradiance at a surface
uniform sampler2D u_probe_irr;    // irradiance atlas (linear filtering, bordered tiles)
uniform sampler2D u_probe_dist;   // distance atlas (linear filtering), DDGI/RTXGI
uniform sampler2D u_probe_state;  // state texture (nearest)
uniform float u_normal_bias;      // world units
uniform float u_view_bias;        // world units

vec4 probe_state(ivec3 s) { return finite_or_zero(texelFetch(u_probe_state, slot_tile(s), 0)); }

vec3 probe_position(ivec3 a, vec4 st) { return cell_position(a) + st.xyz; }

vec3 sample_probe_irradiance(ivec3 s, vec3 dir) {
    vec2 atlas = vec2(textureSize(u_probe_irr, 0));
    vec2 uv = (vec2(slot_tile(s) * u_irr_size) + oct_tile_uv(dir, u_irr_size)) / atlas;
    return finite_or_zero(textureLod(u_probe_irr, uv, 0.0)).rgb;
}

vec2 sample_probe_distance(ivec3 s, vec3 dir) {
    vec2 atlas = vec2(textureSize(u_probe_dist, 0));
    vec2 uv = (vec2(slot_tile(s) * u_dist_size) + oct_tile_uv(dir, u_dist_size)) / atlas;
    return finite_or_zero(textureLod(u_probe_dist, uv, 0.0)).rg;
}

// Irradiance E (W/m^2) arriving at surface point P with normal N, seen from direction V
// (unit, towards the viewer). Eight surrounding probes, trilinear weights; with
// PROBE_VISIBILITY (DDGI, Majercik et al. 2019): surface bias n*normal_bias + v*view_bias,
// wrap-shading weight ((dot(dir to probe, n) + 1)/2)^2 + 0.2, Chebyshev visibility
// (sigma^2/(sigma^2 + delta^2))^3 floored at 0.05, small weights crushed (w^3/0.04), and
// inactive probes (RTXGI classification) skipped. Without it (IRRADIANCE_VOLUME, Greger et al.
// 1998): plain trilinear interpolation, which leaks through thin walls. Returns the weight
// sum in w (0: no usable probe) .
vec3 probe_irradiance(vec3 P, vec3 N, vec3 V, out float wsum) {
    wsum = 0.0;
    vec3 sum = vec3(0.0);
#ifdef PROBE_VISIBILITY
    vec3 Pb = P + N * u_normal_bias + V * u_view_bias;
#else
    vec3 Pb = P;
#endif
    vec3 g = (Pb - cell_position(u_probe_cell0)) / u_probe_spacing;
    ivec3 base = clamp(ivec3(floor(g)), ivec3(0), max(u_probe_counts - 2, ivec3(0)));
    vec3 alpha = clamp(g - vec3(base), 0.0, 1.0);
    for (int i = 0; i < 8; ++i) {
        ivec3 off = ivec3(i & 1, (i >> 1) & 1, (i >> 2) & 1);
        ivec3 gi = min(base + off, u_probe_counts - 1);
        ivec3 a = u_probe_cell0 + gi;
        ivec3 s = slot_of_cell(a);
        vec3 tri3 = mix(1.0 - alpha, alpha, vec3(off));
        float tri = tri3.x * tri3.y * tri3.z;
        float w = 1.0;
#ifdef PROBE_VISIBILITY
        vec4 st = probe_state(s);
        if (st.w > 0.5) continue;  // inactive (in a wall, or nothing near it)
        vec3 pp = probe_position(a, st);
        vec3 to_probe = normalize(pp - P + vec3(0.0, 0.0, 1e-9));
        w *= sqr((dot(to_probe, N) + 1.0) * 0.5) + 0.2;
        vec3 from_probe = Pb - pp;
        float dist = length(from_probe);
        vec2 m = sample_probe_distance(s, from_probe / max(dist, 1e-9));
        float cheb = 1.0;
        if (dist > m.x) {
            float var = abs(m.x * m.x - m.y);
            float d = dist - m.x;
            cheb = var / max(var + d * d, 1e-12);
            cheb = cheb * cheb * cheb;
        }
        w *= max(cheb, 0.05);
        w = max(w, 1e-6);
        if (w < 0.2) w *= w * w / (0.2 * 0.2);
        tri = max(tri, 0.001);
#endif
        w *= tri;
        sum += w * sample_probe_irradiance(s, N);
        wsum += w;
    }
    return wsum > 0.0 ? sum / wsum : vec3(0.0);
}

// Closest probe sphere (radius `radius`, centred on the probe's relocated position) along the
// ray o + t d (d unit) before t_max: the slot index, -1 none; n = the sphere's normal at the
// hit, slot and state of the probe. Used by the debug views (gather.comp) and the viewport
// overlay (overlay.comp). Loops over every probe: for volumes of a few thousand probes.
int hit_probe(vec3 o, vec3 d, float t_max, float radius, out vec3 n, out ivec3 slot, out vec4 state) {
    int best = -1;
    float bt = t_max;
    n = vec3(0.0, 0.0, 1.0);
    slot = ivec3(0);
    state = vec4(0.0);
    for (int i = 0; i < probe_count(); ++i) {
        ivec3 s = slot_from_index(i);
        ivec3 a = cell_of_slot(s, u_probe_cell0);
        vec4 st = probe_state(s);
        vec3 c = cell_position(a) + st.xyz;
        vec3 oc = o - c;
        float b = dot(oc, d);
        float disc = b * b - (dot(oc, oc) - radius * radius);
        if (disc < 0.0) continue;
        float t = -b - sqrt(disc);
        if (t > 0.0 && t < bt) { bt = t; best = i; n = normalize(o + d * t - c); slot = s; state = st; }
    }
    return best;
}
#endif

// Direction of ray r of a probe: the first u_fixed_rays are a fixed spherical Fibonacci set
// (RTXGI: relocation and classification look at them, the blend does not), the others a
// spherical Fibonacci set rotated by this frame's random rotation.
uniform int u_rays;
uniform int u_fixed_rays;
uniform mat3 u_ray_rotation;

vec3 probe_ray_dir(int r) {
    if (r < u_fixed_rays) return spherical_fibonacci(float(r), float(u_fixed_rays));
    int n = u_rays - u_fixed_rays;
    return normalize(u_ray_rotation * spherical_fibonacci(float(r - u_fixed_rays), float(max(n, 1))));
}

#endif
