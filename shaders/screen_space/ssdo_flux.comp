// ssdo_flux.comp — SSDO's sender importance, level 0: per full-resolution G-buffer pixel the
// flux it sends (r: luminance of its direct-lit radiance aov.direct times its diffuse share fd
// times its world area, the area's 1/cos capped at 5) and its world area (g: the pixel's
// footprint (1 / pixels_per_unit)^2 / cos, the 1/cos capped at 20), in a power-of-two image
// (texels outside the frame and background pixels are 0). ssdo_flux_reduce.comp sums it into
// the coarser levels; ssdo.comp descends the levels to pick senders in proportion to r
// (importance sampling of bright senders, e.g. a small sun patch; see ssdo.comp).
#include "lib/common.glsl"
#include "lib/rng.glsl"
#include "lib/sampling.glsl"
#include "lib/brdf.glsl"
#include "lib/screen.glsl"
#include "screen_space/common.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rg32f) uniform writeonly image2D o_flux;

uniform sampler2D u_radiance;  // aov.direct
uniform sampler2D u_trust;     // (fd, sigma) per pixel (ssdo_trust.comp)

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(px, imageSize(o_flux)))) return;
    vec2 v = vec2(0.0);
    if (all(lessThan(px, ivec2(u_resolution)))) {
        GPixel g = fetch_g(px);
        if (g.valid) {
            float foot = 1.0 / pixels_per_unit(view_depth(g.P));
            float c = abs(dot(g.N, view_dir(g.P)));
            float L = luminance(texelFetch(u_radiance, px, 0).rgb) * texelFetch(u_trust, px, 0).r;
            v = vec2(max(L, 0.0) * foot * foot / max(c, 0.2), foot * foot / max(c, 0.05));
        }
    }
    imageStore(o_flux, px, vec4(v, 0.0, 0.0));
}
