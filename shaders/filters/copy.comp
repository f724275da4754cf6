// copy.comp — o_out = u_in (a filter's result written back into the frame's colour).
#include "lib/common.glsl"
layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform writeonly image2D o_out;
uniform sampler2D u_in;
void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(px, textureSize(u_in, 0)))) return;
    vec4 v = texelFetch(u_in, px, 0);
#ifdef KEEP_ALPHA
    imageStore(o_out, px, vec4(sanitize(v.rgb), isnan(v.a) || isinf(v.a) ? 0.0 : v.a));
#else
    imageStore(o_out, px, vec4(sanitize(v.rgb), 1.0));
#endif
}
