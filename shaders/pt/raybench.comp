// raybench.comp — ray throughput of lib/bvh.glsl for scripts/bench_rt.py (not used by PT).
// u_mode 0: primary rays from the camera (closest hit), writes hit position + normal;
//        1: shadow rays (any hit) from each primary hit to a point light;
//        2: diffuse-bounce rays (closest hit) from each primary hit, cosine-distributed.
// Rays of modes 1 and 2 start only at pixels whose primary ray hit; u_count_out counts rays.
#include "lib/common.glsl"
#include "lib/sampling.glsl"
#include "lib/rng.glsl"
#include "lib/bvh.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(std430, binding = 0) buffer Hits { vec4 hit_pos[]; };  // xyz position, w = 1 hit / 0 miss
layout(std430, binding = 1) buffer Norms { vec4 hit_n[]; };
layout(std430, binding = 2) buffer Out { uint checksum[]; };
uniform mat4 u_cam_to_world;
uniform mat4 u_inv_proj;
uniform ivec2 u_size;
uniform int u_mode;
uniform vec3 u_light;
uniform uint u_seed;

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (px.x >= u_size.x || px.y >= u_size.y) return;
    int idx = px.y * u_size.x + px.x;
    Rng rng = rng_init(uvec2(px), 0u, u_seed);
    if (u_mode == 0) {
        vec2 ndc = (vec2(px) + 0.5) / vec2(u_size) * 2.0 - 1.0;
        vec4 v = u_inv_proj * vec4(ndc, 1.0, 1.0);
        vec3 d = normalize(mat3(u_cam_to_world) * normalize(v.xyz / v.w));
        vec3 o = u_cam_to_world[3].xyz;
        RtHit h = rt_miss();
        if (rt_trace_closest(o, d, 0.0, 1e30, h)) {
            RtSurface s = rt_surface(h);
            vec3 n = dot(s.geo_normal, d) < 0.0 ? s.geo_normal : -s.geo_normal;
            hit_pos[idx] = vec4(rt_offset_ray(s.position, n), 1.0);
            hit_n[idx] = vec4(n, 0.0);
        } else {
            hit_pos[idx] = vec4(0.0);
            hit_n[idx] = vec4(0.0);
        }
        return;
    }
    vec4 p = hit_pos[idx];
    if (p.w < 0.5) return;
    vec3 n = hit_n[idx].xyz;
    if (u_mode == 1) {
        vec3 to = u_light - p.xyz;
        float dist = length(to);
        bool blocked = rt_trace_any(p.xyz, to / dist, 0.0, dist);
        if (blocked) atomicAdd(checksum[0], 1u);
    } else {
        vec3 d = to_world(sample_cosine_hemisphere(rng_next2(rng)), n);
        RtHit h = rt_miss();
        if (rt_trace_closest(p.xyz, d, 0.0, 1e30, h)) atomicAdd(checksum[1], 1u);
    }
}
