// grid.comp — per surfel: list it in every cell of the finest cascade holding its centre that
// its sphere overlaps (at most 3 per axis; a full cell drops the surfel there).
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/sampling.glsl"
#include "surfels/common.glsl"

layout(local_size_x = 64) in;

void main() {
    int i = int(gl_GlobalInvocationID.x);
    if (i >= SF_CAPACITY) return;
    vec4 wn = sf_surfels[i].wnrm;
    if (wn.w < 0.5) return;
    vec4 wp = sf_surfels[i].wpos;
    int k = sf_cascade(wp.xyz);
    if (k < 0) return;
    ivec3 lo = sf_cell_of(wp.xyz - vec3(wp.w), k), hi = sf_cell_of(wp.xyz + vec3(wp.w), k);
    hi = min(hi, lo + 2);
    for (int z = lo.z; z <= hi.z; ++z)
        for (int y = lo.y; y <= hi.y; ++y)
            for (int x = lo.x; x <= hi.x; ++x) {
                int ci = sf_cell_index(ivec3(x, y, z), k);
                if (ci < 0) continue;
                uint slot = atomicAdd(sf_cells[ci], 1u);
                if (slot < uint(SF_CELL_CAP)) sf_cells[sf_cell_count() + ci * SF_CELL_CAP + int(slot)] = uint(i);
            }
}
