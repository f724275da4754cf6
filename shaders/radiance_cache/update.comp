// update.comp — one invocation per entry of the world radiance cache (radiance_cache/common.glsl).
// A used entry traces u_rc_rays cosine-distributed rays from the point it was made for; a hit
// returns the light it reflects towards the cell (lib/bounce.glsl: its direct light, the uniform
// sky at it, and its diffuse albedo × last frame's cached irradiance there / π: infinite
// bounces over frames, the lookup requesting the cells it misses); either side of a surface
// reflects, as Cycles shades them (the cells sit on surfaces, outside geometry). Misses add
// nothing (the world seen from the cell is direct light). E = π · mean(L), blended into last
// frame's value with weight max(1 / n, u_rc_min_blend) (n: samples so far), raised to
// u_rc_fast_blend when the luminance moved by more than u_rc_change_threshold (relative): a
// switched or moved light is followed within a few frames. Entries unused for u_rc_max_age
// frames are freed.
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/sampling.glsl"
#include "lib/rng.glsl"
#include "lib/brdf.glsl"
#include "lib/lights.glsl"
#include "lib/scene_rt.glsl"
#include "lib/albedo.glsl"
#include "lib/bounce.glsl"
#include "radiance_cache/common.glsl"

layout(local_size_x = 64) in;
layout(std430, binding = RC_BINDING_IRR_OUT) writeonly buffer RcIrrOut { vec4 rc_irr_out[]; };

uniform int u_rc_rays;
uniform uint u_rc_max_age;
uniform float u_rc_min_blend;
uniform float u_rc_fast_blend;
uniform float u_rc_change_threshold;
uniform uint u_seed;

void main() {
    int i = int(gl_GlobalInvocationID.x);
    if (i >= rc_capacity()) return;
    RcEntry e = rc_entries[i];
    if (e.key.x == 0u) {
        rc_irr_out[i] = vec4(0.0);
        return;
    }
    if (u_rc_frame - e.key.y > u_rc_max_age) {  // least recently used: free it
        atomicCompSwap(rc_entries[i].key.x, e.key.x, 0u);
        rc_irr_out[i] = vec4(0.0);
        return;
    }
    vec4 prev = e.key.z == u_rc_frame ? vec4(0.0) : finite_or_zero(rc_irr[i]);
    vec3 n = normalize(e.nrm.xyz);
    vec3 o = e.pos.xyz + n * (1e-3 * e.pos.w);
    Rng rng = rng_init(uvec2(i, 0x5EC0u), u_seed, 0x2545F491u);
    vec3 sum = vec3(0.0);
    for (int r = 0; r < u_rc_rays; ++r) {
        vec3 d = to_world(sample_cosine_hemisphere(rng_next2(rng)), n);
        SurfaceHit sh;
        if (!scene_trace(o, d, 0.0, T_INF, sh)) continue;
        vec3 kd, N, p;
        vec3 L = bounce_direct(sh, d, rng, kd, N, p);
        if (max3(kd) > 0.0) {
            float s;
            L += kd * rc_irradiance_jittered(p, N, rng_next2(rng), true, s) * INV_PI;
        }
        sum += sanitize(L);
    }
    vec3 E = PI * sum / float(max(u_rc_rays, 1));
    float n_prev = prev.w;
    float a = max(1.0 / (n_prev + 1.0), u_rc_min_blend);
    float lp = luminance(prev.rgb), ln = luminance(E);
    if (n_prev > 0.0 && abs(ln - lp) > u_rc_change_threshold * max(max(lp, ln), 1e-6)) a = max(a, u_rc_fast_blend);
    rc_irr_out[i] = vec4(sanitize(mix(prev.rgb, E, a)), min(n_prev + 1.0, 65535.0));
}
