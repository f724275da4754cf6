// update.comp — blends this frame's probe rays into the probe atlases (one invocation per
// atlas texel, border texels included: a border texel blends the rays for the interior
// texel it mirrors, so the tile is complete after this one dispatch).
// UPDATE_IRRADIANCE: E(n) = pi * sum max(0, n.d) L / sum max(0, n.d) over the rays (the cosine-
//   weighted mean radiance times pi), float32, rgb; a = updates since the probe was reset.
// UPDATE_DISTANCE: (mean d, mean d^2) with weights max(0, n.d)^50, d clamped to u_max_distance.
// Hysteresis (Majercik et al. 2019): new = mix(blend, old, h) with h = u_hysteresis, except
//   - a reset texel (new probe, scrolled in, or nothing stored) takes the blend (h = 0);
//   - the first updates after a reset average: h <= age / (age + u_ramp) (warm-up);
//   - a large change (relative luminance change above u_change_threshold: a light switched)
//     uses h * 0.25, so the probes follow quickly without boiling in steady state.
// A probe relocated last frame (state w = -1) restarts like a reset one.
// Inactive probes (RTXGI classification) keep their stored value. Rays 0..u_fixed_rays-1
// (RTXGI's fixed set for relocation/classification) are not blended.
// With PROBE_STATS the irradiance update also writes the per-texel signed relative change of
// the stored value (its mean over the atlas: the drift that measures the warm-up's convergence).
#include "lib/common.glsl"
#include "probes/common.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
#ifdef UPDATE_IRRADIANCE
layout(binding = 0, rgba32f) uniform writeonly image2D o_atlas;
#else
layout(binding = 0, rg32f) uniform writeonly image2D o_atlas;
#endif
#ifdef PROBE_STATS
layout(binding = 1, r32f) uniform writeonly image2D o_change;
#endif
uniform sampler2D u_prev;        // last frame's atlas
uniform sampler2D u_ray_tex;        // trace.comp's output
uniform sampler2D u_state;       // this frame's probe state
uniform sampler2D u_state_prev;  // last frame's: w = -1 where the probe moved (its rays are new)
uniform float u_hysteresis;
uniform float u_change_threshold;
uniform float u_ramp;
uniform float u_max_distance;
uniform int u_reset;             // 1: every probe is new (history invalid)

void main() {
    ivec2 texel = ivec2(gl_GlobalInvocationID.xy);
    ivec2 size = imageSize(o_atlas);
    if (any(greaterThanEqual(texel, size))) return;
#ifdef UPDATE_IRRADIANCE
    int tile_size = u_irr_size;
#else
    int tile_size = u_dist_size;
#endif
    ivec2 tile = texel / tile_size;
    ivec2 t = texel - tile * tile_size;
    ivec3 s = slot_from_tile(tile);
    int pi = slot_index(s);
    vec4 prev = finite_or_zero(texelFetch(u_prev, texel, 0));
    bool reset = u_reset != 0 || slot_is_new(s) || texelFetch(u_state_prev, tile, 0).w < -0.5;
    if (reset) prev = vec4(0.0);
    vec4 st = texelFetch(u_state, tile, 0);
    if (st.w > 0.5) {  // inactive: not traced this frame, keep what it had
#ifdef PROBE_STATS
        imageStore(o_change, texel, vec4(0.0));
#endif
        imageStore(o_atlas, texel, prev);
        return;
    }
    vec3 n = oct_texel_dir(t, tile_size);
    vec3 sum = vec3(0.0);
    float wsum = 0.0;
    for (int r = u_fixed_rays; r < u_rays; ++r) {
        vec4 ray = texelFetch(u_ray_tex, ivec2(r, pi), 0);
        vec3 d = probe_ray_dir(r);
        float c = max(dot(n, d), 0.0);
#ifdef UPDATE_IRRADIANCE
        if (ray.a < 0.0) {  // back face: not a surface seen from outside
            continue;
        }
        sum += c * ray.rgb;
        wsum += c;
#else
        float w = pow(c, 50.0);
        float dist = min(abs(ray.a), u_max_distance);
        sum += w * vec3(dist, dist * dist, 0.0);
        wsum += w;
#endif
    }
#ifdef UPDATE_IRRADIANCE
    // No front-face ray in this texel's hemisphere (a probe behind a wall or in geometry sees
    // only back faces there): it receives nothing, so it decays towards 0 like any texel whose
    // light went out. (Keeping the stored value instead left such texels stuck at whatever a
    // stray ray once gave them: stuck-bright probes after a light was switched off.)
    vec3 blend = wsum > 1e-12 ? sum / wsum * PI : vec3(0.0);
#else
    if (wsum <= 1e-12) {
        imageStore(o_atlas, texel, prev);
        return;
    }
    vec3 blend = sum / wsum;
#endif
#ifdef UPDATE_IRRADIANCE
    float age = prev.a;
    float h = u_hysteresis;
    if (age <= 0.0) h = 0.0;
    h = min(h, age / (age + u_ramp));
    float lp = luminance(prev.rgb), lb = luminance(blend);
    if (abs(lb - lp) > u_change_threshold * max(max(lp, lb), 1e-6)) h *= 0.25;
    vec3 v = sanitize(mix(blend, prev.rgb, h));
#ifdef PROBE_STATS
    float lv = luminance(v);
    imageStore(o_change, texel, vec4((lv - lp) / max(lv, 1e-4), 0.0, 0.0, 0.0));
#endif
    imageStore(o_atlas, texel, vec4(v, min(age + 1.0, 1e6)));
#else
    float h = (prev.x <= 0.0) ? 0.0 : u_hysteresis;
    vec2 v = mix(blend.xy, prev.xy, h);
    imageStore(o_atlas, texel, vec4(v, 0.0, 0.0));
#endif
}
