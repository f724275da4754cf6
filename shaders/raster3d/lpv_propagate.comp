// lpv_propagate.comp — one propagation step of the light propagation volume (Kaplanyan
// 2009): every cell gathers from its 6 neighbours. For a neighbour s in direction -d, the
// flux through each of the 5 faces of this cell not shared with s (the far face, normal d,
// and 4 side faces) is Ω_face · I_s(ω_face): I_s the neighbour's SH intensity evaluated
// towards the face's centre, Ω_face the face's solid angle seen from s's centre (far face
// 0.4007 sr, side face 0.4234 sr, integrated on the host; 6 x 5 faces cover 4π). It is
// re-emitted into this cell as a Lambertian lobe around the face normal, Φ/π·max(0, n_f·ω)
// (the reprojection onto the face), so propagation conserves energy without occlusion.
// Geometry volume (u_use_gv): the flux crossing from s to this cell is scaled by 1 - B, B
// the blocking of the surfels between the two cell centres (the staggered cell of the
// shared face, channel = axis; lpv_common.glsl), clamped to [0, 1].
// LPV_COPY: the accumulated volume starts as the injected light.
// Writes the step's result and adds it to the accumulated volume. Slabs (cascades, rings)
// are independent: propagation never crosses a slab; each dispatch is one slab (u_slab).
#include "lib/sh.glsl"
#include "raster3d/lpv_common.glsl"
layout(local_size_x = 4, local_size_y = 4, local_size_z = 4) in;
layout(binding = 0, rgba32f) uniform writeonly image2DArray o_r;
layout(binding = 1, rgba32f) uniform writeonly image2DArray o_g;
layout(binding = 2, rgba32f) uniform writeonly image2DArray o_b;
layout(binding = 3, rgba32f) uniform image2DArray acc_r;
layout(binding = 4, rgba32f) uniform image2DArray acc_g;
layout(binding = 5, rgba32f) uniform image2DArray acc_b;
uniform sampler2DArray u_src_r;
uniform sampler2DArray u_src_g;
uniform sampler2DArray u_src_b;
uniform sampler2DArray u_gv;
uniform int u_use_gv;
uniform int u_slabs;
uniform int u_slab;  // the slab this dispatch propagates (one dispatch per slab and step)
uniform float u_omega_front;
uniform float u_omega_side;
uniform float u_copy_scale;
uniform int u_normalize;  // scale each source by clamp_norm  // LPV_COPY: 1 = the injected light is part of the result, 0 = not

// Evaluating the 2-band SH clamped at zero (a negative intensity carries no flux) adds
// energy: the lobe a + b·cosθ (a = Y00·c0, b = Y1·|c1|) integrates to 4πa unclamped and to
// 2π(a + b/2 + a²/(2b)) clamped when b > a. Each source channel is scaled by the ratio, so a
// step conserves the source's flux (measured without it: +12 % per step on a cosine lobe).
float clamp_norm(vec4 c) {
    float a = SH_Y00 * c.x, b = SH_Y1 * length(c.yzw);
    if (a <= 0.0) return 0.0;
    if (b <= a) return 1.0;
    return 2.0 * a / (a + 0.5 * b + a * a / (2.0 * b));
}

const ivec3 DIRS[6] = ivec3[6](ivec3(1, 0, 0), ivec3(-1, 0, 0), ivec3(0, 1, 0), ivec3(0, -1, 0),
                                ivec3(0, 0, 1), ivec3(0, 0, -1));

void main() {
    ivec3 id = ivec3(gl_GlobalInvocationID);
    if (any(greaterThanEqual(id, ivec3(u_grid, u_grid, u_grid * u_slabs)))) return;
#ifdef LPV_COPY
    imageStore(acc_r, id, u_copy_scale * texelFetch(u_src_r, id, 0));
    imageStore(acc_g, id, u_copy_scale * texelFetch(u_src_g, id, 0));
    imageStore(acc_b, id, u_copy_scale * texelFetch(u_src_b, id, 0));
    return;
#else
    if (id.z >= u_grid) return;
    int slab = u_slab;
    int casc = slab < u_cascades ? slab : slab - u_cascades + 1;
    ivec3 cell = id;
    id = ivec3(cell.xy, cell.z + slab * u_grid);
    vec4 r = vec4(0.0), g = vec4(0.0), b = vec4(0.0);
    for (int k = 0; k < 6; ++k) {
        ivec3 d = DIRS[k];
        ivec3 s = cell - d;
        if (any(lessThan(s, ivec3(0))) || any(greaterThanEqual(s, ivec3(u_grid)))) continue;
        float trans = 1.0;
        if (u_use_gv == 1) {
            int axis = k / 2;
            ivec3 f = min(s, cell);
            trans = 1.0 - clamp(texelFetch(u_gv, ivec3(f.xy, f.z + casc * u_grid), 0)[axis], 0.0, 1.0);
            if (trans <= 0.0) continue;
        }
        ivec3 st = ivec3(s.xy, s.z + slab * u_grid);
        vec4 sr = texelFetch(u_src_r, st, 0);
        vec4 sg = texelFetch(u_src_g, st, 0);
        vec4 sb = texelFetch(u_src_b, st, 0);
        if (u_normalize == 1) {
            sr *= clamp_norm(sr);
            sg *= clamp_norm(sg);
            sb *= clamp_norm(sb);
        }
        vec3 dv = vec3(d);
        // far face: centre at 1.5 d from s's centre
        {
            vec3 w = dv;
            float Ir = max(sh_eval(sr, w), 0.0), Ig = max(sh_eval(sg, w), 0.0), Ib = max(sh_eval(sb, w), 0.0);
            vec4 lobe = sh_cosine_lobe(dv) * (u_omega_front * trans / 3.14159265358979);
            r += lobe * Ir; g += lobe * Ig; b += lobe * Ib;
        }
        // side faces: centre at d + 0.5 t from s's centre, normal t
        for (int j = 0; j < 6; ++j) {
            vec3 t = vec3(DIRS[j]);
            if (abs(dot(t, dv)) > 0.5) continue;
            vec3 w = normalize(dv + 0.5 * t);
            float Ir = max(sh_eval(sr, w), 0.0), Ig = max(sh_eval(sg, w), 0.0), Ib = max(sh_eval(sb, w), 0.0);
            vec4 lobe = sh_cosine_lobe(t) * (u_omega_side * trans / 3.14159265358979);
            r += lobe * Ir; g += lobe * Ig; b += lobe * Ib;
        }
    }
    imageStore(o_r, id, r);
    imageStore(o_g, id, g);
    imageStore(o_b, id, b);
    imageStore(acc_r, id, imageLoad(acc_r, id) + r);
    imageStore(acc_g, id, imageLoad(acc_g, id) + g);
    imageStore(acc_b, id, imageLoad(acc_b, id) + b);
#endif
}
