// lpv_common.glsl — the cascades of the light propagation volume (passes/lpv.py).
// Cascade c: a grid of u_grid^3 cells, corner u_lpv_origin[c].xyz, cell size .w (doubling
// per cascade, corners snapped to the cell size, nested). Light volumes are slabs of
// u_grid layers of 2D-array textures: slab c (c < u_cascades) holds A_c, the light of every
// VPL inside the membership box M_c of cascade c; slab u_cascades + c - 1 (c >= 1) holds the
// ring R_c, the VPLs inside M_c but not inside M_{c-1}. M_c is the grid shrunk by one cell
// (a VPL shifted half a cell along its normal stays in the grid). The geometry volume has
// one slab per cascade; texel (i, j, k) channel a is the blocking between the centres of
// cell (i, j, k) and its neighbour + e_a (the surfels in that staggered cell).
#ifndef GI_LPV_COMMON_GLSL
#define GI_LPV_COMMON_GLSL
#define LPV_MAX_CASCADES 4

uniform int u_grid;
uniform int u_cascades;
uniform vec4 u_lpv_origin[LPV_MAX_CASCADES];  // xyz grid corner, w = cell size

// position in cell units of cascade c (cell centres at integer + 0.5)
vec3 lpv_cell_coord(int c, vec3 p) { return (p - u_lpv_origin[c].xyz) / u_lpv_origin[c].w; }

// is p inside the membership box M_c (the grid shrunk by one cell)?
bool lpv_in_member(int c, vec3 p) {
    vec3 g = lpv_cell_coord(c, p);
    return all(greaterThanEqual(g, vec3(1.0))) && all(lessThan(g, vec3(float(u_grid - 1))));
}

// distance (cells) from p to the border of M_c (negative outside)
float lpv_member_margin(int c, vec3 p) {
    vec3 g = lpv_cell_coord(c, p);
    vec3 m = min(g - 1.0, float(u_grid - 1) - g);
    return min(m.x, min(m.y, m.z));
}

int lpv_slab_all(int c) { return c; }
int lpv_slab_ring(int c) { return u_cascades + c - 1; }

#ifdef LPV_CORNER_TRANSMITTANCE
uniform sampler2DArray u_gv;
uniform sampler2DArray u_gvd;  // per axis: blocking x the blockers' position (cell units)

// Geometry-volume transmittance from a point g (cell units: the lookup point, or an
// injected VPL's centre in front of its surface) to the centre of
// corner cell cc: per axis a, the segment from g to cc's centre lies in the staggered cell
// b_a between the two trilinear centres; its blockers (blocking B_a, mean position D_a / B_a
// along the axis from the depth volume) cut the weight by 1 - B_a only when they lie on the
// segment. A wall inside the staggered cell thus separates the corners on its far side from
// the point and leaves those on the point's side (without the position, a wall crossing the
// staggered cell blocked every corner along that axis, and the lookup fell back to all
// corners: the roof's light showed on the tops of the sun-lit room's walls, relMSE 0.089).
float corner_transmittance(int c, vec3 g, ivec3 b, ivec3 cc) {
    float tr = 1.0;
    for (int a = 0; a < 3; ++a) {
        int fa = b[a];
        if (fa < 0 || fa >= u_grid) continue;
        ivec3 fi = cc;
        fi[a] = fa;
        ivec3 tc = ivec3(fi.xy, fi.z + c * u_grid);
        float B = texelFetch(u_gv, tc, 0)[a];
        if (B <= 1e-6) continue;
        float D = texelFetch(u_gvd, tc, 0)[a] / B;
        float lo = min(g[a], float(cc[a]) + 0.5), hi = max(g[a], float(cc[a]) + 0.5);
        if (D < lo || D > hi) continue;
        tr *= 1.0 - clamp(B, 0.0, 1.0);
    }
    return tr;
}
#endif
#endif
