// bilateral.comp — depth- and normal-aware blur for the screen-space family.
// Papers: Tomasi & Manduchi 1998 (bilateral filter); Kopf et al. 2007 (joint bilateral);
// as used for SSAO by Mittring 2007 and Bavoil et al. 2008.
// A (2R+1)^2 kernel whose spatial Gaussian shrinks as the temporal history grows
// (sigma = R / sqrt(history length)), with weights that drop across depth edges (distance
// of the neighbour to this pixel's tangent plane, in pixels) and normal edges
// (dot(N, Nq)^u_normal_power), so occlusion does not bleed across silhouettes or creases.
#include "lib/common.glsl"
#include "lib/screen.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform writeonly image2D o_dst;

uniform sampler2D u_src;
uniform sampler2D u_len;
uniform sampler2D u_gb_position;
uniform sampler2D u_gb_normal;
uniform int u_radius_px;
uniform float u_normal_power;
uniform float u_depth_sigma;   // pixels

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    ivec2 size = ivec2(u_resolution);
    if (any(greaterThanEqual(px, size))) return;
    vec4 c = texelFetch(u_src, px, 0);
    vec4 pos = texelFetch(u_gb_position, px, 0);
    if (pos.w < 0.0 || u_radius_px <= 0) { imageStore(o_dst, px, c); return; }
    vec3 P = pos.xyz;
    vec3 N = normalize(texelFetch(u_gb_normal, px, 0).xyz + vec3(0.0, 0.0, 1e-12));
    float len = max(texelFetch(u_len, px, 0).r, 1.0);
    float sigma = max(float(u_radius_px) * inversesqrt(len), 0.35);
    float inv2s2 = 0.5 / (sigma * sigma);
    float ppu = pixels_per_unit(view_depth(P));
    vec4 sum = vec4(0.0);
    float wsum = 0.0;
    for (int j = -u_radius_px; j <= u_radius_px; ++j)
        for (int i = -u_radius_px; i <= u_radius_px; ++i) {
            ivec2 t = px + ivec2(i, j);
            if (any(lessThan(t, ivec2(0))) || any(greaterThanEqual(t, size))) continue;
            vec4 pq = texelFetch(u_gb_position, t, 0);
            if (pq.w < 0.0) continue;
            vec3 nq = texelFetch(u_gb_normal, t, 0).xyz;
            float plane = abs(dot(N, pq.xyz - P)) * ppu / max(u_depth_sigma, 1e-3);
            float w = exp(-float(i * i + j * j) * inv2s2 - plane * plane)
                    * pow(max(dot(N, nq), 0.0), u_normal_power);
            sum += w * texelFetch(u_src, t, 0);
            wsum += w;
        }
    imageStore(o_dst, px, wsum > 1e-8 ? sum / wsum : c);
}
