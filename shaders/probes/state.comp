// state.comp — probe state: relocation offset (xyz, world units) and classification (w: 0
// active, 1 inactive). One invocation per probe slot.
// Without PROBE_RELOCATE / PROBE_CLASSIFY (IRRADIANCE_VOLUME, DDGI): every probe active, on
// its lattice point.
// PROBE_RELOCATE (RTXGI, Majercik et al. 2021, the SDK's three cases), from this frame's fixed
//   rays traced from the current position:
//   - inside geometry (more than u_backface_ratio of them hit back faces): move just past the
//     closest back face (+ half u_min_frontface);
//   - else, a front face closer than u_min_frontface: move away from it along the farthest
//     front-face direction, by at most that distance and u_min_frontface, and only when that
//     direction points away from the close face (never through a wall on the other side);
//   - else (nothing close): move back towards the lattice point, by at most the margin the
//     closest front face leaves.
//   The new offset is kept only inside the ellipsoid |offset / spacing| < u_max_offset (0.45 of
//   a cell); outside it the probe stays where it was.
// PROBE_CLASSIFY (RTXGI): inactive when inside geometry (back-face ratio), or when no fixed ray
//   hits a surface within the probe's own cell (empty space: no receiver interpolates from it).
//   An inactive probe still traces its fixed rays, so it is reactivated when that changes.
// A slot that scrolled in (camera-following volume) or a reset starts on its lattice point.
#include "lib/common.glsl"
#include "probes/common.glsl"

layout(local_size_x = 64) in;
layout(binding = 0, rgba32f) uniform writeonly image2D o_state;
uniform sampler2D u_ray_tex;
uniform sampler2D u_prev_state;
uniform float u_backface_ratio;
uniform float u_min_frontface;   // world units
uniform float u_max_offset;      // fraction of a cell
uniform int u_reset;

void main() {
    int pi = int(gl_GlobalInvocationID.x);
    if (pi >= probe_count()) return;
    ivec3 s = slot_from_index(pi);
    vec4 st = (u_reset != 0 || slot_is_new(s)) ? vec4(0.0) : finite_or_zero(texelFetch(u_prev_state, slot_tile(s), 0));
#if defined(PROBE_RELOCATE) || defined(PROBE_CLASSIFY)
    int nf = u_fixed_rays;
    int back = 0;
    float close_back = 1e30, close_front = 1e30, far_front = -1.0;
    vec3 dir_back = vec3(0.0), dir_front = vec3(0.0), dir_far = vec3(0.0);
    bool near_surface = false;
    for (int r = 0; r < nf; ++r) {
        float t = texelFetch(u_ray_tex, ivec2(r, pi), 0).a;
        vec3 d = probe_ray_dir(r);
        if (t < 0.0) {
            back++;
            if (-t < close_back) { close_back = -t; dir_back = d; }
        } else {
            if (t < close_front) { close_front = t; dir_front = d; }
            if (t > far_front) { far_front = t; dir_far = d; }  // a miss counts as far (1e27)
        }
        float at = abs(t);
        if (at < 1e26 && all(lessThanEqual(abs(d * at), u_probe_spacing))) near_surface = true;
    }
    bool inside = float(back) > u_backface_ratio * float(max(nf, 1));
    vec3 off = st.xyz;
#ifdef PROBE_RELOCATE
    vec3 moved = off;
    if (inside) {
        moved += dir_back * (close_back + 0.5 * u_min_frontface);
    } else if (close_front < u_min_frontface) {
        if (dot(dir_front, dir_far) <= 0.0) moved += dir_far * min(far_front, u_min_frontface);
    } else {
        float back_len = min(close_front - u_min_frontface, length(off));
        if (back_len > 0.0) moved -= normalize(off) * back_len;
    }
    vec3 rel = moved / u_probe_spacing;
    if (dot(rel, rel) < u_max_offset * u_max_offset) off = moved;
#endif
    // an active probe that moved more than 1 % of a cell is flagged (w = -1): next frame's rays
    // are the first from its new place, and the update restarts its atlases from them (the
    // old distances would let light through walls the probe now sits beside)
    float state = any(greaterThan(abs(off - st.xyz), 0.01 * u_probe_spacing)) ? -1.0 : 0.0;
#ifdef PROBE_CLASSIFY
    if (inside || !near_surface) state = 1.0;
#endif
    imageStore(o_state, slot_tile(s), vec4(off, state));
#else
    imageStore(o_state, slot_tile(s), vec4(0.0));
#endif
}
