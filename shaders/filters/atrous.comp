// atrous.comp — one iteration of the edge-avoiding à-trous wavelet filter.
// MODE 0 (ATROUS, Dammertz et al. 2010): 5x5 B3-spline taps spaced u_step pixels apart,
//   weighted by colour (tone-mapped difference, sigma halved each iteration as in the
//   paper), normal and position (distance from the centre's tangent plane, in pixel
//   footprints: scale-free, unlike a raw world-space sigma).
// MODE 1 (SVGF, Schied et al. 2017 §4.3): the colour weight is luminance difference over
//   sigma_l times the 3x3-Gaussian-prefiltered standard deviation; normal weight
//   max(0, n.n')^sigma_n; depth weight from the plane distance over the tap distance; the
//   variance (alpha) is filtered with squared weights.
// Input: u_in (rgb signal, a variance); background pixels pass through.
#include "lib/common.glsl"
#include "lib/screen.glsl"
#include "filters/common.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform writeonly image2D o_out;

uniform sampler2D u_in;
uniform sampler2D u_gb_position;
uniform sampler2D u_gb_normal;
uniform int u_step;
uniform int u_mode;
uniform float u_sigma_c;   // MODE 0: colour sigma (this iteration's); MODE 1: sigma_l
uniform float u_sigma_n;   // MODE 0: normal sigma; MODE 1: normal exponent
uniform float u_sigma_p;   // plane-distance sigma (pixel footprints per pixel of tap distance)

vec3 tonemap(vec3 c) { return c / (1.0 + c); }

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    ivec2 size = ivec2(u_resolution);
    if (any(greaterThanEqual(px, size))) return;
    vec4 center = texelFetch(u_in, px, 0);
    vec4 pos = texelFetch(u_gb_position, px, 0);
    if (pos.w < 0.0) {
        imageStore(o_out, px, center);
        return;
    }
    vec3 P = pos.xyz;
    vec3 N = normalize(texelFetch(u_gb_normal, px, 0).xyz + vec3(0.0, 0.0, 1e-12));
    float ppu = pixels_per_unit(view_depth(P));
    float lc = luminance(center.rgb);
    float sd = 0.0;
    if (u_mode == 1) {  // 3x3 Gaussian of the variance
        float v = 0.0, ws = 0.0;
        for (int dy = -1; dy <= 1; ++dy)
            for (int dx = -1; dx <= 1; ++dx) {
                ivec2 q = clamp(px + ivec2(dx, dy), ivec2(0), size - 1);
                float w = (dx == 0 ? 0.5 : 0.25) * (dy == 0 ? 0.5 : 0.25);
                v += w * texelFetch(u_in, q, 0).a;
                ws += w;
            }
        sd = sqrt(max(v / ws, 0.0));
    }
    vec3 tc = tonemap(center.rgb);
    vec3 sum = vec3(0.0);
    float var = 0.0, wsum = 0.0;
    for (int j = -2; j <= 2; ++j)
        for (int i = -2; i <= 2; ++i) {
            ivec2 q = px + ivec2(i, j) * u_step;
            if (any(lessThan(q, ivec2(0))) || any(greaterThanEqual(q, size))) continue;
            vec4 pq = texelFetch(u_gb_position, q, 0);
            if (pq.w < 0.0) continue;
            vec4 s = texelFetch(u_in, q, 0);
            vec3 nq = texelFetch(u_gb_normal, q, 0).xyz;
            float h = ATROUS_H[i + 2] * ATROUS_H[j + 2];
            float dist = float(u_step) * length(vec2(i, j));
            float dp = abs(dot(N, pq.xyz - P)) * ppu;
            float w;
            if (u_mode == 1) {
                float wl = (i == 0 && j == 0) ? 0.0 : abs(luminance(s.rgb) - lc) / (u_sigma_c * sd + 1e-6);
                float wz = dp / (u_sigma_p * dist + 1e-3);
                w = h * pow(max(dot(N, nq), 0.0), u_sigma_n) * exp(-wl - wz);
            } else {
                vec3 dc = tonemap(s.rgb) - tc;
                vec3 dn = nq - N;
                float wz = dp / (u_sigma_p * max(dist, 1.0));
                w = h * exp(-dot(dc, dc) / max(u_sigma_c * u_sigma_c, 1e-8)
                            - dot(dn, dn) / max(u_sigma_n * u_sigma_n, 1e-8) - wz * wz);
            }
            sum += w * s.rgb;
            var += w * w * s.a;
            wsum += w;
        }
    if (wsum <= 1e-12) {
        imageStore(o_out, px, center);
        return;
    }
    imageStore(o_out, px, vec4(sum / wsum, var / (wsum * wsum)));
}
