// ssdo_flux_reduce.comp — one level of SSDO's sender-flux pyramid: r = the sum of the (up to)
// four children's r one level finer (ssdo_flux.comp wrote level 0; a power-of-two image, so
// every texel has its 2x2 children, or 2x1 / 1x2 once one side is down to 1).
layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rg32f) uniform readonly image2D u_fine;
layout(binding = 1, rg32f) uniform writeonly image2D o_coarse;

void main() {
    ivec2 t = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(t, imageSize(o_coarse)))) return;
    ivec2 fs = imageSize(u_fine);
    float s = 0.0;
    for (int k = 0; k < 4; ++k) {
        ivec2 c = 2 * t + ivec2(k & 1, k >> 1);
        if (all(lessThan(c, fs))) s += imageLoad(u_fine, c).r;
    }
    imageStore(o_coarse, t, vec4(s, 0.0, 0.0, 0.0));
}
