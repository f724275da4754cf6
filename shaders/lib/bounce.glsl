// bounce.glsl — the light a ray's first hit sends back along the ray, for the techniques that
// cache indirect light (probe volumes, screen probes, the world radiance cache): what leaves
// the hit towards the ray's origin *other than* the receiver's own direct light, which DIRECT
// computes exactly at every receiver. That is the hit's direct light (shade_direct_at: one
// light by the light tree or the world map by luminance, one shadow ray) plus, for a uniform
// world (not a light of next-event estimation), one cosine ray to the sky. The caller adds
// kd × E / π with E the indirect irradiance its own cache holds at the hit (infinite bounces
// over frames). Lights, emitters and the world seen directly by the ray are left out.
// Include after lib/scene_rt.glsl and lib/albedo.glsl. Host side: set u_world_light (1 when
// the world is not black).
#ifndef GI_BOUNCE_GLSL
#define GI_BOUNCE_GLSL

uniform int u_world_light;   // 1: the world is not black

// Returns the radiance leaving the front-face hit `sh` of direction `d` back towards the ray's
// origin (direct light and uniform sky at the hit); `kd` its diffuse albedo, `N` the shading
// normal facing the ray, `p` the hit point. mis: the hit's light sample is MIS-weighted
// against one BSDF sample that collects the lights, emitters and world map it meets (power
// heuristic, as PT at every bounce) — for a pixel's own reflection ray, where one light
// sample of a sharp lobe seen at a grazing angle is a firefly; a cache averaging many rays
// per entry takes the light sample alone.
vec3 bounce_direct_ex(SurfaceHit sh, vec3 d, inout Rng rng, bool mis, out vec3 kd, out vec3 N, out vec3 p) {
    vec3 V = -d;
    vec3 Ng;
    surface_frame(sh, V, N, Ng, p);
    Surface bs = sh.bsdf;
    float NoV = max(dot(N, V), 1e-4);
    kd = diffuse_albedo(bs, NoV);
    vec3 L = shade_direct_at(bs, p, N, Ng, V, rng, mis);
    if (mis && (u_light_count > 0 || u_world_select > 0.0)) {
        vec3 g, dir;
        float t;
        L += bsdf_sample_lights(bs, p, N, Ng, V, rng, g, dir, t);
    }
    if (u_world_light != 0 && u_world_select <= 0.0 && max3(kd) > 0.0) {  // a uniform world
                                                                          // (a map is in shade_direct)
        vec3 wd = to_world(sample_cosine_hemisphere(rng_next2(rng)), N);
        if (dot(wd, Ng) > 0.0 && !scene_occluded(p, wd, 0.0, T_INF)) L += kd * u_world_color;
    }
    return L;
}

vec3 bounce_direct(SurfaceHit sh, vec3 d, inout Rng rng, out vec3 kd, out vec3 N, out vec3 p) {
    return bounce_direct_ex(sh, d, rng, false, kd, N, p);
}

#endif
