// lpv_inject.geom — routes a VPL (or a surfel) to its cells: one point per target cell,
// gl_Layer = the layer of the 2D-array target.
// Light (default): a Lambertian VPL of flux Φ is the intensity Φ/π·max(0, n·ω) (W/sr),
// projected on 2-band SH, added to the cell containing p + ½ cell · n, in the slab A_c of
// every cascade whose membership box holds p, and in the ring slab R_c of the cascade
// whose box holds p while the next finer one does not (lpv_common.glsl).
// LPV_GV (cascade u_only_cascade): the surfel's blocking of the flux crossing between two
// cell centres along axis a, area·|n_a| / cell², added to channel a of the staggered cell
// floor(g - ½ e_a), and area·|n_a| / cell² · g_a (g in cell units) to channel a of the
// depth volume (second target): divided by the blocking it is the blockers' mean position
// along the axis, so the lookup knows on which side of a point inside the staggered cell
// the blockers lie. A surfel wider than a cell is split into k x k sub-surfels (k <= 3) in
// its tangent plane, so a coarse RSM or G-buffer leaves no holes in a fine cascade.
#include "lib/sh.glsl"
#include "raster3d/lpv_common.glsl"
layout(points) in;
#ifdef LPV_GV
layout(points, max_vertices = 27) out;
uniform int u_only_cascade;
#else
layout(points, max_vertices = 7) out;
#endif
in vec3 v_pos[];
in vec3 v_nrm[];
in vec4 v_val[];
out vec4 g_r;
out vec4 g_g;
out vec4 g_b;

void emit_cell(ivec3 cell, int slab, vec4 r, vec4 g, vec4 b) {
    if (any(lessThan(cell, ivec3(0))) || any(greaterThanEqual(cell, ivec3(u_grid)))) return;
    gl_Position = vec4((vec2(cell.xy) + 0.5) / float(u_grid) * 2.0 - 1.0, 0.0, 1.0);
    gl_Layer = cell.z + slab * u_grid;
    g_r = r;
    g_g = g;
    g_b = b;
    EmitVertex();
    EndPrimitive();
}

void main() {
    vec4 val = v_val[0];
    if (val.a < 0.0) return;
    vec3 p = v_pos[0], n = v_nrm[0];
#ifdef LPV_GV
    int c = u_only_cascade;
    float cs = u_lpv_origin[c].w;
    float side = sqrt(max(val.a, 0.0));
    int k = int(clamp(ceil(side / cs), 1.0, 3.0));
    vec3 t1 = normalize(abs(n.z) < 0.9 ? cross(n, vec3(0.0, 0.0, 1.0)) : cross(n, vec3(1.0, 0.0, 0.0)));
    vec3 t2 = cross(n, t1);
    float a = val.a / float(k * k) / (cs * cs);
    vec3 blk = a * abs(n);
    for (int i = 0; i < k; ++i) {
        for (int j = 0; j < k; ++j) {
            vec3 q = p + side * ((float(i) + 0.5) / float(k) - 0.5) * t1
                       + side * ((float(j) + 0.5) / float(k) - 0.5) * t2;
            vec3 g = lpv_cell_coord(c, q);
            vec3 bd = blk * g;  // blocking-weighted position along the axis (the blockers' depth)
            emit_cell(ivec3(floor(g - vec3(0.5, 0.0, 0.0))), c, vec4(blk.x, 0.0, 0.0, 0.0), vec4(bd.x, 0.0, 0.0, 0.0), vec4(0.0));
            emit_cell(ivec3(floor(g - vec3(0.0, 0.5, 0.0))), c, vec4(0.0, blk.y, 0.0, 0.0), vec4(0.0, bd.y, 0.0, 0.0), vec4(0.0));
            emit_cell(ivec3(floor(g - vec3(0.0, 0.0, 0.5))), c, vec4(0.0, 0.0, blk.z, 0.0), vec4(0.0, 0.0, bd.z, 0.0), vec4(0.0));
        }
    }
#else
    vec4 lobe = sh_cosine_lobe(n) * (1.0 / 3.14159265358979);
    vec4 r = lobe * val.r, g = lobe * val.g, b = lobe * val.b;
    bool inner = false;  // inside the membership box of the next finer cascade
    for (int c = 0; c < u_cascades; ++c) {
        bool inside = lpv_in_member(c, p);
        if (inside) {
            vec3 gc = lpv_cell_coord(c, p + 0.5 * u_lpv_origin[c].w * n);
            ivec3 cell = ivec3(floor(gc));
            emit_cell(cell, lpv_slab_all(c), r, g, b);
            if (c > 0 && !inner) emit_cell(cell, lpv_slab_ring(c), r, g, b);
        }
        inner = inside;
    }
#endif
}
