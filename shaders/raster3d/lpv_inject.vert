// lpv_inject.vert — one RSM texel (VPL) per vertex (no attributes: gl_VertexID): finds the
// finest cascade containing the VPL shifted half a cell along its normal, and the cell.
// LPV_GV: the geometry volume instead (the texel's surfel, unshifted, into each cascade).
#include "lib/sh.glsl"
#define LPV_MAX_CASCADES 4

uniform sampler2D u_rsm_pos;
uniform sampler2D u_rsm_nrm;
uniform sampler2D u_rsm_flux;
uniform int u_atlas_w;
uniform int u_grid;
uniform int u_cascades;
uniform vec4 u_lpv_origin[LPV_MAX_CASCADES];  // xyz grid corner, w = cell size
uniform int u_only_cascade;

out vec4 v_r;
out vec4 v_g;
out vec4 v_b;
flat out int v_layer;

#ifdef LPV_GV_GBUFFER
uniform vec3 u_camera_pos;
uniform float u_pixel_size;  // pixel size on the image plane at distance 1
#endif

void main() {
    ivec2 t = ivec2(gl_VertexID % u_atlas_w, gl_VertexID / u_atlas_w);
    vec4 p = texelFetch(u_rsm_pos, t, 0);
    vec3 n = texelFetch(u_rsm_nrm, t, 0).xyz;
    vec3 flux = texelFetch(u_rsm_flux, t, 0).rgb;
#ifdef LPV_GV_GBUFFER
    // the G-buffer's surfels (u_rsm_pos/nrm bound to the G-buffer): area of the pixel's footprint
    float surfel_area = 0.0;
    if (p.w >= 0.0) {
        vec3 dv = p.xyz - u_camera_pos;
        float cosv = max(abs(dot(normalize(dv), n)), 0.05);
        surfel_area = u_pixel_size * u_pixel_size * dot(dv, dv) / cosv;
    }
    p.w = p.w >= 0.0 ? 1.0 : 0.0;
    flux = vec3(1.0);
#else
    float surfel_area = texelFetch(u_rsm_nrm, t, 0).w;
#endif
    v_layer = -1;
    gl_Position = vec4(2.0, 2.0, 0.0, 1.0);
    if (p.w < 0.5 || max(flux.r, max(flux.g, flux.b)) <= 0.0) return;
    for (int c = 0; c < u_cascades; ++c) {
        float cs = u_lpv_origin[c].w;
#ifdef LPV_GV
        // geometry volume: the surfel's blocking potential in the cell that contains it, in
        // every cascade (one draw per cascade: u_only_cascade)
        if (c != u_only_cascade) continue;
        vec3 g = (p.xyz - u_lpv_origin[c].xyz) / cs;
#else
        vec3 g = (p.xyz + 0.5 * cs * n - u_lpv_origin[c].xyz) / cs;
#endif
        if (all(greaterThanEqual(g, vec3(0.0))) && all(lessThan(g, vec3(float(u_grid))))) {
            ivec3 cell = ivec3(floor(g));
            gl_Position = vec4((vec2(cell.xy) + 0.5) / float(u_grid) * 2.0 - 1.0, 0.0, 1.0);
            v_layer = cell.z + c * u_grid;
#ifdef LPV_GV
            // isotropic blocking (a 2-band SH of |n.w| is isotropic): area over the cell's
            // face area, i.e. the fraction of the face a perpendicular surfel covers
            v_r = vec4(surfel_area / (cs * cs), 0.0, 0.0, 0.0);
            v_g = v_r;
            v_b = v_r;
            return;
#endif
            // a Lambertian VPL: intensity Φ/π max(0, n.w) (W/sr)
            vec4 lobe = sh_cosine_lobe(n) * (1.0 / 3.14159265358979);
            v_r = lobe * flux.r;
            v_g = lobe * flux.g;
            v_b = lobe * flux.b;
            return;
        }
    }
}
