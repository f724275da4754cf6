// rt_probe.comp — a compute pass that is not PT tracing rays through the shared scene
// component (lib/scene_rt.glsl), for blender_tests/test_shared_rt.py: per ray, the surface
// interaction (distance, normals, uv, material, textured base colour), the any-hit query,
// the light-selection table and shade_direct (mean and second moment over u_samples
// independent light samples). Bindings: the SceneRT's (rt.defines / rt.bind) plus rays at 4
// and results at 5.
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/sampling.glsl"
#include "lib/rng.glsl"
#include "lib/brdf.glsl"
#include "lib/lights.glsl"
#include "lib/scene_rt.glsl"

layout(local_size_x = 64) in;
struct ProbeRay { vec4 o; vec4 d; };  // o.w = tmin, d.w = tmax
layout(std430, binding = 4) readonly buffer ProbeRays { ProbeRay probe_rays[]; };
layout(std430, binding = 5) writeonly buffer ProbeOut { vec4 probe_out[]; };  // 6 per ray
uniform int u_count;
uniform int u_samples;

void main() {
    int i = int(gl_GlobalInvocationID.x);
    if (i >= u_count) return;
    ProbeRay r = probe_rays[i];
    SurfaceHit s;
    bool hit = scene_trace(r.o.xyz, r.d.xyz, r.o.w, r.d.w, s);
    int base = 6 * i;
    probe_out[base + 0] = vec4(hit ? s.t : -1.0, float(hit ? s.material : -1), float(s.instance),
                               float(hit ? s.triangle : -1));
    probe_out[base + 1] = vec4(hit ? s.geo_normal : vec3(0.0), hit ? 1.0 : 0.0);
    probe_out[base + 2] = vec4(hit ? s.normal : vec3(0.0), hit ? s.uv.x : 0.0);
    probe_out[base + 3] = vec4(hit ? s.bsdf.base_color : vec3(0.0), hit ? s.uv.y : 0.0);
    vec3 m = vec3(0.0);
    float m2 = 0.0;
    if (hit) {
        for (int k = 0; k < u_samples; ++k) {
            Rng rng = rng_init(uvec2(uint(i), 7u), uint(k), 3u);
            vec3 c = shade_direct(s, -r.d.xyz, rng);
            m += c;
            m2 += sqr(luminance(c));
        }
        m /= float(max(u_samples, 1));
        m2 /= float(max(u_samples, 1));
    }
    probe_out[base + 4] = vec4(m, m2);
    float sel;
    int li = u_light_count > 0 ? select_light((float(i) + 0.5) / float(u_count), sel) : -1;
    probe_out[base + 5] = vec4(scene_occluded(r.o.xyz, r.d.xyz, r.o.w, r.d.w) ? 1.0 : 0.0,
                               u_light_count > 0 ? light_pdf(i % u_light_count) : 0.0, float(li), sel);
}
