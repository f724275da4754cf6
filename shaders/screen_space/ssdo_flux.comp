// ssdo_flux.comp — SSDO's sender importance, level 0, at the SSDO pass's own resolution
// (u_out_size; ssdo_flux.glsl): per texel the flux its block of full-resolution G-buffer pixels
// sends (r: the sum over the block of the luminance of the pixel's direct-lit radiance
// aov.direct times its diffuse share fd times its world area, the area's 1/cos capped at 5)
// and the block's pixel count (g), in a power-of-two image (texels outside the pass and
// background pixels are 0). ssdo_flux_reduce.comp sums r into the coarser levels; ssdo.comp
// descends the levels to pick senders in proportion to r (importance sampling of bright
// senders, e.g. a small sun patch; see ssdo.comp).
#include "lib/common.glsl"
#include "lib/rng.glsl"
#include "lib/sampling.glsl"
#include "lib/brdf.glsl"
#include "lib/screen.glsl"
#include "screen_space/common.glsl"
#include "screen_space/ssdo_flux.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rg32f) uniform writeonly image2D o_flux;

uniform sampler2D u_radiance;  // aov.direct
uniform sampler2D u_trust;     // (fd, sigma) per pixel (ssdo_trust.comp)
uniform ivec2 u_out_size;      // the SSDO pass's resolution (level 0's texels that hold blocks)

void main() {
    ivec2 t = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(t, imageSize(o_flux)))) return;
    vec2 v = vec2(0.0);
    if (all(lessThan(t, u_out_size))) {
        ivec2 lo, hi;
        flux_block_range(t, u_out_size, lo, hi);
        for (int y = lo.y; y < hi.y; ++y)
            for (int x = lo.x; x < hi.x; ++x) {
                ivec2 px = ivec2(x, y);
                GPixel g = fetch_g(px);
                if (g.valid) {
                    float foot = 1.0 / pixels_per_unit(view_depth(g.P));
                    float c = abs(dot(g.N, view_dir(g.P)));
                    float L = luminance(texelFetch(u_radiance, px, 0).rgb) * texelFetch(u_trust, px, 0).r;
                    v.x += max(L, 0.0) * foot * foot / max(c, 0.2);
                }
            }
        v.y = float((hi.x - lo.x) * (hi.y - lo.y));
    }
    imageStore(o_flux, t, vec4(v, 0.0, 0.0));
}
