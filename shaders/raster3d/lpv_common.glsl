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
#endif
