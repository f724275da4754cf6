// brdf.glsl — the Principled BSDF subset GI Preview shades, as Cycles evaluates it
// (Blender 4.x/5.x Principled v2, Multiscatter GGX, the default):
// * dielectric specular layer: GGX with the exact dielectric Fresnel remapped to
//   [f0 * specular tint, 1] (Cycles' generalized Schlick with exponent -eta);
// * metal: GGX with the F82-tint Fresnel (F0 = base colour, tint = specular tint; a white
//   tint reduces it to Schlick);
// * multiple-scattering energy preservation as Cycles does it: each GGX lobe is scaled by
//   1 + Fms (1 - E) / E with E the tabulated GGX albedo and Fms = Fss Eavg / (1 - Fss (1 - Eavg))
//   (Kulla & Conty 2017), Fss the lobe's hemispherical-average Fresnel;
// * Lambertian diffuse weighted by 1 - max(albedo of the specular layer) with the layer's
//   albedo E (1 + Fms (1-E)/E) mix(f0, 1, s), s from the tabulated Fresnel average
//   (Cycles' closure_layering_weight / bsdf_microfacet_estimate_albedo);
// * height-correlated Smith masking (Heitz 2014), visible-normal sampling (Heitz 2018).
// The tables (lib/brdf_tables.glsl) are recomputed by scripts/gen_brdf_tables.py with
// Cycles' definitions, grids and bilinear lookup. Roughness is Blender's perceptual
// roughness; GGX alpha = roughness^2. Requires common.glsl and sampling.glsl.
#ifndef GI_BRDF_GLSL
#define GI_BRDF_GLSL

#include "lib/brdf_tables.glsl"

struct Surface {
    vec3 base_color;
    float metallic;
    float roughness;
    float alpha;        // GGX alpha (clamped away from 0 for the evaluation)
    float eta;          // effective IOR of the dielectric layer (after specular IOR level)
    float f0;           // dielectric normal-incidence reflectance
    vec3 spec_tint;
    vec3 emission;
    // the lobe (lib/common.glsl BSDF_*), as the path tracer reads it; the G-buffer family
    // builds every surface as an opaque Principled one (kind 0, transmission 0)
    int kind;
    float transmission; // Principled Transmission Weight
    float ior;          // the IOR input as given (refraction: ior entering, 1 / ior leaving)
    bool backfacing;    // the ray arrived on the back of the triangle (Cycles' SD_BACKFACING)
    bool transmits;     // some lobe of the material transmits (light below the surface counts)
    int material;       // record of the material whose lobe list the path tracer evaluates, -1 none
    vec2 uv;            // where the lobes' textures are sampled
    vec3 ns;            // the smooth normal under a normal / bump map (Cycles' sd->N); 0 = none
    bool bump_correction; // soften diffuse light at grazing angles when N != ns (Bump Map Correction)
    float coat;         // Principled coat weight (0: none)
    float coat_alpha;   // coat GGX alpha
    float coat_ior;
    vec3 coat_tint;
    vec3 coat_n;        // the coat's normal (Cycles: the smooth normal); 0 = the shading normal
    float sheen;        // Principled sheen weight (0: none)
    float sheen_rough;
    vec3 sheen_tint;
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
    s.kind = int(m.bsdf.x + 0.5);
    s.transmission = clamp(m.bsdf.y, 0.0, 1.0);
    s.ior = max(m.params.z, 1e-5);
    s.backfacing = false;
    s.transmits = false;
    s.material = -1;
    s.uv = vec2(0.0);
    s.ns = vec3(0.0);
    s.bump_correction = m.lobes.w > 0.5;
    s.coat = clamp(m.coat.x, 0.0, 1.0);
    s.coat_alpha = max(sqr(clamp(m.coat.y, 0.0, 1.0)), 1e-4);
    s.coat_ior = max(m.coat.z, 1.0001);
    s.coat_tint = m.coat_tint.rgb;
    s.coat_n = vec3(0.0);
    s.sheen = max(m.coat_tint.w, 0.0);
    s.sheen_rough = clamp(m.sheen.w, 0.0, 1.0);
    s.sheen_tint = max(m.sheen.rgb, vec3(0.0));
    return s;
}

// The surface at a G-buffer texel: the material record with the textured inputs the
// G-buffer stored (raster/gbuffer.frag): albedo = (base colour, specular IOR level),
// normal.w = roughness, geonormal.w = metallic; emission from gbuffer.emission where the
// reader binds it (else the record's).
Surface gbuffer_surface(Material m, vec4 albedo, vec4 normal, vec4 geonormal, vec3 emission) {
    m.params.x = geonormal.w;
    m.params.y = normal.w;
    m.params.w = albedo.w;
    m.emission.rgb = emission;
    return make_surface(m, albedo.rgb);
}

// GGX normal distribution. The denominator is written as sin^2 + cos^2 a2 so that it stays
// positive in float32 for a mirror (a2 = 1e-8 at roughness 0: the usual (a2 - 1) NoH^2 + 1
// rounds a2 - 1 to -1 and gives 0 at NoH = 1, i.e. D = inf and f / pdf = NaN).
float ggx_D(float NoH, float a2) {
    float c2 = NoH * NoH;
    float d = max(1.0 - c2, 0.0) + c2 * a2;
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

// ---- Cycles' tables (lookup_table_read: bilinear, grid i/(size-1), clamped)
float ggx_E(float rough, float mu) {
    float x = clamp(rough, 0.0, 1.0) * 31.0, y = clamp(mu, 0.0, 1.0) * 31.0;
    int i0 = min(int(x), 31), j0 = min(int(y), 31);
    int i1 = min(i0 + 1, 31), j1 = min(j0 + 1, 31);
    float tx = x - float(i0), ty = y - float(j0);
    float a = mix(GGX_E_at(i0 * 32 + j0), GGX_E_at(i1 * 32 + j0), tx);
    float b = mix(GGX_E_at(i0 * 32 + j1), GGX_E_at(i1 * 32 + j1), tx);
    return max(mix(a, b, ty), 1e-4);
}

float ggx_Eavg(float rough) {
    float x = clamp(rough, 0.0, 1.0) * 31.0;
    int i0 = min(int(x), 31), i1 = min(i0 + 1, 31);
    return mix(GGX_EAVG_at(i0), GGX_EAVG_at(i1), x - float(i0));
}

float _schlick_s_at(int k, float x, float y) {
    int i0 = min(int(x), 15), j0 = min(int(y), 15);
    int i1 = min(i0 + 1, 15), j1 = min(j0 + 1, 15);
    float tx = x - float(i0), ty = y - float(j0);
    int o = k * 256;
    float a = mix(GGX_SCHLICK_S_at(o + j0 * 16 + i0), GGX_SCHLICK_S_at(o + j0 * 16 + i1), tx);
    float b = mix(GGX_SCHLICK_S_at(o + j1 * 16 + i0), GGX_SCHLICK_S_at(o + j1 * 16 + i1), tx);
    return mix(a, b, ty);
}

// Fresnel blend factor of the dielectric layer averaged over the GGX lobe (ggx_gen_schlick_ior_s).
float ggx_schlick_s(float rough, float mu, float eta) {
    float z = sqrt(abs((eta - 1.0) / (eta + 1.0))) * 15.0;
    float x = clamp(rough, 0.0, 1.0) * 15.0, y = clamp(mu, 0.0, 1.0) * 15.0;
    z = clamp(z, 0.0, 15.0);
    int k0 = min(int(z), 15), k1 = min(k0 + 1, 15);
    return mix(_schlick_s_at(k0, x, y), _schlick_s_at(k1, x, y), z - float(k0));
}

// Multiple-scattering scale of a GGX lobe with hemispherical-average Fresnel Fss (Cycles'
// microfacet_ggx_preserve_energy: energy_scale * darkening).
vec3 ggx_ms_scale(float E, float Eavg, vec3 Fss) {
    vec3 Fms = Fss * Eavg / max(1.0 - Fss * (1.0 - Eavg), vec3(1e-6));
    return 1.0 + Fms * ((1.0 - E) / E);
}

// Dielectric layer: f0 with the tint, and its average Fresnel Fss (Kulla & Conty's fit).
vec3 dielectric_f0(Surface s) { return s.f0 * s.spec_tint; }
vec3 dielectric_Fss(Surface s) {
    float real_fss = (s.eta - 1.0) / (4.08567 + 1.00071 * s.eta);
    float t = clamp((real_fss - s.f0) / max(1.0 - s.f0, 1e-6), 0.0, 1.0);
    return mix(dielectric_f0(s), vec3(1.0), t);
}

// Metal: F82-tint (Cycles' fresnel_f82tint): b from the tint, F = Schlick - b cos (1-cos)^6.
vec3 metal_f82_b(Surface s) {
    const float f = 6.0 / 7.0;
    const float f5 = f * f * f * f * f;
    vec3 tint = min(s.spec_tint, vec3(1.0));
    vec3 schlick = mix(s.base_color, vec3(1.0), f5);
    return schlick * (7.0 / (f5 * f)) * (1.0 - tint);
}
vec3 fresnel_f82_tint(vec3 f0, vec3 b, float cosi) {
    float m = clamp(1.0 - cosi, 0.0, 1.0);
    float m5 = (m * m) * (m * m) * m;
    return clamp(mix(f0, vec3(1.0), m5) - b * cosi * m5 * m, 0.0, 1.0);
}
vec3 metal_Fss(Surface s) {
    return clamp(mix(s.base_color, vec3(1.0), 1.0 / 21.0) - metal_f82_b(s) / 126.0, 0.0, 1.0);
}

// Albedo of the dielectric specular layer seen from NoV (what Cycles takes off the diffuse),
// as a scalar (closure_layering_weight takes the max over channels).
float dielectric_layer_albedo(Surface s, float NoV) {
    if (s.f0 <= 1e-6) return 0.0;
    float E = ggx_E(s.roughness, NoV);
    vec3 ms = ggx_ms_scale(E, ggx_Eavg(s.roughness), dielectric_Fss(s));
    float sv = ggx_schlick_s(s.roughness, NoV, s.eta);
    vec3 a = E * ms * mix(dielectric_f0(s), vec3(1.0), sv);
    return clamp(max3(a), 0.0, 1.0);
}

// The surface's diffuse lobe alone, as a Surface (base colour times (1 - metallic) times
// (1 - its dielectric layer's albedo seen from NoV), no specular): the lobe eval_principled
// gives, for light paths one light sample per ray would turn into fireflies through the
// glossy lobe (SSDO's traced senders, SSR's miss trace on near-mirror hits).
Surface surface_diffuse_only(Surface s, float NoV) {
    float layer = (s.f0 > 1e-6 && s.metallic < 1.0) ? dielectric_layer_albedo(s, NoV) : 0.0;
    s.base_color *= (1.0 - s.metallic) * (1.0 - layer);
    s.metallic = 0.0;
    s.f0 = 0.0;
    return s;
}

// Approximate albedo of the metal lobe (for lobe selection only).
vec3 metal_albedo_estimate(Surface s, float NoV) {
    float E = ggx_E(s.roughness, NoV);
    vec3 Fss = metal_Fss(s);
    return clamp(E * ggx_ms_scale(E, ggx_Eavg(s.roughness), Fss) * Fss, 0.0, 1.0);
}

// Weights of the two lobes, for lobe selection in sampling (sum to 1).
vec2 lobe_weights(Surface s, float NoV) {
    float layer = dielectric_layer_albedo(s, NoV);
    float diff = (1.0 - s.metallic) * (1.0 - layer) * luminance(s.base_color);
    float spec_d = (1.0 - s.metallic) * layer;
    float spec_m = s.metallic * luminance(metal_albedo_estimate(s, NoV));
    float spec = spec_d + spec_m;
    float tot = diff + spec;
    if (tot <= 0.0) return vec2(0.5, 0.5);
    return vec2(diff, spec) / tot;
}

float ggx_vndf_pdf(float NoV, float NoH, float a2);

// ---- Principled sheen: Cycles' microfiber sheen (Zeltner et al. 2022, an LTC fit) with its
// directional albedo A(roughness, cos) measured from Cycles (render/sheen_table.py) and the lobe's
// shape approximated by the Charlie distribution (Estevez & Kulla 2017) of alpha = roughness^2
// with Neubelt & Pettineo's visibility, scaled to albedo A (its own albedo E: SHEEN_E,
// gen_brdf_tables.py). As in Cycles it is the top layer, scaling everything below by
// 1 - weight * max(tint) * A.
float sheen_table(bool cycles, float rough, float mu) {
    float x = clamp(rough, 0.0, 1.0) * 31.0, y = clamp(mu, 0.0, 1.0) * 31.0;
    int i0 = min(int(x), 31), j0 = min(int(y), 31);
    int i1 = min(i0 + 1, 31), j1 = min(j0 + 1, 31);
    float tx = x - float(i0), ty = y - float(j0);
    float v00 = cycles ? SHEEN_ALBEDO_at(i0 * 32 + j0) : SHEEN_E_at(i0 * 32 + j0);
    float v10 = cycles ? SHEEN_ALBEDO_at(i1 * 32 + j0) : SHEEN_E_at(i1 * 32 + j0);
    float v01 = cycles ? SHEEN_ALBEDO_at(i0 * 32 + j1) : SHEEN_E_at(i0 * 32 + j1);
    float v11 = cycles ? SHEEN_ALBEDO_at(i1 * 32 + j1) : SHEEN_E_at(i1 * 32 + j1);
    return mix(mix(v00, v10, tx), mix(v01, v11, tx), ty);
}
float sheen_E(float rough, float mu) { return sheen_table(false, rough, mu); }
float sheen_A(float rough, float mu) { return max(sheen_table(true, rough, mu), 0.0); }

float sheen_attenuation(Surface s, float NoV) {
    if (s.sheen <= 0.0) return 1.0;
    return clamp(1.0 - s.sheen * max3(s.sheen_tint) * sheen_A(s.sheen_rough, NoV), 0.0, 1.0);
}

vec3 sheen_eval(Surface s, vec3 N, vec3 V, vec3 L) {
    if (s.sheen <= 0.0) return vec3(0.0);
    float NoL = dot(N, L), NoV = max(dot(N, V), 1e-4);
    if (NoL <= 0.0) return vec3(0.0);
    float a = clamp(s.sheen_rough * s.sheen_rough, 0.01, 1.0);
    vec3 H = normalize(V + L);
    float sin2 = max(1.0 - sqr(dot(N, H)), 0.0);
    float D = (2.0 + 1.0 / a) * pow(sin2, 0.5 / a) * (0.5 * INV_PI);
    float vis = 1.0 / (4.0 * (NoL + NoV - NoL * NoV));
    float k = sheen_A(s.sheen_rough, NoV) / max(sheen_E(s.sheen_rough, NoV), 1e-4);
    return s.sheen * s.sheen_tint * (D * vis * NoL * k);
}

// Probability of sampling the sheen (cosine-weighted) rather than the layers below.
float sheen_select(Surface s, float NoV) {
    if (s.sheen <= 0.0) return 0.0;
    float e = s.sheen * luminance(s.sheen_tint) * sheen_A(s.sheen_rough, NoV);
    return clamp(e / max(e + sheen_attenuation(s, NoV) * max(luminance(s.base_color) + s.f0 + s.metallic, 0.05), 1e-6),
                 0.0, 0.9);
}

// ---- Principled coat (Cycles: a GGX dielectric reflection of weight Coat Weight on top; the
// layers below scaled by 1 - weight * F(cos(Nc, V), coat IOR) (the coat's albedo, Fresnel of a
// smooth interface) and by mix(1, tint^(1 / cos(refracted V)), weight), the tint's absorption
// along the path through a coat of unit thickness). Nc: the coat normal facing V.
vec3 coat_normal(Surface s, vec3 N) {
    vec3 n = dot(s.coat_n, s.coat_n) > 0.0 ? s.coat_n : N;
    return dot(n, N) < 0.0 ? -n : n;
}

vec3 coat_attenuation(Surface s, vec3 N, vec3 V) {
    if (s.coat <= 0.0) return vec3(1.0);
    vec3 Nc = coat_normal(s, N);
    float cosNI = dot(V, Nc);
    float a = 1.0 - s.coat * (cosNI > 0.0 ? fresnel_dielectric(cosNI, s.coat_ior) : 0.0);
    vec3 t = vec3(1.0);
    if (s.coat_tint != vec3(1.0)) {
        float cosNT = sqrt(max(1.0 - (1.0 - cosNI * cosNI) / (s.coat_ior * s.coat_ior), 1e-8));
        t = mix(vec3(1.0), pow(clamp(s.coat_tint, 0.0, 1.0), vec3(1.0 / cosNT)), s.coat);
    }
    return a * t;
}

// The coat lobe, f * cos (single-scattering GGX with exact dielectric Fresnel).
vec3 coat_eval(Surface s, vec3 N, vec3 V, vec3 L) {
    if (s.coat <= 0.0) return vec3(0.0);
    vec3 Nc = coat_normal(s, N);
    float NoL = dot(Nc, L), NoV = dot(Nc, V);
    if (NoL <= 0.0 || NoV <= 0.0) return vec3(0.0);
    vec3 H = normalize(V + L);
    float a2 = s.coat_alpha * s.coat_alpha;
    float F = fresnel_dielectric(max(dot(V, H), 0.0), s.coat_ior);
    return vec3(s.coat * F * ggx_D(max(dot(Nc, H), 0.0), a2) * ggx_V(NoV, NoL, a2) * NoL);
}

float coat_pdf(Surface s, vec3 N, vec3 V, vec3 L) {
    vec3 Nc = coat_normal(s, N);
    float NoL = dot(Nc, L), NoV = dot(Nc, V);
    if (NoL <= 0.0 || NoV <= 0.0) return 0.0;
    return ggx_vndf_pdf(NoV, max(dot(Nc, normalize(V + L)), 0.0), s.coat_alpha * s.coat_alpha);
}

// Probability of sampling the coat lobe: its albedo against what it leaves to the layers below.
float coat_select(Surface s, vec3 N, vec3 V) {
    if (s.coat <= 0.0) return 0.0;
    vec3 Nc = coat_normal(s, N);
    float cosNI = max(dot(V, Nc), 1e-4);
    float c = s.coat * fresnel_dielectric(cosNI, s.coat_ior);
    float below = luminance(coat_attenuation(s, N, V)) * max(luminance(s.base_color) + s.f0 + s.metallic, 0.05);
    return clamp(c / max(c + below, 1e-6), 0.0, 0.95);
}

struct BsdfEval {
    vec3 diffuse;   // f * cos for the diffuse lobe
    vec3 glossy;    // f * cos for the specular lobe
};

// BSDF times the cosine at L; N is the shading normal facing V. `keep` scales the
// dielectric part (diffuse and its specular layer) and leaves the metal alone: 1 - the
// transmission weight, as Cycles layers a Principled BSDF (metal, then glass, then the rest).
BsdfEval eval_principled_keep(Surface s, vec3 N, vec3 V, vec3 L, float keep) {
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
    float E = ggx_E(s.roughness, NoV);
    float Eavg = ggx_Eavg(s.roughness);
    // dielectric layer: exact Fresnel remapped to [f0 * tint, 1]
    vec3 spec_d = vec3(0.0);
    float layer = 0.0;
    if (s.f0 > 1e-6 && s.metallic < 1.0) {
        float Fr = fresnel_dielectric(VoH, s.eta);
        float sF = clamp((Fr - s.f0) / max(1.0 - s.f0, 1e-6), 0.0, 1.0);
        spec_d = mix(dielectric_f0(s), vec3(1.0), sF) * DV * ggx_ms_scale(E, Eavg, dielectric_Fss(s));
        layer = dielectric_layer_albedo(s, NoV);
    }
    vec3 diff = s.base_color * (INV_PI * (1.0 - layer));
    // metal: F82-tint
    vec3 spec_m = vec3(0.0);
    if (s.metallic > 0.0) {
        vec3 Fm = fresnel_f82_tint(s.base_color, metal_f82_b(s), VoH);
        spec_m = Fm * DV * ggx_ms_scale(E, Eavg, metal_Fss(s));
    }
    e.diffuse = (1.0 - s.metallic) * diff * NoL * keep;
    e.glossy = mix(spec_d * keep, spec_m, s.metallic) * NoL;
    if (s.coat > 0.0) {
        vec3 att = coat_attenuation(s, N, V);
        e.diffuse *= att;
        e.glossy = e.glossy * att + coat_eval(s, N, V, L);
    }
    if (s.sheen > 0.0) {
        float att = sheen_attenuation(s, NoV);
        e.diffuse = e.diffuse * att + sheen_eval(s, N, V, L);
        e.glossy *= att;
    }
    return e;
}

BsdfEval eval_principled(Surface s, vec3 N, vec3 V, vec3 L) { return eval_principled_keep(s, N, V, L, 1.0); }

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

float pdf_principled(Surface s, vec3 N, vec3 V, vec3 L);

// Sample L from the principled BSDF (the coat with probability coat_select, else a lobe chosen
// by lobe_weights). Returns pdf via out.
vec3 sample_principled(Surface s, vec3 N, vec3 V, vec3 u, out float pdf) {
    float psh = sheen_select(s, max(dot(N, V), 1e-4));
    if (u.z < psh) {
        vec3 L = to_world(sample_cosine_hemisphere(u.xy), N);
        pdf = pdf_principled(s, N, V, L);
        return L;
    }
    u.z = psh > 0.0 ? clamp((u.z - psh) / (1.0 - psh), 0.0, 0.99999994) : u.z;
    float pc = coat_select(s, N, V);
    if (u.z < pc) {
        vec3 Nc = coat_normal(s, N);
        vec3 Vl = to_local(V, Nc);
        vec3 L = to_world(reflect(-Vl, sample_ggx_vndf(Vl, s.coat_alpha, u.xy)), Nc);
        pdf = pdf_principled(s, N, V, L);
        return L;
    }
    u.z = pc > 0.0 ? clamp((u.z - pc) / (1.0 - pc), 0.0, 0.99999994) : u.z;
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
    pdf = pdf_principled(s, N, V, L);
    return L;
}

float pdf_principled(Surface s, vec3 N, vec3 V, vec3 L) {
    float psh = sheen_select(s, max(dot(N, V), 1e-4));
    float pc = coat_select(s, N, V) * (1.0 - psh);
    float p = pc > 0.0 ? pc * coat_pdf(s, N, V, L) : 0.0;
    float NoL = dot(N, L);
    if (NoL <= 0.0) return p;
    p += psh * NoL * INV_PI;
    pc += psh;
    float NoV = max(dot(N, V), 1e-4);
    vec2 w = lobe_weights(s, NoV);
    vec3 H = normalize(V + L);
    float a2 = s.alpha * s.alpha;
    return p + (1.0 - pc) * (w.x * NoL * INV_PI + w.y * ggx_vndf_pdf(NoV, max(dot(N, H), 0.0), a2));
}

// ---------------------------------------------------------------- every lobe kind
// The lobes Cycles' other BSDF nodes and the Principled BSDF's transmission make, for the
// path tracer (the G-buffer family shades every surface with eval_principled above).
// eval_surface / sample_surface / pdf_surface dispatch on Surface.kind (common.glsl BSDF_*):
// adding a kind is one case in each. N is the shading normal facing V; L below N is
// transmission.
#define LOBE_DIFFUSE 0
#define LOBE_GLOSSY 1
#define LOBE_TRANSMISSION 2

// Multiple-scattering energy of GGX glass (Cycles' Multiscatter GGX glass: the lobe is scaled
// by 1 / E with E the single-scattering albedo, reflection + refraction, tabulated over
// roughness, cos(N, V) and the IOR); lib/brdf_tables.glsl GGX_GLASS_E / GGX_GLASS_INV_E.
float ggx_glass_E(float rough, float mu, float eta) {
#ifdef GGX_GLASS_TABLES
    bool inv = eta < 1.0;
    float ior = inv ? 1.0 / eta : eta;
    float z = sqrt(abs((ior - 1.0) / (ior + 1.0))) * 15.0;
    float x = clamp(rough, 0.0, 1.0) * 15.0, y = clamp(mu, 0.0, 1.0) * 15.0;
    z = clamp(z, 0.0, 15.0);
    int i0 = min(int(x), 15), j0 = min(int(y), 15), k0 = min(int(z), 15);
    int i1 = min(i0 + 1, 15), j1 = min(j0 + 1, 15), k1 = min(k0 + 1, 15);
    float tx = x - float(i0), ty = y - float(j0), tz = z - float(k0);
    float v[8];
    for (int c = 0; c < 8; ++c) {
        int i = (c & 1) != 0 ? i1 : i0, j = (c & 2) != 0 ? j1 : j0, k = (c & 4) != 0 ? k1 : k0;
        int o = (k * 16 + j) * 16 + i;
        v[c] = inv ? GGX_GLASS_INV_E_at(o) : GGX_GLASS_E_at(o);
    }
    float a = mix(mix(v[0], v[1], tx), mix(v[2], v[3], tx), ty);
    float b = mix(mix(v[4], v[5], tx), mix(v[6], v[7], tx), ty);
    return max(mix(a, b, tz), 1e-3);
#else
    return 1.0;
#endif
}

// Smooth glass is GGX of this alpha (Cycles: a singular lobe): below it 1 - alpha^2 rounds to 1
// in float32 and D at the half vector recomputed from a refracted direction overflows.
#define DIELECTRIC_MIN_ALPHA 1e-3

// A dielectric interface with GGX microfacets (Walter et al. 2007, as Cycles' microfacet
// glass): eta = IOR behind the surface / IOR in front (ior entering, 1 / ior leaving).
// f * |cos L|: reflection F * refl_tint above N, refraction (1 - F) * trans_tint below
// (radiance is not scaled by 1 / eta^2 on refraction, as in Cycles); fresnel = false is
// refraction alone with weight 1 (the Refraction BSDF).
vec3 dielectric_eval(vec3 N, vec3 V, vec3 L, float alpha, float eta, vec3 refl_tint, vec3 trans_tint, bool fresnel) {
    alpha = max(alpha, DIELECTRIC_MIN_ALPHA);
    float NoV = max(dot(N, V), 1e-4);
    float NoL = dot(N, L);
    float a2 = alpha * alpha;
    if (NoL > 0.0) {
        if (!fresnel) return vec3(0.0);
        vec3 H = normalize(V + L);
        float F = fresnel_dielectric(max(dot(V, H), 0.0), eta);
        return refl_tint * (F * ggx_D(max(dot(N, H), 0.0), a2) * ggx_V(NoV, NoL, a2) * NoL);
    }
    if (NoL == 0.0) return vec3(0.0);
    vec3 Ht = V + eta * L;
    float len2 = dot(Ht, Ht);
    if (len2 <= 1e-20) return vec3(0.0);
    vec3 H = Ht * inversesqrt(len2);
    if (dot(N, H) < 0.0) H = -H;
    float VoH = dot(V, H), LoH = dot(L, H);
    if (VoH <= 0.0 || LoH >= 0.0) return vec3(0.0);
    float F = fresnel ? fresnel_dielectric(VoH, eta) : 0.0;
    float aNoL = -NoL;
    float G2 = 4.0 * NoV * aNoL * ggx_V(NoV, aNoL, a2);
    return trans_tint * ((1.0 - F) * ggx_D(dot(N, H), a2) * G2 * VoH * eta * eta * (-LoH) / (NoV * len2));
}

float dielectric_pdf(vec3 N, vec3 V, vec3 L, float alpha, float eta, bool fresnel) {
    alpha = max(alpha, DIELECTRIC_MIN_ALPHA);
    float NoV = max(dot(N, V), 1e-4);
    float NoL = dot(N, L);
    float a2 = alpha * alpha;
    if (NoL > 0.0) {
        if (!fresnel) return 0.0;
        vec3 H = normalize(V + L);
        float F = fresnel_dielectric(max(dot(V, H), 0.0), eta);
        return F * ggx_vndf_pdf(NoV, max(dot(N, H), 0.0), a2);
    }
    if (NoL == 0.0) return 0.0;
    vec3 Ht = V + eta * L;
    float len2 = dot(Ht, Ht);
    if (len2 <= 1e-20) return 0.0;
    vec3 H = Ht * inversesqrt(len2);
    if (dot(N, H) < 0.0) H = -H;
    float VoH = dot(V, H), LoH = dot(L, H);
    if (VoH <= 0.0 || LoH >= 0.0) return 0.0;
    float F = fresnel ? fresnel_dielectric(VoH, eta) : 0.0;
    float NoH = dot(N, H);
    return (1.0 - F) * ggx_G1(NoV, a2) * ggx_D(NoH, a2) * VoH / NoV * eta * eta * (-LoH) / len2;
}

// A visible normal, then reflection with probability F, else refraction (total internal
// reflection: F = 1).
vec3 dielectric_sample(vec3 N, vec3 V, float alpha, float eta, bool fresnel, vec3 u, out bool refracted) {
    alpha = max(alpha, DIELECTRIC_MIN_ALPHA);
    vec3 Vl = to_local(V, N);
    vec3 Hl = sample_ggx_vndf(Vl, alpha, u.xy);
    float F = fresnel ? fresnel_dielectric(max(dot(Vl, Hl), 0.0), eta) : 0.0;
    refracted = u.z >= F;
    vec3 Ll = refracted ? refract(-Vl, Hl, 1.0 / eta) : reflect(-Vl, Hl);
    return to_world(Ll, N);
}

float surface_eta(Surface s) { return s.backfacing ? 1.0 / s.ior : s.ior; }

// Cycles' Principled: metal, then glass of weight (1 - metallic) transmission (reflection
// untinted, refraction tinted by sqrt(base colour) at each interface), then the rest.
vec3 principled_glass(Surface s, vec3 N, vec3 V, vec3 L) {
    float w = (1.0 - s.metallic) * s.transmission;
    if (w <= 0.0) return vec3(0.0);
    float eta = surface_eta(s);
    float ms = 1.0 / ggx_glass_E(s.roughness, max(dot(N, V), 0.0), eta);
    return (w * ms) * dielectric_eval(N, V, L, s.alpha, eta, vec3(1.0), sqrt(clamp(s.base_color, 0.0, 1.0)), true);
}

// Lobe selection of a Principled surface with transmission: diffuse, specular, glass.
vec3 principled_lobe_weights(Surface s, float NoV) {
    float keep = 1.0 - s.transmission;
    float layer = dielectric_layer_albedo(s, NoV);
    float diff = (1.0 - s.metallic) * keep * (1.0 - layer) * luminance(s.base_color);
    float spec = (1.0 - s.metallic) * keep * layer + s.metallic * luminance(metal_albedo_estimate(s, NoV));
    float glass = (1.0 - s.metallic) * s.transmission;
    float tot = diff + spec + glass;
    return tot > 0.0 ? vec3(diff, spec, glass) / tot : vec3(0.5, 0.5, 0.0);
}

BsdfEval eval_surface(Surface s, vec3 N, vec3 V, vec3 L) {
    BsdfEval e;
    e.diffuse = vec3(0.0);
    e.glossy = vec3(0.0);
    float NoL = dot(N, L);
    if (s.kind == BSDF_PRINCIPLED) {
        if (s.transmission <= 0.0) return eval_principled(s, N, V, L);
        if (NoL > 0.0) e = eval_principled_keep(s, N, V, L, 1.0 - s.transmission);
        e.glossy += principled_glass(s, N, V, L);
    } else if (s.kind == BSDF_GLOSSY) {
        if (NoL <= 0.0) return e;
        float NoV = max(dot(N, V), 1e-4);
        vec3 H = normalize(V + L);
        float a2 = s.alpha * s.alpha;
        float E = ggx_E(s.roughness, NoV);
        e.glossy = s.base_color * ggx_D(max(dot(N, H), 0.0), a2) * ggx_V(NoV, NoL, a2) * NoL
                 * ggx_ms_scale(E, ggx_Eavg(s.roughness), s.base_color);
    } else if (s.kind == BSDF_GLASS || s.kind == BSDF_REFRACTION) {
        bool glass = s.kind == BSDF_GLASS;
        float eta = surface_eta(s);
        float ms = glass ? 1.0 / ggx_glass_E(s.roughness, max(dot(N, V), 0.0), eta) : 1.0;
        e.glossy = ms * dielectric_eval(N, V, L, s.alpha, eta, s.base_color, s.base_color, glass);
    } else if (s.kind == BSDF_TRANSLUCENT) {
        if (NoL < 0.0) e.diffuse = s.base_color * (-NoL * INV_PI);
    }
    return e;
}

float pdf_surface(Surface s, vec3 N, vec3 V, vec3 L) {
    float NoL = dot(N, L);
    float NoV = max(dot(N, V), 1e-4);
    float a2 = s.alpha * s.alpha;
    if (s.kind == BSDF_PRINCIPLED) {
        if (s.transmission <= 0.0) return pdf_principled(s, N, V, L);
        vec3 w = principled_lobe_weights(s, NoV);
        float p = w.z * dielectric_pdf(N, V, L, s.alpha, surface_eta(s), true);
        if (NoL > 0.0) p += w.x * NoL * INV_PI + w.y * ggx_vndf_pdf(NoV, max(dot(N, normalize(V + L)), 0.0), a2);
        return p;
    }
    if (s.kind == BSDF_GLOSSY) return NoL > 0.0 ? ggx_vndf_pdf(NoV, max(dot(N, normalize(V + L)), 0.0), a2) : 0.0;
    if (s.kind == BSDF_GLASS || s.kind == BSDF_REFRACTION)
        return dielectric_pdf(N, V, L, s.alpha, surface_eta(s), s.kind == BSDF_GLASS);
    if (s.kind == BSDF_TRANSLUCENT) return NoL < 0.0 ? -NoL * INV_PI : 0.0;
    return 0.0;
}

// A direction from the surface's lobes and which kind of bounce it is (LOBE_*, for
// Cycles' bounce limits); its pdf is pdf_surface's.
vec3 sample_surface(Surface s, vec3 N, vec3 V, vec3 u, out int lobe) {
    float NoV = max(dot(N, V), 1e-4);
    lobe = LOBE_GLOSSY;
    bool refracted = false;
    if (s.kind == BSDF_PRINCIPLED) {
        if (s.transmission <= 0.0) {
            float pdf;
            float psh = sheen_select(s, NoV);
            float u1 = psh > 0.0 ? clamp((u.z - psh) / (1.0 - psh), 0.0, 0.99999994) : u.z;
            float pc = coat_select(s, N, V);
            float uz = pc > 0.0 ? (u1 - pc) / (1.0 - pc) : u1;
            lobe = u.z < psh ? LOBE_DIFFUSE : ((u1 >= pc && uz < lobe_weights(s, NoV).x) ? LOBE_DIFFUSE : LOBE_GLOSSY);
            return sample_principled(s, N, V, u, pdf);
        }
        vec3 w = principled_lobe_weights(s, NoV);
        if (u.z < w.x) {
            lobe = LOBE_DIFFUSE;
            return to_world(sample_cosine_hemisphere(u.xy), N);
        }
        if (u.z < w.x + w.y || w.z <= 0.0) {
            vec3 Vl = to_local(V, N);
            return to_world(reflect(-Vl, sample_ggx_vndf(Vl, s.alpha, u.xy)), N);
        }
        float uz = clamp((u.z - w.x - w.y) / w.z, 0.0, 0.99999994);
        vec3 L = dielectric_sample(N, V, s.alpha, surface_eta(s), true, vec3(u.xy, uz), refracted);
        lobe = refracted ? LOBE_TRANSMISSION : LOBE_GLOSSY;
        return L;
    }
    if (s.kind == BSDF_GLASS || s.kind == BSDF_REFRACTION) {
        vec3 L = dielectric_sample(N, V, s.alpha, surface_eta(s), s.kind == BSDF_GLASS, u, refracted);
        lobe = refracted ? LOBE_TRANSMISSION : LOBE_GLOSSY;
        return L;
    }
    if (s.kind == BSDF_TRANSLUCENT) {
        lobe = LOBE_TRANSMISSION;
        return to_world(sample_cosine_hemisphere(u.xy), -N);
    }
    vec3 Vl = to_local(V, N);  // BSDF_GLOSSY
    return to_world(reflect(-Vl, sample_ggx_vndf(Vl, s.alpha, u.xy)), N);
}

#endif
