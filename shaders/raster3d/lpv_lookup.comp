// lpv_lookup.comp — indirect diffuse from the light propagation volume, per pixel.
// Cascades (Kaplanyan & Dachsbacher 2010, lpv_common.glsl): with f the finest cascade
// whose membership box holds the lookup point, E = A_f(P) + Σ_{c>f} R_c(P): the light of
// the VPLs near the camera at the fine resolution, the rest from the coarser rings, each
// VPL counted once. Within 2 cells of M_f's border the result blends linearly into the
// next cascade's (no popping when the camera moves; the grids are snapped to their cells).
// Per slab: SH intensity at P + u_normal_offset cell · N (normal offset, default ¼), interpolated trilinearly over
// the 8 nearest cell centres, leaving out centres behind the surface's plane and weighting
// each by the geometry volume's transmittance between the cell of the lookup point and it
// (what a thin wall separates is not interpolated across it, corner_transmittance); the
// weights are renormalised (if every centre is blocked, the centres in front are used). Radiance L = I / cell², irradiance E = ∫ L(ω) max(0, -N·ω) dω (an SH dot
// product). Dampening (Kaplanyan 2009): light flowing away from the surface along N (the
// SH gradient aligned with N: the surface's own injected light) scales the slab's
// irradiance by 1 - u_dampening · max(0, cos). Output rgb = E/π, a = 1; o_cascade: f plus
// the blend towards f + 1 (the GI_LPV_Cascade debug view).
#define LPV_CORNER_TRANSMITTANCE 1  // corner_transmittance, u_gv, u_gvd (lpv_common.glsl)
#include "lib/sh.glsl"
#include "raster3d/lpv_common.glsl"
layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform writeonly image2D o_out;
layout(binding = 1, rgba16f) uniform writeonly image2D o_cascade;
uniform sampler2D u_gb_position;
uniform sampler2D u_gb_normal;
uniform sampler2DArray u_lpv_r;
uniform sampler2DArray u_lpv_g;
uniform sampler2DArray u_lpv_b;
uniform int u_use_gv;
uniform float u_dampening;
uniform float u_normal_offset;  // cells along N (passes/lpv.py normal_offset)

vec3 slab_irradiance(int slab, int c, vec3 P, vec3 N) {
    float cs = u_lpv_origin[c].w;
    vec3 gp = lpv_cell_coord(c, P);
    vec3 g = gp + u_normal_offset * N;
    vec3 f = g - 0.5;
    ivec3 b = ivec3(floor(f));
    vec3 t = f - vec3(b);
    vec4 r = vec4(0.0), gg = vec4(0.0), bb = vec4(0.0);
    float wsum = 0.0;
    for (int pass_ = 0; pass_ < 2 && wsum < 1e-6; ++pass_) {
    for (int k = 0; k < 8; ++k) {
        ivec3 o = ivec3(k & 1, (k >> 1) & 1, k >> 2);
        ivec3 cc = b + o;
        if (any(lessThan(cc, ivec3(0))) || any(greaterThanEqual(cc, ivec3(u_grid)))) continue;
        if (dot(vec3(cc) + 0.5 - gp, N) <= 0.0) continue;  // behind the surface
        float w = (o.x == 1 ? t.x : 1.0 - t.x) * (o.y == 1 ? t.y : 1.0 - t.y) * (o.z == 1 ? t.z : 1.0 - t.z);
        if (u_use_gv == 1 && pass_ == 0) w *= corner_transmittance(c, g, b, cc);
        if (w <= 0.0) continue;
        ivec3 tc = ivec3(cc.xy, cc.z + slab * u_grid);
        r += w * texelFetch(u_lpv_r, tc, 0);
        gg += w * texelFetch(u_lpv_g, tc, 0);
        bb += w * texelFetch(u_lpv_b, tc, 0);
        wsum += w;
    }
    }  // second pass (everything blocked): the centres in front of the surface, unweighted
    if (wsum < 1e-6) return vec3(0.0);
    r /= wsum; gg /= wsum; bb /= wsum;
    vec3 e = vec3(sh_cosine_integral(r, -N), sh_cosine_integral(gg, -N), sh_cosine_integral(bb, -N));
    vec3 grad = 0.2126 * r.yzw + 0.7152 * gg.yzw + 0.0722 * bb.yzw;
    float gl = length(grad);
    float damp = gl > 1e-20 ? 1.0 - u_dampening * max(dot(grad / gl, N), 0.0) : 1.0;
    return e * damp / (cs * cs);
}

// E of cascade f: A_f + the coarser rings
vec3 cascade_irradiance(int f, vec3 P, vec3 N) {
    vec3 E = slab_irradiance(lpv_slab_all(f), f, P, N);
    for (int c = f + 1; c < u_cascades; ++c) E += slab_irradiance(lpv_slab_ring(c), c, P, N);
    return E;
}

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(px, imageSize(o_out)))) return;
    vec4 pos = texelFetch(u_gb_position, px, 0);
    if (pos.w < 0.0) {
        imageStore(o_out, px, vec4(0.0, 0.0, 0.0, 1.0));
        imageStore(o_cascade, px, vec4(0.0));
        return;
    }
    vec3 P = pos.xyz;
    vec3 N = normalize(texelFetch(u_gb_normal, px, 0).xyz + vec3(0.0, 0.0, 1e-12));
    int f = -1;
    float margin = 0.0;
    for (int c = 0; c < u_cascades; ++c) {
        margin = lpv_member_margin(c, P + 0.5 * u_lpv_origin[c].w * N);
        if (margin >= 0.0) { f = c; break; }
    }
    vec3 E = vec3(0.0);
    float shown = float(u_cascades);
    if (f >= 0) {
        float w = f == u_cascades - 1 ? 1.0 : clamp(margin / 2.0, 0.0, 1.0);
        E = w * cascade_irradiance(f, P, N);
        if (w < 1.0) E += (1.0 - w) * cascade_irradiance(f + 1, P, N);
        shown = float(f) + (1.0 - w);
    }
    imageStore(o_out, px, vec4(max(E, vec3(0.0)) * 0.31830988618, 1.0));
    imageStore(o_cascade, px, vec4(vec3(shown), 1.0));
}
