// lpv_inject.vert — one RSM texel (VPL) or G-buffer pixel (surfel) per vertex, no
// attributes (gl_VertexID): fetches it and hands it to lpv_inject.geom, which routes it
// into the cells of the light volumes (LPV_GV: of the geometry volume).
uniform sampler2D u_rsm_pos;   // LPV_GV_GBUFFER: the G-buffer's position
uniform sampler2D u_rsm_nrm;   // LPV_GV_GBUFFER: the G-buffer's normal
uniform sampler2D u_rsm_flux;
uniform int u_atlas_w;
#ifdef LPV_GV_GBUFFER
uniform vec3 u_camera_pos;
uniform float u_pixel_size;  // pixel size on the image plane at distance 1
#endif

out vec3 v_pos;
out vec3 v_nrm;
out vec4 v_val;  // rgb flux (W), a = surfel area (m²); a < 0: nothing to inject

void main() {
    ivec2 t = ivec2(gl_VertexID % u_atlas_w, gl_VertexID / u_atlas_w);
    vec4 p = texelFetch(u_rsm_pos, t, 0);
    vec4 n = texelFetch(u_rsm_nrm, t, 0);
    gl_Position = vec4(2.0, 2.0, 0.0, 1.0);
    v_pos = p.xyz;
    v_nrm = normalize(n.xyz + vec3(0.0, 0.0, 1e-12));
#ifdef LPV_GV_GBUFFER
    // the surfel of the pixel's footprint (w < 0: background)
    if (p.w < 0.0) { v_val = vec4(-1.0); return; }
    vec3 dv = p.xyz - u_camera_pos;
    float cosv = max(abs(dot(normalize(dv), v_nrm)), 0.05);
    v_val = vec4(1.0, 1.0, 1.0, u_pixel_size * u_pixel_size * dot(dv, dv) / cosv);
#else
    vec3 flux = texelFetch(u_rsm_flux, t, 0).rgb;
    bool ok = p.w >= 0.5;
#ifndef LPV_GV
    ok = ok && max(flux.r, max(flux.g, flux.b)) > 0.0;
#endif
    v_val = ok ? vec4(flux, n.w) : vec4(-1.0);
#endif
}
