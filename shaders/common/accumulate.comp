// accumulate.comp — running mean of a frame output into its accumulator:
// acc = acc + (new - acc) * weight, weight = 1 / (n + 1). Non-finite inputs are dropped.
#include "lib/common.glsl"
layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform image2D io_acc;
uniform sampler2D u_input;
uniform float u_weight;
uniform int u_coverage;  // 1: the input is the G-buffer's position; accumulate 1 where w >= 0 (a surface)
void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(px, imageSize(io_acc)))) return;
    vec4 v = texelFetch(u_input, px, 0);
    if (u_coverage != 0) v = vec4(v.w >= 0.0 ? 1.0 : 0.0);
    v.rgb = sanitize(v.rgb);
    vec4 acc = u_weight >= 1.0 ? v : imageLoad(io_acc, px);
    imageStore(io_acc, px, acc + (v - acc) * u_weight);
}
