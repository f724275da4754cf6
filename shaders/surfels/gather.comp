// gather.comp — per pixel: the irradiance of the surfels around the G-buffer point (weights:
// radius falloff, normals, depth-moment visibility; surfels/common.glsl), marking them seen;
// color += diffuse albedo × E / π. Render passes: o_effect / o_diffuse (what was added) and
// the debug views o_view_surfels (each pixel in the colour of the surfel that weighs most there,
// shaded by its irradiance: the surfels themselves) and o_view_coverage (the summed weight:
// black = no surfel, a hole the spawn pass will fill).
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/rng.glsl"
#include "lib/sampling.glsl"
#include "lib/brdf.glsl"
#include "lib/screen.glsl"
#include "screen_space/common.glsl"
#define SF_LOOKUP 1
#include "surfels/common.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform image2D io_color;
layout(binding = 1, rgba32f) uniform writeonly image2D o_effect;
layout(binding = 2, rgba32f) uniform writeonly image2D o_view_surfels;
layout(binding = 3, rgba32f) uniform writeonly image2D o_view_coverage;
uniform int u_debug;

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    ivec2 size = imageSize(io_color);
    if (any(greaterThanEqual(px, size))) return;
    GPixel g = fetch_g(px);
    vec4 c = imageLoad(io_color, px);
    vec3 add = vec3(0.0);
    float cov = 0.0;
    if (g.valid) {
        Surface s = fetch_surface(px, g.mid);
        float NoV = max(dot(g.N, view_dir(g.P)), 1e-4);
        vec3 E = sf_irradiance(g.P, g.Ng, cov, u_sf_frame);
        add = diffuse_albedo(s, NoV) * E * INV_PI;
    }
    vec3 total = sanitize(c.rgb + add);
    imageStore(io_color, px, vec4(total, c.a));
    imageStore(o_effect, px, vec4(total - c.rgb, 1.0));
    if (u_debug == 0) return;
    vec3 vs = vec3(0.0);
    if (g.valid) {
        int count;
        int base = sf_cell_at(g.P, count);
        float best = 0.0;
        for (int j = 0; j < count; ++j) {
            int i = int(sf_cells[base + j]);
            float w = sf_weight(i, g.P, g.Ng);
            if (w > best) {
                best = w;
                uvec4 h = pcg4d(uvec4(uint(i), 3u, 5u, 7u));
                vs = (0.3 + 0.7 * vec3(h.xyz & 255u) / 255.0) * (0.5 + 0.5 * min(luminance(sf_state[i * SF_STATE].rgb) * INV_PI, 1.0));
            }
        }
    }
    imageStore(o_view_surfels, px, vec4(vs, 1.0));
    imageStore(o_view_coverage, px, vec4(vec3(min(cov, 1.0)), 1.0));
}
