// lpv_inject.geom — routes a VPL (or a surfel) to its cells: one point per target cell,
// gl_Layer = the layer of the 2D-array target.
// Light (default): a Lambertian VPL of flux Φ is the intensity Φ/π·max(0, n·ω) (W/sr),
// projected on 2-band SH, added to the one cell containing p + u_inject_offset cell · n
// (LPV_SPLAT_NEAREST: passes/lpv.py trilinear_injection False) or (the default) splatted
// trilinearly over the cell centres around that point in front of its surface, each
// centre's weight cut by the geometry volume's transmittance between the point and it
// (u_use_gv: the volume is built before the injection; without it the splat crossed thin
// walls sideways), in the slab A_c of
// every cascade whose membership box holds p, and in the ring slab R_c of the cascade
// whose box holds p while the next finer one does not (lpv_common.glsl).
// LPV_GV (cascade u_only_cascade): the surfel's blocking of the flux crossing between two
// cell centres along axis a, area·|n_a| / cell², added to channel a of the staggered cell
// floor(g - ½ e_a), and area·|n_a| / cell² · g_a (g in cell units) to channel a of the
// depth volume (second target): divided by the blocking it is the blockers' mean position
// along the axis, so the lookup knows on which side of a point inside the staggered cell
// the blockers lie. A surfel wider than a cell is split into k x k sub-surfels (k <= 3) in
// its tangent plane, so a coarse RSM or G-buffer leaves no holes in a fine cascade.
#if !defined(LPV_GV) && !defined(LPV_SPLAT_NEAREST)
#define LPV_CORNER_TRANSMITTANCE 1  // the splat's weights through the geometry volume
uniform int u_use_gv;  // 1: the geometry volume (built before the injection) cuts the splat
#endif
#include "lib/sh.glsl"
#include "raster3d/lpv_common.glsl"
layout(points) in;
#ifndef LPV_GV
uniform float u_inject_offset;  // cells along n (passes/lpv.py inject_offset)
#endif
#ifdef LPV_GV
layout(points, max_vertices = 27) out;
uniform int u_only_cascade;
#elif defined(LPV_SPLAT_NEAREST)
layout(points, max_vertices = 7) out;
#else
layout(points, max_vertices = 56) out;  // 8 cells x (A_c + R_c) x up to 4 cascades
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
    float wprev = 0.0;   // the VPL's share in A_{c-1} (soft membership)
    for (int c = 0; c < u_cascades; ++c) {
        bool inside = lpv_in_member(c, p);
#ifdef LPV_HARD_CASCADES
        float a_c = 1.0, r_c = (c > 0 && !inner) ? 1.0 : 0.0;
#else
        // Soft membership: a VPL's share w_c in A_c ramps from 0 at M_c's border to 1 two
        // cells inside (1 everywhere in the coarsest), made monotone over the cascades
        // (M_{c-1} lies inside M_c); the ring R_c takes w_c - w_{c-1}. The lookup's sum
        // A_f + Σ_{c>f} R_c still counts each VPL once (w_f + (1 - w_f)), and a cascade that
        // moves with the camera moves its VPLs between grids gradually, not by whole cells.
        float wc = !inside ? 0.0 : (c == u_cascades - 1 ? 1.0 : clamp(lpv_member_margin(c, p) * 0.5, 0.0, 1.0));
        wc = max(wc, wprev);
        float a_c = wc, r_c = c > 0 ? wc - wprev : 0.0;
        wprev = wc;
        inside = inside && (a_c > 0.0 || r_c > 0.0);
#endif
        if (inside) {
            vec3 gp = lpv_cell_coord(c, p);
            vec3 gc = gp + u_inject_offset * n;
#ifdef LPV_SPLAT_NEAREST
            ivec3 cell = ivec3(floor(gc));
            if (a_c > 0.0) emit_cell(cell, lpv_slab_all(c), a_c * r, a_c * g, a_c * b);
            if (r_c > 0.0) emit_cell(cell, lpv_slab_ring(c), r_c * r, r_c * g, r_c * b);
#else
            // trilinear splat over the 8 cell centres around p + u_inject_offset cell · n, leaving out
            // centres behind the VPL's surface (its light would start behind the wall);
            // weights renormalised, so the VPL's flux is kept. A VPL moving with its light
            // moves its light between cells continuously (nearest-cell injection stepped).
            vec3 f = gc - 0.5;
            ivec3 base = ivec3(floor(f));
            vec3 t = f - vec3(base);
            float w[8];
            float wsum = 0.0;
            for (int k = 0; k < 8; ++k) {
                ivec3 o = ivec3(k & 1, (k >> 1) & 1, k >> 2);
                float wk = (o.x == 1 ? t.x : 1.0 - t.x) * (o.y == 1 ? t.y : 1.0 - t.y) * (o.z == 1 ? t.z : 1.0 - t.z);
                if (dot(vec3(base + o) + 0.5 - gp, n) <= 0.0) wk = 0.0;
                // blocked: a centre the geometry volume separates from the VPL (a thin wall
                // next to it) gets the share the blockers let through, as in the lookup
                if (u_use_gv == 1 && wk > 0.0) wk *= corner_transmittance(c, gc, base, base + o);
                w[k] = wk;
                wsum += wk;
            }
            if (wsum <= 1e-6) {  // a diagonal normal can leave every centre behind; the nearest cell
                ivec3 cell = ivec3(floor(gc));
                if (a_c > 0.0) emit_cell(cell, lpv_slab_all(c), a_c * r, a_c * g, a_c * b);
                if (r_c > 0.0) emit_cell(cell, lpv_slab_ring(c), r_c * r, r_c * g, r_c * b);
            } else {
                for (int k = 0; k < 8; ++k) {
                    if (w[k] <= 0.0) continue;
                    float s = w[k] / wsum;
                    ivec3 cell = base + ivec3(k & 1, (k >> 1) & 1, k >> 2);
                    if (a_c > 0.0) emit_cell(cell, lpv_slab_all(c), (s * a_c) * r, (s * a_c) * g, (s * a_c) * b);
                    if (r_c > 0.0) emit_cell(cell, lpv_slab_ring(c), (s * r_c) * r, (s * r_c) * g, (s * r_c) * b);
                }
            }
#endif
        }
        inner = inside;
    }
#endif
}
