// trace.comp — probe rays (IRRADIANCE_VOLUME, DDGI, RTXGI): one invocation per (ray, probe).
// Rays leave each probe (lattice point + relocation offset) through the shared ray tracer
// (lib/scene_rt.glsl). A front-face hit returns the light it reflects towards the probe
// *other than* what DIRECT already computes at the receivers: direct light at the hit
// (shade_direct: one light by power, a shadow ray), the world's light at the hit (one cosine
// ray, unoccluded -> diffuse albedo x world radiance), and last frame's probe irradiance at
// the hit times the diffuse albedo / pi (infinite bounces over frames). Lights, emissive
// surfaces and the world seen *directly* by a probe are left out: DIRECT lights the receivers
// with them exactly, so the probes carry indirect light only.
// Output texel (ray, probe slot): rgb radiance, a = hit distance (negative: a back face was hit,
// i.e. the probe looks at the inside of geometry; 1e27: miss).
// RTXGI: an inactive probe traces only its fixed rays (to be reactivated when it sees geometry).
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/sampling.glsl"
#include "lib/rng.glsl"
#include "lib/brdf.glsl"
#include "lib/lights.glsl"
#include "lib/scene_rt.glsl"
#include "lib/albedo.glsl"
#include "lib/bounce.glsl"
#define PROBE_LOOKUP 1
#include "probes/common.glsl"

layout(local_size_x = 32, local_size_y = 1) in;
layout(binding = 0, rgba32f) uniform writeonly image2D o_rays;

uniform uint u_seed;
uniform int u_bounce;        // 1: add last frame's probe irradiance at hits (infinite bounces)

void main() {
    int r = int(gl_GlobalInvocationID.x);
    int pi = int(gl_GlobalInvocationID.y);
    if (r >= u_rays || pi >= probe_count()) return;
    ivec3 s = slot_from_index(pi);
    ivec3 a = cell_of_slot(s, u_probe_cell0);
    vec4 st = slot_is_new(s) ? vec4(0.0) : finite_or_zero(texelFetch(u_probe_state, slot_tile(s), 0));
    if (st.w > 0.5 && r >= u_fixed_rays) {
        imageStore(o_rays, ivec2(r, pi), vec4(0.0, 0.0, 0.0, 1e27));
        return;
    }
    vec3 o = cell_position(a) + st.xyz;
    vec3 d = probe_ray_dir(r);
    SurfaceHit sh;
    if (!scene_trace(o, d, 0.0, T_INF, sh)) {
        imageStore(o_rays, ivec2(r, pi), vec4(0.0, 0.0, 0.0, 1e27));
        return;
    }
    if (dot(sh.geo_normal, d) > 0.0) {  // back face: inside geometry, reflects nothing here
        imageStore(o_rays, ivec2(r, pi), vec4(0.0, 0.0, 0.0, -sh.t));
        return;
    }
    Rng rng = rng_init(uvec2(r, pi), u_seed, 0x9e3779b9u);
    vec3 kd, N, p;
    vec3 L = bounce_direct(sh, d, rng, kd, N, p);
    if (u_bounce != 0 && max3(kd) > 0.0) {
        float w;
        vec3 E = probe_irradiance(sh.position, N, -d, w);
        L += kd * E * (1.0 / PI);
    }
    imageStore(o_rays, ivec2(r, pi), vec4(sanitize(L), sh.t));
}
