// lpv_lookup.comp — indirect diffuse from the light propagation volume: per pixel, the
// accumulated SH intensity of every cascade containing P + ½ cell · N (normal offset),
// trilinear (bilinear in the layer + linear between layers), as radiance L = I / cell²,
// integrated against the cosine lobe of the incoming hemisphere: E = ∫ L(w) max(0, -N·w) dw.
// Cascades hold disjoint VPLs (each VPL in the finest cascade containing it), so their
// irradiances add. Dampening (Kaplanyan 2009): light flowing away from the surface along
// N (the SH gradient aligned with N, the surface's own injected light) is scaled by
// 1 - u_dampening · max(0, cos). Output rgb = E/π, a = 1.
#include "lib/sh.glsl"
layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform writeonly image2D o_out;
#define LPV_MAX_CASCADES 4
uniform sampler2D u_gb_position;
uniform sampler2D u_gb_normal;
uniform sampler2DArray u_lpv_r;
uniform sampler2DArray u_lpv_g;
uniform sampler2DArray u_lpv_b;
uniform int u_grid;
uniform int u_cascades;
uniform vec4 u_lpv_origin[LPV_MAX_CASCADES];
uniform float u_dampening;

vec4 fetch3(sampler2DArray t, vec3 g, int slab) {
    // g in cell units, cell centres at integer + 0.5
    vec2 uv = g.xy / float(u_grid);
    float z = clamp(g.z - 0.5, 0.0, float(u_grid - 1));
    float z0 = floor(z);
    float f = z - z0;
    float z1 = min(z0 + 1.0, float(u_grid - 1));
    vec4 a = texture(t, vec3(uv, z0 + float(slab * u_grid)));
    vec4 b = texture(t, vec3(uv, z1 + float(slab * u_grid)));
    return mix(a, b, f);
}

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(px, imageSize(o_out)))) return;
    vec4 pos = texelFetch(u_gb_position, px, 0);
    if (pos.w < 0.0) { imageStore(o_out, px, vec4(0.0, 0.0, 0.0, 1.0)); return; }
    vec3 N = normalize(texelFetch(u_gb_normal, px, 0).xyz + vec3(0.0, 0.0, 1e-12));
    vec3 E = vec3(0.0);
    for (int c = 0; c < u_cascades; ++c) {
        float cs = u_lpv_origin[c].w;
        vec3 g = (pos.xyz + 0.5 * cs * N - u_lpv_origin[c].xyz) / cs;
        if (any(lessThan(g, vec3(0.0))) || any(greaterThan(g, vec3(float(u_grid))))) continue;
        vec4 r = fetch3(u_lpv_r, g, c), gg = fetch3(u_lpv_g, g, c), b = fetch3(u_lpv_b, g, c);
        vec3 e = vec3(sh_cosine_integral(r, -N), sh_cosine_integral(gg, -N), sh_cosine_integral(b, -N));
        vec3 grad = 0.2126 * r.yzw + 0.7152 * gg.yzw + 0.0722 * b.yzw;
        float gl = length(grad);
        float damp = gl > 1e-20 ? 1.0 - u_dampening * max(dot(grad / gl, N), 0.0) : 1.0;
        E += max(e, vec3(0.0)) * damp / (cs * cs);
    }
    imageStore(o_out, px, vec4(E * 0.31830988618, 1.0));
}
