// prepare.comp — per surfel, first of the surfel passes each frame. u_stage 0 (after a reset):
// every surfel free, the free stack full. u_stage 1: a surfel unused for u_sf_max_age frames
// (info.y: surfels/common.glsl sf_irradiance's marks) is recycled (pushed back on the free stack: this is the only
// pass that pushes, the spawns only pop); each live surfel's world position and normal from its
// instance's transform this frame (surfels on moving objects move with them); the grid's cell
// counts cleared.
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/sampling.glsl"
#include "lib/bvh.glsl"
#include "surfels/common.glsl"

layout(local_size_x = 64) in;
uniform int u_stage;
uniform uint u_sf_max_age;

void main() {
    int i = int(gl_GlobalInvocationID.x);
    if (u_stage == 0) {
        if (i < SF_CAPACITY) {
            sf_free[i] = uint(SF_CAPACITY - 1 - i);
            sf_surfels[i].info = uvec4(0u);
            sf_surfels[i].wnrm = vec4(0.0);
        }
        if (i == 0) sf_free_count = uint(SF_CAPACITY);
        return;
    }
    if (i < sf_cell_count()) sf_cells[i] = 0u;
    if (i >= SF_CAPACITY) return;
    SfSurfel s = sf_surfels[i];
    if (s.info.x != 0u && s.info.z != u_sf_frame - 1u && u_sf_frame - s.info.y > u_sf_max_age) {
        sf_surfels[i].info.x = 0u;  // unused for u_sf_max_age frames: recycled
        uint slot = atomicAdd(sf_free_count, 1u);
        sf_free[slot] = uint(i);
        s.info.x = 0u;
    }
    if (s.info.x == 0u) {
        sf_surfels[i].wnrm = vec4(0.0);
        return;
    }
    RtInstance inst = rt_instances[int(s.info.x) - 1];
    vec3 p = (inst.object_to_world * vec4(s.pos.xyz, 1.0)).xyz;
    vec3 n = normalize(transpose(mat3(inst.world_to_object)) * s.nrm.xyz);
    sf_surfels[i].wpos = vec4(p, s.pos.w);
    sf_surfels[i].wnrm = vec4(n, 1.0);
}
