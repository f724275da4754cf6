// trace.comp — one invocation per ray texel of the probes that trace this frame (state 2 or 3,
// screen_probes/place.comp). Rays leave the probe's surface point over its normal's
// hemisphere (screen_probes/common.glsl) through the shared ray tracer. A hit, on either side
// of a surface (a probe sits on a visible surface, outside geometry: a back face is the other
// side of a single-sided plane, which Cycles shades as the front), returns what it reflects
// towards the probe besides the probe's own direct light
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
uniform isampler2D u_sp_src;     // importance sampling: the tile of last frame's probe, -1 new
uniform sampler2D u_prev_sh_r;   // and its SH history
uniform sampler2D u_prev_sh_g;
uniform sampler2D u_prev_sh_b;

void main() {
    ivec2 a = ivec2(gl_GlobalInvocationID.xy);
    ivec2 t = a / u_sp_res, k = a % u_sp_res;
    if (!sp_in_grid(t)) return;
    vec4 pp = texelFetch(u_sp_pos, t, 0);
    if (pp.w < 1.5) return;  // no probe, or kept without a refresh this frame
    vec3 n = normalize(texelFetch(u_sp_nrm, t, 0).xyz);
    if (u_sp_importance != 0) {
        int src = texelFetch(u_sp_src, t, 0).x;
        ivec2 q = ivec2(max(src, 0) % u_sp_grid.x, max(src, 0) / u_sp_grid.x);
        sp_build_cdf(finite_or_zero(texelFetch(u_prev_sh_r, q, 0)), finite_or_zero(texelFetch(u_prev_sh_g, q, 0)),
                     finite_or_zero(texelFetch(u_prev_sh_b, q, 0)), n, src >= 0);
    }
    float pdf;
    vec3 d = sp_ray(t, k.x + k.y * u_sp_res, n, u_sp_frame, pdf);
    float eps = 1e-3 * max(view_depth(pp.xyz), 1e-3);
    vec3 o = pp.xyz + n * eps;
    SurfaceHit sh;
    if (!scene_trace(o, d, 0.0, T_INF, sh)) {
        imageStore(o_atlas, a, vec4(0.0));
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
