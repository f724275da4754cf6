// overlay.comp — the viewport's probe overlay (addon/render/probe_overlay.py): every probe of
// the volume drawn as a small sphere shaded with its own irradiance, as DDGI tools show them.
// Per pixel, 2x2 camera rays (unjittered view) against the probe spheres (hit_probe in
// probes/common.glsl, radius u_radius), depth-tested against the G-buffer (a sphere behind a
// surface is hidden). A sphere point with normal n shows E(n)/pi read from the irradiance
// atlas (the radiance of a white diffuse sphere in that light: the probe's stored irradiance
// in the direction n). Output: rgb premultiplied by the coverage, a = coverage (0..1); the
// host composites it over the rendered image.
#include "lib/common.glsl"
#define PROBE_LOOKUP 1
#include "probes/common.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform writeonly image2D o_overlay;
uniform sampler2D u_gb_position;   // world position, w < 0: background
uniform mat4 u_inv_view_proj;      // unjittered
uniform float u_radius;            // world units

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    ivec2 size = imageSize(o_overlay);
    if (any(greaterThanEqual(px, size))) return;
    vec4 gp = texelFetch(u_gb_position, px, 0);
    vec3 col = vec3(0.0);
    float cov = 0.0;
    for (int k = 0; k < 4; ++k) {
        vec2 sub = vec2(float(k & 1), float(k >> 1)) * 0.5 + 0.25;
        vec2 ndc = (vec2(px) + sub) / vec2(size) * 2.0 - 1.0;
        vec4 a0 = u_inv_view_proj * vec4(ndc, -1.0, 1.0), a1 = u_inv_view_proj * vec4(ndc, 1.0, 1.0);
        vec3 o = a0.xyz / a0.w, d = normalize(a1.xyz / a1.w - o);
        float t_max = gp.w >= 0.0 ? length(gp.xyz - o) : 1e30;
        vec3 n;
        ivec3 slot;
        vec4 st;
        if (hit_probe(o, d, t_max, u_radius, n, slot, st) >= 0) {
            col += sample_probe_irradiance(slot, n) * INV_PI;
            cov += 1.0;
        }
    }
    imageStore(o_overlay, px, vec4(sanitize(col * 0.25), cov * 0.25));
}
