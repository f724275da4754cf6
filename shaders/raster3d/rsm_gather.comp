// rsm_gather.comp — RSM indirect diffuse (passes/rsm.py).
// RSM_LOW: gather at low resolution (u_low_size), each low pixel at the full-resolution
//   pixel it maps to. RSM_RESOLVE: per full-resolution pixel, bilinear interpolation of the
//   four nearest low-resolution samples whose normal and plane agree with the pixel's (at
//   least three must), else a full gather here (the paper's screen-space scheme).
// Output rgb = E/π (the composite multiplies by the diffuse albedo), a = 1.
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/rng.glsl"
#include "raster3d/rsm_common.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform writeonly image2D o_out;
#ifdef RSM_RESOLVE
layout(binding = 1, rgba16f) uniform writeonly image2D o_regather;
uniform sampler2D u_low;
uniform float u_low_scale;
uniform float u_normal_tol;
uniform float u_plane_tol;
#endif
uniform sampler2D u_gb_position;  // w = material id, < 0 background
uniform sampler2D u_gb_normal;
uniform ivec2 u_low_size;
uniform vec2 u_resolution;
uniform vec3 u_camera_pos;
uniform vec3 u_camera_fwd;
uniform uint u_sample;
uniform uint u_pattern;  // the VPL pattern's index: the frame within the current accumulation


void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
#ifdef RSM_LOW
    if (any(greaterThanEqual(px, u_low_size))) return;
    vec2 scale = vec2(u_low_size) / u_resolution;
    ivec2 fp = clamp(ivec2((vec2(px) + 0.5) / scale), ivec2(0), ivec2(u_resolution) - 1);
    vec4 pos = texelFetch(u_gb_position, fp, 0);
    if (pos.w < 0.0) { imageStore(o_out, px, vec4(0.0)); return; }
    vec3 N = normalize(texelFetch(u_gb_normal, fp, 0).xyz + vec3(0.0, 0.0, 1e-12));
    imageStore(o_out, px, vec4(sanitize(rsm_gather(pos.xyz, N, u_pattern)), 1.0));
#else
    if (any(greaterThanEqual(px, ivec2(u_resolution)))) return;
    vec4 pos = texelFetch(u_gb_position, px, 0);
    if (pos.w < 0.0) {
        imageStore(o_out, px, vec4(0.0, 0.0, 0.0, 1.0));
        imageStore(o_regather, px, vec4(0.0));
        return;
    }
    vec3 P = pos.xyz;
    vec3 N = normalize(texelFetch(u_gb_normal, px, 0).xyz + vec3(0.0, 0.0, 1e-12));
    vec2 scale = vec2(u_low_size) / u_resolution;
    vec2 f = (vec2(px) + 0.5) * scale - 0.5;
    ivec2 b = ivec2(floor(f));
    vec2 t = f - vec2(b);
    float depth = max(dot(P - u_camera_pos, u_camera_fwd), 1e-3);
    vec3 acc = vec3(0.0);
    float wsum = 0.0;
    int ok = 0;
    for (int j = 0; j < 2; ++j) {
        for (int i = 0; i < 2; ++i) {
            ivec2 q = clamp(b + ivec2(i, j), ivec2(0), u_low_size - 1);
            ivec2 qp = clamp(ivec2((vec2(q) + 0.5) / scale), ivec2(0), ivec2(u_resolution) - 1);
            vec4 qpos = texelFetch(u_gb_position, qp, 0);
            if (qpos.w < 0.0) continue;
            vec3 qn = normalize(texelFetch(u_gb_normal, qp, 0).xyz + vec3(0.0, 0.0, 1e-12));
            if (dot(qn, N) < u_normal_tol || abs(dot(N, qpos.xyz - P)) > u_plane_tol * depth) continue;
            float w = (i == 1 ? t.x : 1.0 - t.x) * (j == 1 ? t.y : 1.0 - t.y);
            acc += w * texelFetch(u_low, q, 0).rgb;
            wsum += w;
            ok += 1;
        }
    }
    vec3 E;
    float again = 0.0;
    if (ok >= 3 && wsum > 1e-3) {
        E = acc / wsum;
    } else {
        E = rsm_gather(P, N, u_pattern);
        again = 1.0;
    }
    imageStore(o_out, px, vec4(sanitize(E), 1.0));
    imageStore(o_regather, px, vec4(again));
#endif
}
