// ssdo_trace.comp — SSDO's off-screen directions traced through the scene, one invocation per
// tile of u_world_tile^2 pixels (ssdo.comp picked the tile's tracer and wrote its ray). A
// pass of its own so that the rays run side by side (one ray per SIMD lane) and the ray
// tracer's code is not in ssdo.comp: on llvmpipe the per-pixel pass ran it, masked off, for
// every group of pixels (sunlit_room 96 px q1: the ssdo pass 12.3 ms with the tracer's code,
// 8.2 ms without; docs/techniques/SSDO.md).
// In:  u_ray_o (rgba32f: origin, tracer pixel x + 65536 y), u_ray_d (rgba32f: direction, 1 = traced).
// Out: o_tile_L (rgba16f: the diffuse radiance the hit sends back along the ray, 0 for a miss;
//      a = 1 when traced).
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/rng.glsl"
#include "lib/sampling.glsl"
#include "lib/brdf.glsl"
#include "lib/lights.glsl"
#include "lib/scene_rt.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 1, rgba32f) uniform readonly image2D u_ray_o;
layout(binding = 2, rgba32f) uniform readonly image2D u_ray_d;
layout(binding = 3, rgba16f) uniform writeonly image2D o_tile_L;

uniform uint u_sample;
uniform ivec2 u_tiles;
uniform float u_world_distance;

// A direction screen space cannot answer, traced with the shared ray tracer: true with the
// diffuse radiance the surface it hits sends back along it (next-event estimation at the
// hit, lib/scene_rt.glsl's shade_direct_at: one light, one shadow ray), false = open (the
// world, which DIRECT already lights with). Diffuse only, as for on-screen senders
// (view_trust): a glossy hit's light toward the receiver is a caustic path, which one light
// sample per ray turns into fireflies (glossy_spheres q2: relMSE 0.037 -> 0.080 with it). The
// surface is made diffuse-only (lib/brdf.glsl surface_diffuse_only).
bool world_sender(vec3 O, vec3 dir, inout Rng rng, out vec3 L) {
    SurfaceHit s;
    L = vec3(0.0);
    if (!scene_trace(O, dir, 0.0, u_world_distance, s)) return false;
    vec3 V = -dir, Nh, Ngh, ph;
    surface_frame(s, V, Nh, Ngh, ph);
    Surface d = surface_diffuse_only(s.bsdf, max(dot(Nh, V), 1e-4));
    L = shade_direct_at(d, ph, Nh, Ngh, V, rng, false);
    return true;
}

void main() {
    ivec2 t = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(t, u_tiles))) return;
    vec4 o = imageLoad(u_ray_o, t);
    vec4 d = imageLoad(u_ray_d, t);
    vec4 res = vec4(0.0);
    if (d.w > 0.5) {
        int code = int(o.w + 0.5);
        ivec2 px = ivec2(code % 65536, code / 65536);
        Rng rng = rng_init(uvec2(px), u_sample, 29u);
        vec3 L;
        res = vec4(world_sender(o.xyz, d.xyz, rng, L) ? L : vec3(0.0), 1.0);
    }
    imageStore(o_tile_L, t, res);
}
