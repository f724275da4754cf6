// ssdo_resolve.comp — SSDO's last step with traced off-screen directions: ssdo.comp left per
// pixel the sum of its known senders' radiance (rgb, a = open fraction) and in u_part
// (wunknown, unknown) its counts of off-screen and unknown directions; ssdo_trace.comp left
// per tile the radiance its tracer's ray brought back. The traced radiance stands for this
// pixel's off-screen directions when it faces like the tracer, shrunk towards the mean of
// this pixel's known (on-screen) directions by the share of its directions that are known:
// one traced ray per tile and frame is unbiased but noisy (a ray meeting the sun patch), the
// on-screen mean is smooth but stands for the off-screen directions only when most
// directions are known (sunlit_room q1/q2/q3 over 3 seeds 0.0130/0.0105/0.0113 ->
// 0.0116/0.0084/0.0099; bounce_room ceiling 0.071 -> 0.019); otherwise (an edge in the tile,
// no tracer) they are unknown: the bounce is the mean of the known.
#include "lib/common.glsl"
#include "lib/rng.glsl"
#include "lib/sampling.glsl"
#include "lib/brdf.glsl"
#include "lib/screen.glsl"
#include "screen_space/common.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba16f) uniform image2D io_ssdo;
layout(binding = 1, rgba32f) uniform readonly image2D u_ray_o;
layout(binding = 3, rgba16f) uniform readonly image2D u_tile_L;
layout(binding = 4, rg16f) uniform readonly image2D u_part;

uniform int u_samples;
uniform int u_world_tile;

void main() {
    ivec2 q = ivec2(gl_GlobalInvocationID.xy);
    ivec2 osize = imageSize(io_ssdo);
    if (any(greaterThanEqual(q, osize))) return;
    vec2 part = imageLoad(u_part, q).xy;
    float wunknown = part.x, unknown = part.y;
    if (wunknown <= 0.0) return;  // final already (no off-screen direction, or background)
    vec4 s = imageLoad(io_ssdo, q);
    float n = float(max(u_samples, 1));
    vec3 bounce = s.rgb;
    ivec2 t = q / max(u_world_tile, 1);
    vec4 L = imageLoad(u_tile_L, t);
#if defined(SSDO_CLASSES) && (SSDO_CLASSES & 4) == 0
    L.rgb = vec3(0.0);  // diagnostic (ssdo.comp's SSDO_CLASSES): the traced radiance left out
#endif
    bool used = false;
    if (L.a > 0.5) {
        int code = int(imageLoad(u_ray_o, t).w + 0.5);
        ivec2 px = ivec2((vec2(q) + 0.5) * u_resolution / vec2(osize));
        vec3 N = fetch_g(px).N;
        vec3 Nt = fetch_g(ivec2(code % 65536, code / 65536)).N;
        if (dot(N, Nt) > 0.8) {
            float known = n - wunknown - unknown;
            vec3 mean_known = known > 0.0 ? bounce / known : L.rgb;
            bounce += wunknown * mix(L.rgb, mean_known, known / n);
            used = true;
        }
    }
    if (!used) unknown += wunknown;
    imageStore(io_ssdo, q, vec4(sanitize(bounce / max(n - unknown, 1.0)), s.a));
}
