// update.comp — per live surfel: u_sf_rays cosine rays from its world position; a hit
// returns its light towards the surfel besides the surfel's own direct light (lib/bounce.glsl)
// plus its diffuse albedo × the surfels' irradiance there / π (last frame's: the later bounces
// build up over frames; the surfels used are marked used as of when this one was last used);
// misses add nothing (the sky seen
// from the surfel is direct light). A hit no surfel covers spawns one there with chance
// u_sf_ray_spawn_chance (at most one per surfel and frame): surfaces the camera does not see
// (behind it, around a corner) get surfels too, and so the later bounces they reflect.
// E = π · mean(L) feeds the estimator (GIBS' multiscale mean estimator, as WickedEngine keeps
// it): a sample above mean + 8σ is clamped (fireflies; from the 32nd sample on), then the mean moves by
// max(1/n, u_sf_mean_blend) and the variance by max(1/n, u_sf_var_blend). The rays' distances
// update the depth moments of the hemi-octahedral texels they fall in (weight u_sf_moment_blend,
// the first sample taken whole).
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
#define SF_LOOKUP 1
#include "surfels/common.glsl"

layout(local_size_x = 64) in;
layout(std430, binding = SF_BINDING_STATE_OUT) writeonly buffer SfStateOut { vec4 sf_state_out[]; };
uniform int u_sf_rays;
uniform uint u_sf_max_age;
uniform float u_sf_mean_blend;
uniform float u_sf_var_blend;
uniform float u_sf_moment_blend;
uniform uint u_seed;
uniform float u_sf_ray_spawn_chance;
uniform float u_sf_radius_px;

// A new surfel at a ray's hit (object space of its instance), sized as a screen spawn at that
// distance from the camera.
void sf_spawn_at(vec3 p, vec3 n, int instance) {
    float r = sf_spawn_radius(p, u_sf_radius_px / pixels_per_unit(max(distance(p, u_camera_pos), 1e-4)));
    if (instance < 0 || r <= 0.0) return;
    int slot = int(atomicAdd(sf_free_count, uint(-1))) - 1;  // pop (no pass pushes in this one)
    if (slot < 0) {
        atomicAdd(sf_free_count, 1u);
        return;
    }
    int j = int(sf_free[slot]);
    RtInstance inst = rt_instances[instance];
    sf_surfels[j].pos = vec4((inst.world_to_object * vec4(p, 1.0)).xyz, r);
    sf_surfels[j].nrm = vec4(normalize(transpose(mat3(inst.object_to_world)) * n), 0.0);
    sf_surfels[j].info = uvec4(uint(instance + 1), u_sf_frame, u_sf_frame, 0u);
    sf_surfels[j].wpos = vec4(p, r);
    sf_surfels[j].wnrm = vec4(n, 0.0);
}

void main() {
    int i = int(gl_GlobalInvocationID.x);
    if (i >= SF_CAPACITY) return;
    SfSurfel s = sf_surfels[i];
    bool fresh = s.info.z == u_sf_frame;  // made this frame: last frame's state is another surfel's
    if (s.info.x == 0u) {
        for (int k = 0; k < SF_STATE; ++k) sf_state_out[i * SF_STATE + k] = vec4(0.0);
        return;
    }
    vec4 st[SF_STATE];
    for (int k = 0; k < SF_STATE; ++k) st[k] = fresh ? vec4(0.0) : finite_or_zero(sf_state[i * SF_STATE + k]);
    vec3 n = normalize(s.wnrm.xyz), p0 = s.wpos.xyz;
    float r = s.wpos.w;
    vec3 o = p0 + n * (1e-3 * max(r, 1e-4));
    Rng rng = rng_init(uvec2(i, 0x5F5Fu), u_seed, 0x68E31DA4u);
    vec3 sum = vec3(0.0);
    bool spawned = false;
    vec2 msum[SF_MOMENTS * SF_MOMENTS];
    float mcnt[SF_MOMENTS * SF_MOMENTS];
    for (int k = 0; k < SF_MOMENTS * SF_MOMENTS; ++k) { msum[k] = vec2(0.0); mcnt[k] = 0.0; }
    for (int k = 0; k < u_sf_rays; ++k) {
        vec3 d = to_world(sample_cosine_hemisphere(rng_next2(rng)), n);
        SurfaceHit sh;
        float t = 1e4 * max(r, 1e-4);
        if (scene_trace(o, d, 0.0, T_INF, sh)) {
            t = sh.t;
            vec3 kd, N, p;
            vec3 L = bounce_direct(sh, d, rng, kd, N, p);
            float cov;
            vec3 Es = sf_irradiance(p, N, cov, s.info.y);  // (marks the surfels it uses)
            if (max3(kd) > 0.0) L += kd * Es * INV_PI;
            if (cov <= 0.0 && !spawned && rng_next(rng) < u_sf_ray_spawn_chance) {
                spawned = true;  // an uncovered hit, maybe off screen: a surfel there
                sf_spawn_at(p, N, sh.instance);
            }
            sum += sanitize(L);
        }
        int tx = sf_moment_texel(d, n);
        msum[tx] += vec2(t, t * t);
        mcnt[tx] += 1.0;
    }
    vec3 x = PI * sum / float(max(u_sf_rays, 1));
    float nprev = st[0].w, nn = nprev + 1.0;
    // fireflies: only once the variance has a settled estimate (a clamp on a few samples' variance
    // cuts the rare bright rays of a dim room and darkens it: two rooms 0.82 of Cycles with it
    // from the 5th sample, 1.07 without)
    if (nprev >= 32.0) x = min(x, st[0].rgb + 8.0 * sqrt(max(st[1].rgb, vec3(0.0))));
    float am = max(1.0 / nn, u_sf_mean_blend), av = max(1.0 / nn, u_sf_var_blend);
    st[1].rgb = mix(st[1].rgb, (x - st[0].rgb) * (x - st[0].rgb), av);
    vec3 mean = mix(st[0].rgb, x, am);
    st[0] = vec4(mean, min(nn, 65535.0));
    st[2].rgb = mix(st[2].rgb, x, max(1.0 / nn, 2.0 * u_sf_mean_blend));
    for (int k = 0; k < SF_MOMENTS * SF_MOMENTS; ++k) {
        if (mcnt[k] <= 0.0) continue;
        vec2 m = msum[k] / mcnt[k];
        vec4 v = st[3 + k / 2];
        vec2 old = (k & 1) == 0 ? v.xy : v.zw;
        vec2 nw = old.x > 0.0 ? mix(old, m, u_sf_moment_blend) : m;
        if ((k & 1) == 0) st[3 + k / 2].xy = nw; else st[3 + k / 2].zw = nw;
    }
    for (int k = 0; k < SF_STATE; ++k) sf_state_out[i * SF_STATE + k] = st[k];
}
