// filters/common.glsl — helpers shared by the denoising filters (ATROUS, SVGF, TAA):
// albedo demodulation, finite checks for history taps, the edge-stopping geometry test.
// Requires lib/common.glsl and lib/screen.glsl.
#ifndef GI_FILTERS_COMMON_GLSL
#define GI_FILTERS_COMMON_GLSL

// The albedo a pixel's illumination is divided by (Schied 2017 §4.1): the directional albedo
// of the whole surface seen from the camera, diffuse plus glossy (lib/albedo.glsl), floored so
// that black texels do not blow the noise up; remodulation undoes it exactly. The base colour
// alone would divide a dark glossy texel's reflection by its dark diffuse colour, and the
// filter would spread that amplified reflection over the light texels beside it (a checkered
// glossy floor came out yellow: ATROUS 0.60 relMSE against Cycles).
// Defined where lib/albedo.glsl (and so lib/brdf.glsl and USE_SCENE_BUFFERS) is included.
// G-buffer texels: albedo, normal (w = roughness), geonormal (w = metallic), position (w =
// material id).
#ifdef GI_ALBEDO_GLSL
vec3 demod_albedo(vec4 albedo, vec4 normal, vec4 geonormal, vec4 pos, vec3 V) {
    Surface s = gbuffer_surface(materials[int(pos.w)], albedo, normal, geonormal, vec3(0.0));
    float NoV = clamp(dot(normalize(normal.xyz + vec3(0.0, 0.0, 1e-12)), V), 1e-4, 1.0);
    return max(diffuse_albedo(s, NoV) + specular_albedo(s, NoV), vec3(0.02));
}
#endif

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
