// light_probe.comp — the light tree and light BVH of lib/light_select.glsl, for
// blender_tests/test_lights.py: per query (p, n, u, ray direction d) the light select_light
// picks and its probability, light_pdf of that light, the sum of light_pdf over every light,
// and the lights a ray crosses (radiance sum and count) through the light BVH and by testing
// every light. Bindings: the SceneRT's (rt.defines / rt.bind), queries at 4, results at 5.
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/sampling.glsl"
#include "lib/rng.glsl"
#include "lib/brdf.glsl"
#include "lib/lights.glsl"
#include "lib/scene_rt.glsl"

layout(local_size_x = 64) in;
struct Query { vec4 p; vec4 n; vec4 d; };  // p.w = u, n.w = 1: use the normal
layout(std430, binding = 4) readonly buffer Queries { Query queries[]; };
layout(std430, binding = 5) writeonly buffer ProbeOut { vec4 probe_out[]; };  // 3 per query
uniform int u_count;

void main() {
    int q = int(gl_GlobalInvocationID.x);
    if (q >= u_count) return;
    Query Q = queries[q];
    vec3 p = Q.p.xyz, n = Q.n.w > 0.5 ? Q.n.xyz : vec3(0.0), d = Q.d.xyz;
    float prob;
    int i = select_light(Q.p.w, p, n, prob);
    float total = 0.0;
    for (int k = 0; k < u_light_count; ++k) total += light_pdf(k, p, n);
    probe_out[3 * q] = vec4(float(i), prob, light_pdf(i, p, n), total);
    vec3 sum = vec3(0.0);
    float cnt = 0.0;
#define PROBE_VISIT(k) {                                                                        \
        vec3 Le_;                                                                               \
        float pdf_;                                                                             \
        if (light_ray_hit(lights[k], p, d, 0.0, T_INF, Le_, pdf_)) { sum += Le_; cnt += 1.0; }  \
    }
    LIGHT_BVH_TRAVERSE(p, d, 0.0, T_INF, PROBE_VISIT)
    probe_out[3 * q + 1] = vec4(sum, cnt);
    sum = vec3(0.0);
    cnt = 0.0;
    for (int k = 0; k < u_light_count; ++k) {
        int type = int(lights[k].pos_type.w + 0.5);
        if (type == LIGHT_SUN) continue;
        PROBE_VISIT(k)
    }
    probe_out[3 * q + 2] = vec4(sum, cnt);
}
