// bsdf.glsl — a material's lobe list, as the path tracer evaluates it (included by
// lib/scene_rt.glsl after the material buffer and u_textures).
//
// A material the exporter could not reduce to one opaque Principled record (Mix and Add
// Shaders, Glass, Refraction, Translucent BSDFs, Principled transmission) carries a list of
// lobe records (Material.lobes: first record, count), each a full record of one BSDF kind
// with its textures and its weight (the product of the mix factors on its way to the output,
// constant or a texture: MAP_WEIGHT). The record itself is then the blended approximation
// the G-buffer family shades. A surface whose Surface.material is set (scene_trace with
// RT_EXACT_BSDF) is evaluated as the weighted sum of its lobes and sampled by picking a lobe
// with probability proportional to its weight; any other surface is its own one lobe.
// Call bsdf_begin(surface) once per shading point before bsdf_eval / bsdf_pdf / bsdf_sample.
#ifndef GI_BSDF_GLSL
#define GI_BSDF_GLSL

#ifdef RT_EXACT_BSDF
// The lobes of the surface being shaded, loaded once per path vertex by bsdf_begin (every
// function below inlines its body at each call: loading the lobes there would multiply the
// shader's size, and llvmpipe's compile time, by the number of calls).
Surface g_lobe[MATERIAL_MAX_LOBES];
float g_lobe_w[MATERIAL_MAX_LOBES];
float g_lobe_wsum;
int g_lobe_n;

// Loads the lobes of surface s at its uv (a surface without a lobe list is its own lobe).
void bsdf_begin(Surface s) {
    g_lobe_n = 1;
    g_lobe[0] = s;
    g_lobe_w[0] = 1.0;
    g_lobe_wsum = 1.0;
    if (s.material < 0) return;
    Material m = materials[s.material];
    int n = min(int(m.lobes.y + 0.5), MATERIAL_MAX_LOBES);
    if (n == 0) return;
    int first = int(m.lobes.x + 0.5);
    g_lobe_n = n;
    g_lobe_wsum = 0.0;
    for (int i = 0; i < n; ++i) {
        Material c = materials[first + i];
        MaterialSample cs = sample_material(u_textures, c, s.uv);
        Surface x = make_surface(material_at(c, cs), cs.base_color);
        x.backfacing = s.backfacing;
        x.emission = vec3(0.0);
        g_lobe[i] = x;
        g_lobe_w[i] = max(has_map(c, MAP_WEIGHT) ? sample_map_float(u_textures, c.maps[MAP_WEIGHT], s.uv) : c.bsdf.z, 0.0);
        g_lobe_wsum += g_lobe_w[i];
    }
}

// Cycles' bump_shadowing_term for a shading normal N that differs from the smooth normal Ns
// (a normal or bump map): light L on the other side of the smooth surface than N says is
// rejected; diffuse light is softened by a GGX shadowing G1(cos(Ns, L)) of alpha^2 =
// tan^2(Ns, N) / 8 (Conty Estevez et al.; when the material's Bump Map Correction is on).
vec2 bump_shadowing(Surface s, vec3 N, vec3 L) {
    if (dot(s.ns, s.ns) <= 0.0) return vec2(1.0);
    float cosNsI = dot(s.ns, L), cosNsN = dot(s.ns, N), cosNI = dot(N, L);
    if (cosNsI * cosNsN * cosNI < 0.0) return vec2(0.0);
    if (!s.bump_correction) return vec2(1.0);
    float ci = abs(cosNsI), cd = abs(cosNsN);
    if (cd >= 1.0 || ci >= 1.0) return vec2(1.0);
    if (ci < 1e-6) return vec2(0.0, 1.0);
    float a2 = clamp(0.125 * (1.0 / (cd * cd) - 1.0), 0.0, 1.0);
    float g = 2.0 / (1.0 + sqrt(1.0 + a2 * (1.0 - ci * ci) / (ci * ci)));
    return vec2(g, 1.0);
}

// The weighted sum of the lobes' BSDFs (s: the surface bsdf_begin loaded).
BsdfEval bsdf_eval(Surface s, vec3 N, vec3 V, vec3 L) {
    BsdfEval e;
    e.diffuse = vec3(0.0);
    e.glossy = vec3(0.0);
    for (int i = 0; i < g_lobe_n; ++i) {
        if (g_lobe_w[i] <= 0.0) continue;
        BsdfEval x = eval_surface(g_lobe[i], N, V, L);
        e.diffuse += g_lobe_w[i] * x.diffuse;
        e.glossy += g_lobe_w[i] * x.glossy;
    }
    vec2 b = bump_shadowing(s, N, L);
    e.diffuse *= b.x;
    e.glossy *= b.y;
    return e;
}

// The pdf of bsdf_sample: a lobe with probability weight / sum of weights, then its pdf.
float bsdf_pdf(Surface s, vec3 N, vec3 V, vec3 L) {
    if (g_lobe_wsum <= 0.0) return 0.0;
    float p = 0.0;
    for (int i = 0; i < g_lobe_n; ++i)
        if (g_lobe_w[i] > 0.0) p += g_lobe_w[i] * pdf_surface(g_lobe[i], N, V, L);
    return p / g_lobe_wsum;
}

// A direction and its kind of bounce (LOBE_*).
vec3 bsdf_sample(Surface s, vec3 N, vec3 V, vec3 u, out int kind) {
    float x = u.z * g_lobe_wsum;
    int pick = g_lobe_n - 1;
    float lo = 0.0;
    for (int i = 0; i < g_lobe_n; ++i) {
        if (x < lo + g_lobe_w[i]) { pick = i; break; }
        lo += g_lobe_w[i];
    }
    float uz = g_lobe_w[pick] > 0.0 ? clamp((x - lo) / g_lobe_w[pick], 0.0, 0.99999994) : 0.5;
    Surface sl = g_lobe[0];
    for (int i = 1; i < g_lobe_n; ++i) if (i == pick) sl = g_lobe[i];
    return sample_surface(sl, N, V, vec3(u.xy, uz), kind);
}
#else
// Passes other than the path tracer shade every surface as its record's opaque Principled BSDF.
void bsdf_begin(Surface s) {}
BsdfEval bsdf_eval(Surface s, vec3 N, vec3 V, vec3 L) { return eval_principled(s, N, V, L); }
float bsdf_pdf(Surface s, vec3 N, vec3 V, vec3 L) { return pdf_principled(s, N, V, L); }
#endif

#endif
