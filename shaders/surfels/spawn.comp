// spawn.comp — per screen tile (u_sf_tile pixels): the least covered of a few hashed pixels of
// the tile (coverage: the summed weight of the surfels around it, surfels/common.glsl); below
// u_sf_coverage a surfel is spawned there, with probability u_sf_spawn_chance per frame (a
// disocclusion fills over a few frames instead of flooding the pool). The new surfel is taken
// from the free stack, placed on the instance a camera ray meets at that pixel (object space,
// so it follows the instance), with a radius of u_sf_radius_px pixels at its depth (at most its
// cascade's cell side).
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/sampling.glsl"
#include "lib/rng.glsl"
#include "lib/brdf.glsl"
#include "lib/lights.glsl"
#include "lib/scene_rt.glsl"
#include "lib/screen.glsl"
#include "screen_space/common.glsl"
#define SF_LOOKUP 1
#include "surfels/common.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
uniform int u_sf_tile;
uniform float u_sf_coverage;
uniform float u_sf_spawn_chance;
uniform float u_sf_radius_px;

void main() {
    ivec2 t = ivec2(gl_GlobalInvocationID.xy);
    ivec2 lo = t * u_sf_tile;
    if (any(greaterThanEqual(lo, ivec2(u_resolution)))) return;
    ivec2 hi = min(lo + u_sf_tile, ivec2(u_resolution));
    float best = 1e30;
    ivec2 bp = ivec2(-1);
    for (int k = 0; k < 4; ++k) {
        uvec4 h = pcg4d(uvec4(uvec2(t), u_sf_frame, uint(k) + 0x5Fu));
        ivec2 px = lo + ivec2(h.xy % uvec2(max(hi - lo, ivec2(1))));
        GPixel g = fetch_g(px);
        if (!g.valid) continue;
        float cov;
        sf_irradiance(g.P, g.Ng, cov, 0u);
        if (cov < best) { best = cov; bp = px; }
    }
    if (bp.x < 0 || best >= u_sf_coverage) return;
    uvec4 h = pcg4d(uvec4(uvec2(t), u_sf_frame, 0xC0FFEEu));
    if (float(h.w >> 8u) * (1.0 / 16777216.0) >= u_sf_spawn_chance) return;
    GPixel g = fetch_g(bp);
    vec3 o = u_camera_pos;
    vec3 d = g.P - o;
    float dist = length(d);
    SurfaceHit sh;
    float r = sf_spawn_radius(g.P, u_sf_radius_px / pixels_per_unit(view_depth(g.P)));
    if (r <= 0.0 || dist <= 0.0 || !scene_trace(o, d / dist, 0.0, dist * 1.01 + 1e-4, sh) || sh.instance < 0) return;
    int slot = int(atomicAdd(sf_free_count, uint(-1))) - 1;  // pop
    if (slot < 0) {
        atomicAdd(sf_free_count, 1u);  // the pool is empty: give the count back
        return;
    }
    int i = int(sf_free[slot]);
    RtInstance inst = rt_instances[sh.instance];
    vec3 n = g.Ng;
    sf_surfels[i].pos = vec4((inst.world_to_object * vec4(g.P, 1.0)).xyz, r);
    sf_surfels[i].nrm = vec4(normalize(transpose(mat3(inst.object_to_world)) * n), 0.0);
    sf_surfels[i].info = uvec4(uint(sh.instance + 1), u_sf_frame, u_sf_frame, 0u);
    sf_surfels[i].wpos = vec4(g.P, r);
    sf_surfels[i].wnrm = vec4(n, 0.0);  // alive from the next frame's prepare
}
