// world_probe.comp — the world light of lib/scene_rt.glsl, for blender_tests/test_world.py:
// per query u (2 uniform numbers) world_sample's direction and pdf, world_pdf of that
// direction and world_radiance along it. Bindings: the SceneRT's (rt.defines / rt.bind),
// queries at 4, results at 5.
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/sampling.glsl"
#include "lib/rng.glsl"
#include "lib/brdf.glsl"
#include "lib/lights.glsl"
#include "lib/scene_rt.glsl"

layout(local_size_x = 64) in;
layout(std430, binding = 4) readonly buffer Queries { vec2 queries[]; };
layout(std430, binding = 5) writeonly buffer ProbeOut { vec4 probe_out[]; };  // 2 per query
uniform int u_count;

void main() {
    int q = int(gl_GlobalInvocationID.x);
    if (q >= u_count) return;
    float pdf;
    vec3 d = world_sample(queries[q], pdf);
    probe_out[2 * q] = vec4(d, pdf);
    probe_out[2 * q + 1] = vec4(world_radiance(d), world_pdf(d));
}
