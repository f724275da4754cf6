// hiz.comp — hierarchical depth (Hi-Z) pyramid for screen-space ray marching.
// Paper: Uludag 2014 ("Hi-Z screen-space cone-traced reflections", GPU Pro 5); used by the
// SSR tracer after McGuire & Mara 2014.
// Level 0: the device depth z_ndc of the G-buffer position (the frame's jittered
// view-projection; linear in screen space, so a projected ray interpolates it exactly;
// background = 2, beyond the far plane). Level L: the minimum (nearest) of the 2x2 texels
// of level L-1, plus the third row/column when the finer level has an odd size, so every
// fine texel is covered by the coarse texel that contains it.
#include "lib/common.glsl"
#include "lib/screen.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
#ifdef HIZ_INIT
layout(binding = 1, r32f) uniform writeonly image2D o_dst;
uniform sampler2D u_gb_position;
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(p, imageSize(o_dst)))) return;
    vec4 pos = texelFetch(u_gb_position, p, 0);
    float z = 2.0;
    if (pos.w >= 0.0) {
        vec4 c = to_clip(pos.xyz);
        z = c.w > 1e-7 ? clamp(c.z / c.w, -1.0, 1.0) : -1.0;
    }
    imageStore(o_dst, p, vec4(z));
}
#else
layout(binding = 0, r32f) uniform readonly image2D i_src;
layout(binding = 1, r32f) uniform writeonly image2D o_dst;
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    ivec2 dsize = imageSize(o_dst);
    if (any(greaterThanEqual(p, dsize))) return;
    ivec2 ssize = imageSize(i_src);
    ivec2 lo = 2 * p;
    ivec2 hi = min(2 * p + 1, ssize - 1);
    if (p.x == dsize.x - 1) hi.x = ssize.x - 1;   // odd sizes: the last texel takes the rest
    if (p.y == dsize.y - 1) hi.y = ssize.y - 1;
    float z = 3.0;
    for (int y = lo.y; y <= hi.y; ++y)
        for (int x = lo.x; x <= hi.x; ++x)
            z = min(z, imageLoad(i_src, ivec2(x, y)).r);
    imageStore(o_dst, p, vec4(z));
}
#endif
