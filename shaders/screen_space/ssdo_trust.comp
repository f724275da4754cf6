// ssdo_trust.comp — the per-pixel half of view_trust (common.glsl) for SSDO's senders:
// rg = (diffuse share fd of the pixel's radiance toward the camera, glossy lobe width
// sigma), at full resolution (senders are G-buffer pixels). SSDO reads it once per
// sample instead of evaluating the albedo tables there (8-32 times per receiver).
// Background pixels: (1, 1) (never read: they are not senders).
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/rng.glsl"
#include "lib/sampling.glsl"
#include "lib/brdf.glsl"
#include "lib/screen.glsl"
#include "screen_space/common.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 1, rg16f) uniform writeonly image2D o_trust;

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(px, ivec2(u_resolution)))) return;
    GPixel g = fetch_g(px);
    imageStore(o_trust, px, vec4(g.valid ? trust_params(g, px) : vec2(1.0), 0.0, 0.0));
}
