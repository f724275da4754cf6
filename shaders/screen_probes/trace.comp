// trace.comp — one invocation per ray texel of the probes that trace this frame (state 2 or 3,
// screen_probes/place.comp). Rays leave the probe's surface point over its normal's
// hemisphere (screen_probes/common.glsl) through the shared ray tracer. A front-face hit
// returns what it reflects towards the probe besides the probe's own direct light
// (lib/bounce.glsl) plus its diffuse albedo × the world radiance cache's irradiance there / π
// (radiance_cache/common.glsl, looked up jittered and requested when missing): the second and
// later bounces. A miss returns nothing (the world seen from the probe is direct light).
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/sampling.glsl"
#include "lib/rng.glsl"
#include "lib/brdf.glsl"
#include "lib/lights.glsl"
#include "lib/scene_rt.glsl"
#include "lib/albedo.glsl"
#include "lib/bounce.glsl"
#include "lib/screen.glsl"
#include "radiance_cache/common.glsl"
#include "screen_probes/common.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform writeonly image2D o_atlas;
uniform sampler2D u_sp_pos;
uniform sampler2D u_sp_nrm;
uniform int u_cache;   // 1: the world cache gives the later bounces

void main() {
    ivec2 a = ivec2(gl_GlobalInvocationID.xy);
    ivec2 t = a / u_sp_res, k = a % u_sp_res;
    if (!sp_in_grid(t)) return;
    vec4 pp = texelFetch(u_sp_pos, t, 0);
    if (pp.w < 1.5) return;  // no probe, or kept without a refresh this frame
    vec3 n = normalize(texelFetch(u_sp_nrm, t, 0).xyz);
    vec3 d = sp_ray_dir(t, k, n, u_sp_frame);
    float eps = 1e-3 * max(view_depth(pp.xyz), 1e-3);
    vec3 o = pp.xyz + n * eps;
    SurfaceHit sh;
    if (!scene_trace(o, d, 0.0, T_INF, sh)) {
        imageStore(o_atlas, a, vec4(0.0));
        return;
    }
    if (dot(sh.geo_normal, d) > 0.0) {
        imageStore(o_atlas, a, vec4(0.0, 0.0, 0.0, -sh.t));
        return;
    }
    Rng rng = rng_init(uvec2(a), u_sp_frame, 0x7F4A7C15u);
    vec3 kd, N, p;
    vec3 L = bounce_direct(sh, d, rng, kd, N, p);
    if (u_cache != 0 && max3(kd) > 0.0) {
        float s;
        L += kd * rc_irradiance_jittered(p, N, rng_next2(rng), true, s) * INV_PI;
    }
    imageStore(o_atlas, a, vec4(sanitize(L), sh.t));
}
