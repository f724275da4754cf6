// filters/common.glsl — helpers shared by the denoising filters (ATROUS, SVGF, TAA):
// albedo demodulation, finite checks for history taps, the edge-stopping geometry test.
// Requires lib/common.glsl and lib/screen.glsl.
#ifndef GI_FILTERS_COMMON_GLSL
#define GI_FILTERS_COMMON_GLSL

// the albedo a pixel's illumination is divided by (Schied 2017 §4.1): base colour, floored
// so that black or dark texels do not blow the noise up (remodulation undoes it exactly)
vec3 demod_albedo(vec3 base) { return max(base, vec3(0.02)); }

// Emission of the G-buffer surface at px (gbuffer.emission: textured; zero on background):
// radiance the camera sees directly, not multiplied by the albedo, so it must bypass
// demodulation (illumination = (colour - emission) / albedo; colour = illumination x albedo +
// emission). Dividing it by a small albedo and spreading it over the neighbours made fireflies.
uniform sampler2D u_gb_emission;
vec3 gb_emission(vec4 pos, ivec2 px) {
    if (pos.w < 0.0) return vec3(0.0);
    return max(texelFetch(u_gb_emission, px, 0).rgb, vec3(0.0));
}

bool finite4(vec4 v) { return !(any(isnan(v)) || any(isinf(v))); }

// distance of Q from P's tangent plane, in pixel footprints at P's depth
float plane_pixels(vec3 P, vec3 N, vec3 Q) {
    return abs(dot(N, Q - P)) * pixels_per_unit(view_depth(P));
}

// G-buffer texel (position pq, w < 0: background; normal nq) on the surface of the pixel at P
// with normal N: within 2 pixel footprints of its tangent plane and normal within ~25 degrees
bool same_surface_texel(vec3 P, vec3 N, vec4 pq, vec3 nq) {
    return pq.w >= 0.0 && plane_pixels(P, N, pq.xyz) <= 2.0 && dot(N, nq) > 0.9;
}

// B3-spline 5-tap kernel of the à-trous wavelet (Dammertz et al. 2010)
const float ATROUS_H[5] = float[5](1.0 / 16.0, 1.0 / 4.0, 3.0 / 8.0, 1.0 / 4.0, 1.0 / 16.0);

#endif
