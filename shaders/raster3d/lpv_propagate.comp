// lpv_propagate.comp — one propagation step of the light propagation volume (Kaplanyan
// 2009): every cell gathers from its 6 neighbours. For a neighbour s in direction -d, the
// flux through each of the 5 faces of this cell not shared with s (the far face, normal d,
// and 4 side faces) is Ω_face · I_s(ω_face) (I_s the neighbour's SH intensity evaluated
// towards the face centre, Ω_face the face's solid angle seen from s's centre, computed on
// the host), re-emitted into this cell as a Lambertian lobe around the face normal:
// Φ/π · max(0, n_f·w). 6 x 5 faces cover the sphere: energy is conserved without occlusion.
// LPV_COPY: copies the injected volume into the accumulated one (step 0).
// Geometry volume (u_use_gv): the flux entering a cell is scaled by 1 - B, B the cell's
// blocking potential (surfel area from the RSMs over the cell's face area, clamped to 1).
// Writes the step's result and adds it to the accumulated volume. Cascades are slabs of
// u_grid layers each; propagation never crosses a slab.
#include "lib/sh.glsl"
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
uniform sampler2DArray u_gv;  // x: blocking potential of the cell's geometry (area / cell face)
uniform int u_use_gv;
uniform int u_grid;
uniform int u_cascades;
uniform float u_omega_front;  // solid angle of the far face
uniform float u_omega_side;   // solid angle of a side face

const ivec3 DIRS[6] = ivec3[6](ivec3(1, 0, 0), ivec3(-1, 0, 0), ivec3(0, 1, 0), ivec3(0, -1, 0),
                                ivec3(0, 0, 1), ivec3(0, 0, -1));

void main() {
    ivec3 id = ivec3(gl_GlobalInvocationID);
    if (any(greaterThanEqual(id, ivec3(u_grid, u_grid, u_grid * u_cascades)))) return;
#ifdef LPV_COPY
    // the accumulated volume starts as the injected light
    imageStore(acc_r, id, texelFetch(u_src_r, id, 0));
    imageStore(acc_g, id, texelFetch(u_src_g, id, 0));
    imageStore(acc_b, id, texelFetch(u_src_b, id, 0));
    return;
#endif
    int slab = id.z / u_grid;
    ivec3 cell = ivec3(id.xy, id.z - slab * u_grid);
    vec4 r = vec4(0.0), g = vec4(0.0), b = vec4(0.0);
    // fuzzy occlusion: light entering this cell is attenuated by its geometry's blocking
    float trans = u_use_gv == 1 ? clamp(1.0 - texelFetch(u_gv, id, 0).x, 0.0, 1.0) : 1.0;
    for (int k = 0; k < 6; ++k) {
        ivec3 d = DIRS[k];
        ivec3 s = cell - d;
        if (any(lessThan(s, ivec3(0))) || any(greaterThanEqual(s, ivec3(u_grid)))) continue;
        ivec3 st = ivec3(s.xy, s.z + slab * u_grid);
        vec4 sr = texelFetch(u_src_r, st, 0);
        vec4 sg = texelFetch(u_src_g, st, 0);
        vec4 sb = texelFetch(u_src_b, st, 0);
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
}
