// rsm_common.glsl — the RSM view table and the paper's VPL gather (passes/rsm.py).
// Requires common.glsl and rng.glsl.
#ifndef GI_RSM_COMMON_GLSL
#define GI_RSM_COMMON_GLSL
#define RSM_MAX_VIEWS 24

uniform int u_rsm_count;
uniform mat4 u_rsm_vp[RSM_MAX_VIEWS];
uniform vec4 u_rsm_origin[RSM_MAX_VIEWS];  // w = 1 orthographic
uniform vec4 u_rsm_fwd[RSM_MAX_VIEWS];     // w = texel size
uniform vec4 u_rsm_rect[RSM_MAX_VIEWS];    // atlas texel rect x, y, w, h
uniform sampler2D u_rsm_pos;   // w = 1 where a surface was seen
uniform sampler2D u_rsm_nrm;
uniform sampler2D u_rsm_flux;
uniform int u_vpl_samples;
uniform float u_disk_radius;   // fraction of the RSM side
uniform float u_min_distance;  // d_min of the kernel's distance clamp
uniform int u_exact_weights;

// The VPL at atlas position tc (texels, inside view rect): position, normal and flux of the
// nearest texel. Returns false where that texel saw no surface.
bool rsm_vpl(vec4 rect, vec2 tc, out vec3 xp, out vec3 np, out vec3 flux) {
    ivec2 t = ivec2(rect.xy) + min(ivec2(tc), ivec2(rect.zw) - 1);
    vec4 p = texelFetch(u_rsm_pos, t, 0);
    xp = p.xyz;
    np = texelFetch(u_rsm_nrm, t, 0).xyz;
    flux = texelFetch(u_rsm_flux, t, 0).rgb;
    return p.w >= 0.5;
}

// Projection of P into view v, in [0,1]^2 (clamped; the centre when P is behind the view).
vec2 rsm_project(int v, vec3 P) {
    vec4 c = u_rsm_vp[v] * vec4(P, 1.0);
    if (c.w <= 1e-6) return vec2(0.5);
    return clamp(c.xy / c.w * 0.5 + 0.5, 0.0, 1.0);
}

// Sample k of frame `frame`'s pattern: point k + n·frame of the R2 sequence (n samples per
// frame), shared by every pixel. Consecutive frames take consecutive windows of the one
// sequence, so any run of frames (an accumulation, or the temporal pass's 8-frame window
// while the light or camera moves) covers the disk as evenly as one frame with that many
// samples. Fixed-point (uint, wraps mod 2^32) so the index never loses precision.
vec2 rsm_xi(int k, uint frame) {
    uint i = uint(k) + uint(max(u_vpl_samples, 1)) * frame + 1u;
    uvec2 a = uvec2(3242174889u, 2447445414u);  // R2's (1/g, 1/g²) · 2^32
    uvec2 x = i * a + uvec2(0x80000000u);         // 0.5 + i·a mod 1
    return vec2(x >> 8u) * (1.0 / 16777216.0);
}

// E/π at P with normal N from every view's VPLs (one bounce, no visibility):
// E = (1/π) Σ Φ·max(0,<n_p,x-x_p>)·max(0,<n,x_p-x>)/max(|x-x_p|², d_min²)².
vec3 rsm_gather(vec3 P, vec3 N, uint frame) {
    vec3 total = vec3(0.0);
    float dmin2 = u_min_distance * u_min_distance;
    int n = max(u_vpl_samples, 1);
    for (int v = 0; v < u_rsm_count; ++v) {
        vec4 rect = u_rsm_rect[v];
        vec2 uv = rsm_project(v, P);
        float R = u_disk_radius * rect.z;  // disk radius in texels
        vec3 sum = vec3(0.0);
        for (int k = 0; k < n; ++k) {
            vec2 xi = rsm_xi(k, frame);
            float r = u_disk_radius * xi.x;
            float phi = TWO_PI * xi.y;
            vec2 s = uv + r * vec2(sin(phi), cos(phi));
            if (any(lessThan(s, vec2(0.0))) || any(greaterThanEqual(s, vec2(1.0)))) continue;
            vec3 xp, np, flux;
            if (!rsm_vpl(rect, s * rect.zw, xp, np, flux)) continue;
            vec3 d = P - xp;
            float d2 = max(dot(d, d), dmin2);
            float kern = max(0.0, dot(np, d)) * max(0.0, -dot(N, d)) / max(d2 * d2, 1e-20);
            float w = u_exact_weights == 1 ? 2.0 * xi.x : 3.0 * xi.x * xi.x;
            sum += flux * (kern * w);
        }
        total += sum * (PI * R * R / float(n));
    }
    return total * (INV_PI * INV_PI);
}
#endif
