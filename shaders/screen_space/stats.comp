// stats.comp — per-pixel terms of the screen's ambient estimate (reduced by mipmapping).
// Paper: Cohen et al. 1988 (progressive radiosity's ambient term), applied to the screen.
// Writes, for each pixel on geometry (g = 1, background g = 0):
//   stats0 = (direct-lit outgoing radiance * g, g)
//   stats1 = (diffuse albedo luminance * g, (1 - AO) * g, 0, 0)
// so that the top mip level gives the screen means the composite's constant indirect term
// uses: mean radiance B, mean albedo rho and mean enclosure e within the AO radius.
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/rng.glsl"
#include "lib/sampling.glsl"
#include "lib/brdf.glsl"
#include "lib/screen.glsl"
#include "screen_space/common.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform writeonly image2D o_stats0;
layout(binding = 1, rgba32f) uniform writeonly image2D o_stats1;
uniform sampler2D u_radiance;
uniform sampler2D u_ao;

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(px, imageSize(o_stats0)))) return;
    GPixel g = fetch_g(px);
    if (!g.valid) {
        imageStore(o_stats0, px, vec4(0.0));
        imageStore(o_stats1, px, vec4(0.0));
        return;
    }
    Surface s = fetch_surface(px, g.mid);
    float NoV = max(dot(g.N, view_dir(g.P)), 1e-4);
    vec3 B = sanitize(texelFetch(u_radiance, px, 0).rgb);
    float ao = clamp(texelFetch(u_ao, px, 0).r, 0.0, 1.0);
    imageStore(o_stats0, px, vec4(B, 1.0));
    imageStore(o_stats1, px, vec4(luminance(diffuse_albedo(s, NoV)), 1.0 - ao, 0.0, 0.0));
}
