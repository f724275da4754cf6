// brdf.glsl — the Principled BSDF subset GI Preview shades (Blender 4.x/5.x Principled v2):
// Lambertian diffuse under a dielectric GGX specular layer (diffuse weighted by one minus
// the specular layer's directional albedo), metals as GGX with Schlick/F82 Fresnel
// (F82 tint = white reduces to Schlick), multiple-scattering energy compensation
// (Fdez-Aguera 2019), height-correlated Smith masking (Heitz 2014), and visible-normal
// sampling (Heitz 2018, "Sampling the GGX Distribution of Visible Normals").
// Roughness is Blender's perceptual roughness; GGX alpha = roughness^2.
// Requires common.glsl and sampling.glsl.
#ifndef GI_BRDF_GLSL
#define GI_BRDF_GLSL

struct Surface {
    vec3 base_color;
    float metallic;
    float roughness;
    float alpha;        // GGX alpha (clamped away from 0 for the evaluation)
    float eta;          // effective IOR of the dielectric layer (after specular IOR level)
    float f0;           // dielectric normal-incidence reflectance
    vec3 spec_tint;
    vec3 emission;
};

float fresnel_dielectric(float cosi, float eta) {
    // Exact unpolarised Fresnel reflectance for a dielectric interface (from outside).
    float c = abs(cosi);
    float g = eta * eta - 1.0 + c * c;
    if (g <= 0.0) return 1.0;  // total internal reflection
    g = sqrt(g);
    float A = (g - c) / (g + c);
    float B = (c * (g + c) - 1.0) / (c * (g - c) + 1.0);
    return 0.5 * A * A * (1.0 + B * B);
}

vec3 fresnel_schlick(vec3 f0, float cosi) {
    float m = clamp(1.0 - cosi, 0.0, 1.0);
    float m5 = (m * m) * (m * m) * m;
    return f0 + (1.0 - f0) * m5;
}

Surface make_surface(Material m, vec3 base_color) {
    Surface s;
    s.base_color = base_color;
    s.metallic = clamp(m.params.x, 0.0, 1.0);
    s.roughness = clamp(m.params.y, 0.0, 1.0);
    s.alpha = max(s.roughness * s.roughness, 1e-4);
    float ior = max(m.params.z, 1.0001);
    float f0 = sqr((ior - 1.0) / (ior + 1.0));
    // Specular IOR Level: 0.5 leaves the IOR alone, 0 removes the reflection, 1 doubles F0.
    f0 = clamp(f0 * 2.0 * clamp(m.params.w, 0.0, 1.0), 0.0, 0.9999);
    float sf = sqrt(f0);
    s.f0 = f0;
    s.eta = (1.0 + sf) / max(1.0 - sf, 1e-4);
    s.spec_tint = m.spec_tint.rgb;
    s.emission = m.emission.rgb;
    return s;
}

// GGX normal distribution.
float ggx_D(float NoH, float a2) {
    float d = (NoH * a2 - NoH) * NoH + 1.0;
    return a2 / (PI * d * d);
}

// Smith G1 for GGX.
float ggx_G1(float NoX, float a2) {
    return 2.0 * NoX / (NoX + sqrt(a2 + (1.0 - a2) * NoX * NoX));
}

// Height-correlated visibility V = G2 / (4 NoL NoV).
float ggx_V(float NoV, float NoL, float a2) {
    float gv = NoL * sqrt(NoV * NoV * (1.0 - a2) + a2);
    float gl = NoV * sqrt(NoL * NoL * (1.0 - a2) + a2);
    return 0.5 / max(gv + gl, 1e-12);
}

// Directional albedo of single-scattering GGX, E = F0 * A + B (Karis 2014's analytic fit).
vec2 ggx_albedo_fit(float NoV, float roughness) {
    const vec4 c0 = vec4(-1.0, -0.0275, -0.572, 0.022);
    const vec4 c1 = vec4(1.0, 0.0425, 1.04, -0.04);
    vec4 r = roughness * c0 + c1;
    float a004 = min(r.x * r.x, exp2(-9.28 * NoV)) * r.x + r.y;
    return clamp(vec2(-1.04, 1.04) * a004 + r.zw, 0.0, 1.0);
}

// Albedo of the dielectric specular layer seen from NoV (with multiple-scattering compensation).
float dielectric_layer_albedo(Surface s, float NoV) {
    vec2 ab = ggx_albedo_fit(NoV, s.roughness);
    float ess = ab.x + ab.y;
    float e = s.f0 * ab.x + ab.y;
    return clamp(e + s.f0 * (1.0 - ess) , 0.0, 1.0) * step(1e-6, s.f0);
}

// Weights of the two lobes, for lobe selection in sampling (sum to 1).
vec2 lobe_weights(Surface s, float NoV) {
    float diff = (1.0 - s.metallic) * (1.0 - dielectric_layer_albedo(s, NoV)) * luminance(s.base_color);
    vec2 ab = ggx_albedo_fit(NoV, s.roughness);
    float spec_d = (1.0 - s.metallic) * dielectric_layer_albedo(s, NoV) * luminance(s.spec_tint);
    float spec_m = s.metallic * luminance(s.base_color * ab.x + ab.y);
    float spec = spec_d + spec_m;
    float tot = diff + spec;
    if (tot <= 0.0) return vec2(0.5, 0.5);
    return vec2(diff, spec) / tot;
}

struct BsdfEval {
    vec3 diffuse;   // f * cos for the diffuse lobe
    vec3 glossy;    // f * cos for the specular lobe
};

// BSDF times the cosine at L; N is the shading normal facing V.
BsdfEval eval_principled(Surface s, vec3 N, vec3 V, vec3 L) {
    BsdfEval e;
    e.diffuse = vec3(0.0);
    e.glossy = vec3(0.0);
    float NoL = dot(N, L);
    float NoV = max(dot(N, V), 1e-4);
    if (NoL <= 0.0) return e;
    vec3 H = normalize(V + L);
    float NoH = max(dot(N, H), 0.0);
    float VoH = max(dot(V, H), 0.0);
    float a2 = s.alpha * s.alpha;
    float DV = ggx_D(NoH, a2) * ggx_V(NoV, NoL, a2);
    vec2 ab = ggx_albedo_fit(NoV, s.roughness);
    float ess = max(ab.x + ab.y, 1e-3);
    // dielectric layer
    float Fd = fresnel_dielectric(VoH, s.eta) * step(1e-6, s.f0);
    float comp_d = 1.0 + s.f0 * (1.0 - ess) / ess;
    vec3 spec_d = s.spec_tint * (Fd * DV * comp_d);
    float layer = 1.0 - dielectric_layer_albedo(s, NoV);
    vec3 diff = s.base_color * (INV_PI * layer);
    // metal
    vec3 Fm = fresnel_schlick(s.base_color, VoH);
    vec3 comp_m = 1.0 + s.base_color * (1.0 - ess) / ess;
    vec3 spec_m = Fm * DV * comp_m;
    e.diffuse = (1.0 - s.metallic) * diff * NoL;
    e.glossy = mix(spec_d, spec_m, s.metallic) * NoL;
    return e;
}

// Visible-normal sampling of GGX (isotropic), in the local frame where N = +Z.
vec3 sample_ggx_vndf(vec3 Vl, float alpha, vec2 u) {
    vec3 Vh = normalize(vec3(alpha * Vl.x, alpha * Vl.y, Vl.z));
    float lensq = Vh.x * Vh.x + Vh.y * Vh.y;
    vec3 T1 = lensq > 0.0 ? vec3(-Vh.y, Vh.x, 0.0) * inversesqrt(lensq) : vec3(1.0, 0.0, 0.0);
    vec3 T2 = cross(Vh, T1);
    float r = sqrt(u.x);
    float phi = TWO_PI * u.y;
    float t1 = r * cos(phi);
    float t2 = r * sin(phi);
    float sv = 0.5 * (1.0 + Vh.z);
    t2 = (1.0 - sv) * sqrt(max(0.0, 1.0 - t1 * t1)) + sv * t2;
    vec3 Nh = t1 * T1 + t2 * T2 + sqrt(max(0.0, 1.0 - t1 * t1 - t2 * t2)) * Vh;
    return normalize(vec3(alpha * Nh.x, alpha * Nh.y, max(0.0, Nh.z)));
}

// pdf (solid angle, of L) of visible-normal sampling.
float ggx_vndf_pdf(float NoV, float NoH, float a2) {
    return ggx_G1(NoV, a2) * ggx_D(NoH, a2) / (4.0 * max(NoV, 1e-6));
}

// Sample L from the principled BSDF (lobe chosen by lobe_weights). Returns pdf via out.
vec3 sample_principled(Surface s, vec3 N, vec3 V, vec3 u, out float pdf) {
    float NoV = max(dot(N, V), 1e-4);
    vec2 w = lobe_weights(s, NoV);
    vec3 L;
    if (u.z < w.x) {
        L = to_world(sample_cosine_hemisphere(u.xy), N);
    } else {
        vec3 Vl = to_local(V, N);
        vec3 Hl = sample_ggx_vndf(Vl, s.alpha, u.xy);
        vec3 Ll = reflect(-Vl, Hl);
        L = to_world(Ll, N);
    }
    float NoL = dot(N, L);
    if (NoL <= 0.0) { pdf = 0.0; return L; }
    vec3 H = normalize(V + L);
    float a2 = s.alpha * s.alpha;
    pdf = w.x * NoL * INV_PI + w.y * ggx_vndf_pdf(NoV, max(dot(N, H), 0.0), a2);
    return L;
}

float pdf_principled(Surface s, vec3 N, vec3 V, vec3 L) {
    float NoL = dot(N, L);
    if (NoL <= 0.0) return 0.0;
    float NoV = max(dot(N, V), 1e-4);
    vec2 w = lobe_weights(s, NoV);
    vec3 H = normalize(V + L);
    float a2 = s.alpha * s.alpha;
    return w.x * NoL * INV_PI + w.y * ggx_vndf_pdf(NoV, max(dot(N, H), 0.0), a2);
}

#endif
