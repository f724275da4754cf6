// lpv_gv_rays.comp — the geometry volume's blockers from the scene's triangles (passes/lpv.py,
// parameter geometry_rays): what neither a light's RSM nor the camera sees still blocks.
// For every cell (i, j, k) of every cascade and axis a, the staggered cell between the centres
// of (i, j, k) and (i, j, k) + e_a (lpv_common.glsl) is probed by RAYS x RAYS rays parallel to
// e_a from the first centre's face plane to the second (offsets spread over the face, lib/bvh.glsl,
// closest hit): B_ray = the share of rays that hit a triangle, D_ray = the mean hit position along
// the axis (cell units). The staggered cell keeps the surfels' values unless the rays block
// more (B = max), in which case it takes the rays' B and depth (the surfels' blockers and the
// triangles describe the same walls; the rays also see the walls nobody renders).
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/bvh.glsl"
#include "raster3d/lpv_common.glsl"
layout(local_size_x = 4, local_size_y = 4, local_size_z = 4) in;
layout(binding = 0, rgba32f) uniform image2DArray io_gv;   // per axis: blocking
layout(binding = 1, rgba32f) uniform image2DArray io_gvd;  // per axis: blocking x position (cell units)
#ifndef RAYS
#define RAYS 2
#endif

void main() {
    ivec3 id = ivec3(gl_GlobalInvocationID);
    if (any(greaterThanEqual(id, ivec3(u_grid, u_grid, u_grid * u_cascades)))) return;
    int c = id.z / u_grid;
    ivec3 cell = ivec3(id.xy, id.z - c * u_grid);
    float cs = u_lpv_origin[c].w;
    vec3 corner = u_lpv_origin[c].xyz;
    vec4 B = imageLoad(io_gv, id);
    vec4 BD = imageLoad(io_gvd, id);
    for (int a = 0; a < 3; ++a) {
        if (cell[a] + 1 >= u_grid) continue;  // no neighbour along +a
        vec3 dir = vec3(0.0);
        dir[a] = 1.0;
        int u = (a + 1) % 3, v = (a + 2) % 3;
        float hits = 0.0, pos = 0.0;
        for (int s = 0; s < RAYS; ++s) {
            for (int t = 0; t < RAYS; ++t) {
                vec3 g = vec3(cell) + 0.5;  // the first centre, cell units
                g[u] += (float(s) + 0.5) / float(RAYS) - 0.5;
                g[v] += (float(t) + 0.5) / float(RAYS) - 0.5;
                vec3 o = corner + g * cs;
                RtHit h = rt_miss();
                if (rt_trace_closest(o, dir, 0.0, cs, h)) {
                    hits += 1.0;
                    pos += g[a] + h.t / cs;
                }
            }
        }
        float n = float(RAYS * RAYS);
        float b = hits / n;
        if (b > B[a]) {
            B[a] = b;
            BD[a] = pos / n;  // = b x the mean hit position
        }
    }
    imageStore(io_gv, id, B);
    imageStore(io_gvd, id, BD);
}
