// lpv_debug.comp — GI_LPV_Slice: one horizontal slice of a cascade's accumulated light
// volume (slab A_c) stretched over the frame, as the mean radiance of each cell,
// c0 · Y00 / cell² (W m⁻² sr⁻¹: the SH's average over the sphere). The slice is the
// layer of cascade u_debug_cascade at height u_debug_height (fraction of the grid).
#include "lib/sh.glsl"
#include "raster3d/lpv_common.glsl"
layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform writeonly image2D o_out;
uniform sampler2DArray u_lpv_r;
uniform sampler2DArray u_lpv_g;
uniform sampler2DArray u_lpv_b;
uniform int u_debug_cascade;
uniform float u_debug_height;
void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    ivec2 size = imageSize(o_out);
    if (any(greaterThanEqual(px, size))) return;
    int c = clamp(u_debug_cascade, 0, u_cascades - 1);
    float cs = u_lpv_origin[c].w;
    ivec2 cell = min(ivec2((vec2(px) + 0.5) / vec2(size) * float(u_grid)), ivec2(u_grid - 1));
    int z = clamp(int(u_debug_height * float(u_grid)), 0, u_grid - 1);
    ivec3 tc = ivec3(cell, z + lpv_slab_all(c) * u_grid);
    vec3 L = vec3(texelFetch(u_lpv_r, tc, 0).x, texelFetch(u_lpv_g, tc, 0).x, texelFetch(u_lpv_b, tc, 0).x)
             * SH_Y00 / (cs * cs);
    imageStore(o_out, px, vec4(max(L, vec3(0.0)), 1.0));
}
