// albedo.glsl — directional albedos of the Principled subset's two lobes (what each lobe
// reflects of uniform incident radiance, seen from NoV), from the same Cycles tables that
// brdf.glsl evaluates with: the Lambertian base under the dielectric layer, and the glossy
// lobe (dielectric layer with its tint, F82-tint metal, multiple-scattering scale). Used
// where a technique lights a surface by uniform or pre-integrated radiance (world light,
// ambient terms, reflections). Requires brdf.glsl.
#ifndef GI_ALBEDO_GLSL
#define GI_ALBEDO_GLSL

vec3 diffuse_albedo(Surface s, float NoV) {
    return (1.0 - s.metallic) * s.base_color * (1.0 - dielectric_layer_albedo(s, NoV));
}

vec3 specular_albedo(Surface s, float NoV) {
    vec3 diel = vec3(0.0);
    if (s.f0 > 1e-6) {
        float E = ggx_E(s.roughness, NoV);
        vec3 ms = ggx_ms_scale(E, ggx_Eavg(s.roughness), dielectric_Fss(s));
        float sv = ggx_schlick_s(s.roughness, NoV, s.eta);
        diel = E * ms * mix(dielectric_f0(s), vec3(1.0), sv);
    }
    vec3 metal = metal_albedo_estimate(s, NoV);
    return clamp(mix(diel, metal, s.metallic), 0.0, 1.0);
}

// The glossy lobe's dominant direction (Lagarde & de Rousiers 2014), where a prefiltered
// radiance lookup stands for the whole lobe: R for smooth surfaces, bending towards N as
// the roughness grows.
vec3 specular_dominant_dir(vec3 N, vec3 V, float alpha) {
    return normalize(mix(N, reflect(-V, N), (1.0 - alpha) * (sqrt(1.0 - alpha) + alpha)));
}

#endif
