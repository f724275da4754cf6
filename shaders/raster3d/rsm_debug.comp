// rsm_debug.comp — debug view GI_RSM_Flux: the RSM flux atlas stretched over the frame
// (reflected flux per texel times the texels of one view, W; every light's views as tiles).
layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform writeonly image2D o_out;
uniform sampler2D u_rsm_flux;
uniform float u_scale;  // texels of one view
void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    ivec2 size = imageSize(o_out);
    if (any(greaterThanEqual(px, size))) return;
    ivec2 asz = textureSize(u_rsm_flux, 0);
    ivec2 t = min(ivec2((vec2(px) + 0.5) / vec2(size) * vec2(asz)), asz - 1);
    imageStore(o_out, px, vec4(max(texelFetch(u_rsm_flux, t, 0).rgb * u_scale, vec3(0.0)), 1.0));
}
