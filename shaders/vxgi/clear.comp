// clear.comp — zeroes the records of the voxels the last voxelisation occupied (its list),
// before the scene is voxelised again: the other records are zero already, so this costs
// the occupied voxels only, not the whole grid.
#include "lib/common.glsl"
#include "vxgi/common.glsl"

layout(local_size_x = 256) in;
layout(std430, binding = VX_BINDING_RECORDS) buffer VoxelRecords { uint vx_rec[]; };
layout(std430, binding = VX_BINDING_LIST) readonly buffer VoxelList { uint vx_list[]; };

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= vx_list[0]) return;
    uint base = vx_list[1u + i] * uint(VX_REC);
    for (uint k = 0u; k < uint(VX_REC); ++k) vx_rec[base + k] = 0u;
}
