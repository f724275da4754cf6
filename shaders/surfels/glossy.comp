// glossy.comp — SURFEL's glossy indirect light. A surfel holds irradiance, not directional
// light, so the glossy lobe is traced: per pixel with a glossy lobe, u_sf_glossy_rays rays drawn
// from its GGX lobe (visible normals) through the scene's BVH.
//   hit: the light the hit sends back along the ray other than what DIRECT already gives the
//        pixel: its direct light (lib/bounce.glsl, MIS'd with a BSDF sample: a glossy hit seen at
//        a grazing angle glints) plus its diffuse albedo × the surfels'
//        irradiance there / π (the surfels it uses are marked used, so a surface seen only in a
//        reflection keeps its surfels). A hit emitter's emission is not added: DIRECT's MIS
//        glossy term holds the glossy reflection of the lights and emitters.
//   the world: DIRECT reflects it prefiltered (world_glossy along the lobe's dominant
//        direction × the specular albedo), shadowed by a visibility its world shadow maps
//        estimate along a few directions (aov.world_spec). The share of the rays (weighted by
//        f / pdf) that escape is the traced visibility; where it is lower, color loses the
//        difference (the unshadowed reflection × that share − aov.world_spec): a glossy
//        floor under a roof stops reflecting the sky through it. Noise-free where nothing
//        blocks the lobe.
// color += f_glossy · L_hit / pdf averaged over the rays, plus that world correction. Render
// pass: o_glossy, the first part (the glossy light from other surfaces).
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/rng.glsl"
#include "lib/sampling.glsl"
#include "lib/brdf.glsl"
#include "lib/lights.glsl"
#include "lib/scene_rt.glsl"
#include "lib/screen.glsl"
#include "screen_space/common.glsl"
#include "lib/bounce.glsl"
#define SF_LOOKUP 1
#include "surfels/common.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform image2D io_color;
layout(binding = 1, rgba32f) uniform writeonly image2D o_glossy;
uniform sampler2D u_world_spec;  // DIRECT's shadowed world reflection (aov.world_spec)
uniform int u_world_refl;        // 1: DIRECT reflects the world (0: aov.world_spec is 0)
uniform int u_sf_glossy_rays;

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    ivec2 size = imageSize(io_color);
    if (any(greaterThanEqual(px, size))) return;
    GPixel g = fetch_g(px);
    vec3 add = vec3(0.0), world = vec3(0.0);
    if (g.valid) {
        Surface s = fetch_surface(px, g.mid);
        vec3 V = view_dir(g.P);
        float NoV = max(dot(g.N, V), 1e-4);
        vec3 ks = specular_albedo(s, NoV);
        if (max3(ks) > 1e-4) {
            // from the G-buffer point moved off the surface (scale-aware, as DIRECT's shadow rays)
            vec3 O = rt_offset_ray(g.P + g.Ng * (2e-5 * length(g.P - u_camera_pos) + 1e-6), g.Ng);
            Rng rng = rng_init(uvec2(px), u_sample, 0x51F1u);
            vec3 Vl = to_local(V, g.N);
            float a2 = s.alpha * s.alpha;
            vec3 hits = vec3(0.0);
            float wsum = 0.0, wesc = 0.0;
            for (int k = 0; k < u_sf_glossy_rays; ++k) {
                vec3 d = reflect(-V, to_world(sample_ggx_vndf(Vl, s.alpha, rng_next2(rng)), g.N));
                // the pdf from d's half vector, as eval_principled finds it (at roughness 0 the
                // sampled half vector and that one differ by float rounding, and D by 100x)
                float pdf = ggx_vndf_pdf(NoV, max(dot(g.N, normalize(V + d)), 0.0), a2);
                if (!(pdf > 0.0) || dot(d, g.Ng) <= 0.0 || dot(d, g.N) <= 0.0) continue;
                vec3 fw = eval_principled(s, g.N, V, d).glossy / pdf;
                float w = luminance(fw);
                if (!(w > 0.0)) continue;
                wsum += w;
                SurfaceHit sh;
                if (!scene_trace(O, d, 0.0, T_INF, sh)) {
                    wesc += w;
                    continue;
                }
                vec3 kd, N, p;
                vec3 L = bounce_direct_ex(sh, d, rng, true, kd, N, p);
                float cov;
                if (max3(kd) > 0.0) L += kd * sf_irradiance(p, N, cov, u_sf_frame) * INV_PI;
                hits += sanitize(fw * L);
            }
            add = hits / float(max(u_sf_glossy_rays, 1));
            // the rays take away the world reflection they find blocked, never add to it: where
            // they escape but DIRECT's shadow maps saw less, the prefiltered lookup along the
            // dominant direction is what overshoots (a glossy ball's rim at grazing view under
            // the night HDRI's city lights: 10x Cycles' pixel)
            if (u_world_refl != 0 && wsum > 0.0)
                world = min(world_glossy(specular_dominant_dir(g.N, V, s.alpha), s.alpha) * ks * (wesc / wsum)
                            - texelFetch(u_world_spec, px, 0).rgb, vec3(0.0));
        }
    }
    vec4 c = imageLoad(io_color, px);
    imageStore(io_color, px, vec4(sanitize(c.rgb + add + finite_or_zero(vec4(world, 0.0)).rgb), c.a));
    imageStore(o_glossy, px, vec4(add, 1.0));
}
