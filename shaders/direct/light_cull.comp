// light_cull.comp — DIRECT's per-tile light lists (many lights).
// One work group = one 16x16 pixel tile: the world-space bounds of the tile's G-buffer
// points (background excluded), then every light whose range of influence (a sphere:
// light_ranges[i].xyz centre, .w radius; w < 0 = everywhere: suns) meets the bounds is listed,
// in ascending light order (a bit mask per thread, a prefix sum of their counts: the order,
// hence the shading's random-number use, is deterministic). Lights not listed are not lost:
// direct.comp estimates them with one light sample per pixel (unbiased).
// Output per tile t: tile_lights[t * (cap + 1)] = listed count (<= cap), then the indices;
// tile_bounds[2t] = (min.xyz, pixels with geometry), tile_bounds[2t + 1] = (max.xyz, lights in
// range before the cap).
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"

layout(local_size_x = 16, local_size_y = 16) in;

uniform sampler2D u_gb_position;
uniform int u_capacity;
layout(std430, binding = 4) readonly buffer LightRanges { vec4 light_ranges[]; };
layout(std430, binding = 6) writeonly buffer TileLights { int tile_lights[]; };
layout(std430, binding = 7) writeonly buffer TileBounds { vec4 tile_bounds[]; };

shared vec3 s_lo[256];
shared vec3 s_hi[256];
shared uint s_n[256];
shared uint s_scan[256];

void main() {
    uint lid = gl_LocalInvocationIndex;
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    ivec2 size = textureSize(u_gb_position, 0);
    vec3 lo = vec3(1e30), hi = vec3(-1e30);
    uint n = 0u;
    if (all(lessThan(px, size))) {
        vec4 p = texelFetch(u_gb_position, px, 0);
        if (p.w >= 0.0) { lo = p.xyz; hi = p.xyz; n = 1u; }
    }
    s_lo[lid] = lo; s_hi[lid] = hi; s_n[lid] = n;
    barrier();
    for (uint s = 128u; s > 0u; s >>= 1) {
        if (lid < s) {
            s_lo[lid] = min(s_lo[lid], s_lo[lid + s]);
            s_hi[lid] = max(s_hi[lid], s_hi[lid + s]);
            s_n[lid] += s_n[lid + s];
        }
        barrier();
    }
    lo = s_lo[0]; hi = s_hi[0]; n = s_n[0];
    int tile = int(gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x);
    int base = tile * (u_capacity + 1);
    int total = 0;
    for (int chunk = 0; chunk < u_light_count; chunk += 256 * 32) {
        uint mask = 0u;
        int first = chunk + int(lid) * 32;
        if (n > 0u) {
            for (int b = 0; b < 32; ++b) {
                int i = first + b;
                if (i >= u_light_count) break;
                vec4 r = light_ranges[i];
                vec3 q = clamp(r.xyz, lo, hi);  // nearest point of the tile's box
                vec3 d = r.xyz - q;
                if (r.w < 0.0 || dot(d, d) <= r.w * r.w) mask |= 1u << uint(b);
            }
        }
        uint cnt = uint(bitCount(mask));
        s_scan[lid] = cnt;
        barrier();
        for (uint off = 1u; off < 256u; off <<= 1) {
            uint v = lid >= off ? s_scan[lid - off] : 0u;
            barrier();
            s_scan[lid] += v;
            barrier();
        }
        int pos = total + int(s_scan[lid] - cnt);
        for (int b = 0; b < 32; ++b) {
            if ((mask & (1u << uint(b))) != 0u) {
                if (pos < u_capacity) tile_lights[base + 1 + pos] = first + b;
                ++pos;
            }
        }
        total += int(s_scan[255]);
        barrier();
    }
    if (lid == 0u) {
        tile_lights[base] = min(total, u_capacity);
        tile_bounds[2 * tile] = vec4(lo, float(n));
        tile_bounds[2 * tile + 1] = vec4(hi, float(total));
    }
}
