// sh.glsl — 2-band real spherical harmonics (4 coefficients), shared by every technique
// that stores directional light in SH (LPV; probes may use it too).
// Basis: Y00 = 0.282095, Y1 = 0.488603 * (x, y, z) (orthonormal, so the integral of a
// product of two projected functions is the dot product of their coefficients).
// Clamped cosine lobe max(0, n.w) projected: (π·Y00, 2π/3·0.488603·n) =
// (0.886227, 1.023327·n); its integral over the sphere is π.
#ifndef GI_SH_GLSL
#define GI_SH_GLSL

const float SH_Y00 = 0.28209479177;
const float SH_Y1 = 0.48860251190;
const float SH_COS0 = 0.88622692545;  // π · Y00
const float SH_COS1 = 1.02332670795;  // 2π/3 · Y1

vec4 sh_basis(vec3 w) { return vec4(SH_Y00, SH_Y1 * w); }

// Coefficients of max(0, dot(n, w)) (n unit).
vec4 sh_cosine_lobe(vec3 n) { return vec4(SH_COS0, SH_COS1 * n); }

float sh_eval(vec4 c, vec3 w) { return dot(c, sh_basis(w)); }

// ∫ f(w) max(0, dot(n, w)) dw for f given by its coefficients c.
float sh_cosine_integral(vec4 c, vec3 n) { return dot(c, sh_cosine_lobe(n)); }

#endif
