// shadows.glsl — visibility from the shadow atlas written by the shadow pass
// (addon/render/passes/shadows.py). Each light owns a run of views (6 cube faces, or sun
// cascades); the first view whose frustum holds the point answers, with a 3x3 PCF and
// normal-offset + slope bias. Points outside every view are lit.
#ifndef GI_SHADOWS_GLSL
#define GI_SHADOWS_GLSL

layout(std430, binding = BIND_SHADOW_VIEWS) readonly buffer ShadowViewBuffer { ShadowView shadow_views[]; };
uniform sampler2D u_shadow_atlas;

// Visibility of p through shadow view i; inside = false when p is outside the view.
float shadow_view_visibility(int i, vec3 p, vec3 ng, out bool inside) {
    inside = false;
    ivec2 atlas = textureSize(u_shadow_atlas, 0);
    ShadowView sv = shadow_views[i];
    bool ortho = sv.origin.w > 0.5;
    float dist = ortho ? 1.0 : length(p - sv.origin.xyz);
    float texel = sv.dir.w * dist;
    vec3 to_light = ortho ? -sv.dir.xyz : normalize(sv.origin.xyz - p);
    float cosg = clamp(abs(dot(ng, to_light)), 0.05, 1.0);
    vec3 po = p + ng * texel * sv.misc.y;
    vec4 clip = sv.view_proj * vec4(po, 1.0);
    if (clip.w <= 0.0) return 1.0;
    vec3 ndc = clip.xyz / clip.w;
    if (any(greaterThan(abs(ndc.xy), vec2(1.0))) || ndc.z > 1.0) return 1.0;
    inside = true;
    if (ortho && ndc.z < -1.0) return 1.0;
    float metric = ortho ? dot(po - sv.origin.xyz, sv.dir.xyz) : length(po - sv.origin.xyz);
    float slope = sqrt(1.0 - cosg * cosg) / cosg;
    float bias = texel * (0.3 + 0.25 * min(slope, 4.0)) + 1e-4 * metric;
    vec2 uv = (ndc.xy * 0.5 + 0.5);
    vec2 tile_px = sv.rect.zw * vec2(atlas);
    vec2 base_px = sv.rect.xy * vec2(atlas);
    vec2 px = base_px + uv * tile_px - 0.5;
    ivec2 lo = ivec2(base_px), hi = ivec2(base_px + tile_px) - 1;
    ivec2 ip = ivec2(floor(px));
    // The receiver's own (nearest) texel occluded by a clear margin by an occluder that
    // touches it (within 4 texels of depth): in shadow, with no light from the filter's
    // neighbours. Those can lie across a thin occluder's silhouette, e.g. on a zero-thickness
    // wall's far side where it meets the floor (two_rooms: the dark room's floor/wall seams
    // got 1/3 of the lit level). An occluder farther away casts an ordinary penumbra: there the
    // symmetric filter stays (the test without the depth limit darkened the shadowed side of
    // every edge: 96-px DIRECT q1 relMSE vs Cycles direct glossy_spheres 0.0056 -> 0.0066,
    // cornell 0.0023 -> 0.0030; with it 0.0056 / 0.0023 and two_rooms q1 still 0.00022). Perspective views only: the sun's and world's large texels would grow their
    // shadows (world relMSE vs Cycles +18 % with it; their thin-wall contact leak is a known limit).
    // The window is also capped at 1/64 of the light distance (4 texels of a 512-texel 90-degree
    // cube face): coarser maps' bigger texels would widen it in world units and harden contact
    // shadows (glossy_spheres q0, 256-texel faces: SSAO relMSE vs one_bounce 0.04085 uncapped,
    // 0.04070 capped, 0.04062 without the test; two_rooms dark room q1 0.00022 / q0 0.0121 either way).
    // The receiver itself must be behind a touching occluder too, not only its normal-offset
    // point po: in one of the 2x2 texels around p's own projection, by more than 2 biases and
    // within the window widened by the offset (p lies up to misc.y texels farther from the
    // light than po). A thin wall separates p itself from the light; the offset point of a
    // floor point next to a sphere's contact (2 texels = 5 cm at q0) lies under the sphere's
    // bulge, so po's nearest texel held the sphere although Cycles lights the point (a floor
    // pixel there: Cycles direct 0.48, DIRECT q0 0.27 without the test, 0.21 with it; 16 px all
    // darker, relMSE +0.18 % against a 16384-spp reference too): with this check the test no
    // longer fires on glossy_spheres q0 (SSAO relMSE vs one_bounce 0.04070 -> 0.04062, = without
    // the test) and two_rooms' dark room stays q1 0.00022 / q0 0.0121 (docs/techniques/SSAO.md).
    float near_d = metric - texelFetch(u_shadow_atlas, clamp(ivec2(floor(px + 0.5)), lo, hi), 0).r;
    float touch_hi = 2.0 * bias + min(4.0 * texel, dist / 64.0);
    if (!ortho && near_d > 2.0 * bias && near_d < touch_hi) {
        vec4 c0 = sv.view_proj * vec4(p, 1.0);
        if (c0.w > 0.0) {
            vec2 px0 = base_px + (c0.xy / c0.w * 0.5 + 0.5) * tile_px - 0.5;
            ivec2 i0 = ivec2(floor(px0));
            float m0 = length(p - sv.origin.xyz);
            float hi0 = touch_hi + texel * sv.misc.y;
            for (int k = 0; k < 4; ++k) {
                float d0 = m0 - texelFetch(u_shadow_atlas, clamp(i0 + ivec2(k & 1, k >> 1), lo, hi), 0).r;
                if (d0 > 2.0 * bias && d0 < hi0) return 0.0;
            }
        }
    }
    // 2x2 bilinear-weighted comparisons in a 3x3 neighbourhood (smooth PCF)
    vec2 f = fract(px);
    float lit = 0.0, wsum = 0.0;
    for (int dy = -1; dy <= 2; ++dy) {
        for (int dx = -1; dx <= 2; ++dx) {
            float wx = dx == -1 ? 1.0 - f.x : (dx == 2 ? f.x : 1.0);
            float wy = dy == -1 ? 1.0 - f.y : (dy == 2 ? f.y : 1.0);
            ivec2 q = clamp(ip + ivec2(dx, dy), lo, hi);
            float stored = texelFetch(u_shadow_atlas, q, 0).r;
            lit += wx * wy * ((metric - bias <= stored) ? 1.0 : 0.0);
            wsum += wx * wy;
        }
    }
    return lit / wsum;
}

// Visibility of light L from p. The light's views come in groups, one per shadow origin
// sampled on it this frame (shadow.z views each); each group answers with the view whose
// frustum holds p. The groups' visibilities are averaged with weights w = the origin's
// geometry term cos_x cos_y / d^2 for area and mesh lights (1 for the others): a ratio
// estimator of the shadowed/unshadowed fraction that is exact for unoccluded points and
// does not count light behind the receiver's horizon as shadow.
float light_visibility(Light L, vec3 p, vec3 n, vec3 ng) {
    int first = int(L.shadow.x + 0.5);
    int count = int(L.shadow.y + 0.5);
    int per = max(int(L.shadow.z + 0.5), 1);
    if (count <= 0 || L.axis_w.w < 0.5) return 1.0;
    int type = int(L.pos_type.w + 0.5);
    bool weighted = type == LIGHT_AREA || type == LIGHT_MESH;
    float num = 0.0, den = 0.0;
    for (int g = first; g < first + count; g += per) {
        float w = 1.0;
        if (weighted) {
            ShadowView sv = shadow_views[g];
            vec3 d = sv.origin.xyz - p;
            float d2 = max(dot(d, d), 1e-12);
            vec3 wd = d * inversesqrt(d2);
            float cy = dot(sv.dir.xyz, -wd);
            cy = type == LIGHT_MESH ? abs(cy) : max(cy, 0.0);
            w = max(dot(n, wd), 0.0) * cy / d2;
            if (w <= 0.0) continue;
        }
        float v = 1.0;
        for (int i = g; i < g + per; ++i) {
            bool inside;
            float vi = shadow_view_visibility(i, p, ng, inside);
            if (inside) { v = vi; break; }
        }
        num += w * v;
        den += w;
    }
    return den > 0.0 ? num / den : 1.0;
}

// World light: views [first, first+count) are orthographic maps along directions sampled
// on the sphere this frame (view.dir = the direction light travels, -omega). Ratio
// estimators (exact for unoccluded points at any sample count) of the visible fraction:
// vis_diffuse weights the sampled directions above the surface by cos to n, vis_glossy by
// cos to the glossy lobe's dominant direction d (the lobe widened to what the sample count
// can resolve). 1 when no sampled direction carries weight.
void world_visibility(int first, int count, vec3 p, vec3 n, vec3 ng, vec3 d,
                      out float vis_diffuse, out float vis_glossy) {
    float num_d = 0.0, den_d = 0.0, num_g = 0.0, den_g = 0.0;
    for (int i = first; i < first + count; ++i) {
        vec3 omega = -shadow_views[i].dir.xyz;
        float c = dot(n, omega);
        if (c <= 0.0 || dot(ng, omega) <= 0.0) continue;
        float cg = max(dot(d, omega), 0.0);
        bool inside;
        float v = shadow_view_visibility(i, p, ng, inside);
        num_d += c * v;
        den_d += c;
        num_g += cg * v;
        den_g += cg;
    }
    vis_diffuse = den_d > 0.0 ? num_d / den_d : 1.0;
    vis_glossy = den_g > 0.0 ? num_g / den_g : vis_diffuse;
}

#endif
