// trace.comp — VXGI cone tracing per pixel (Crassin et al. 2011) and the composite.
// From the G-buffer point, offset u_normal_offset voxels along the geometric normal:
//  * indirect diffuse: six cones around the shading normal (vx_diffuse_cones: weights
//    integrating the cosine lobe), E from the voxels' radiance; added as albedo_d * E / pi;
//  * indirect glossy: one cone along the mirror direction, tan(half aperture) = the GGX
//    alpha (roughness^2) clamped to [u_min_tan, tan 30 deg]; added as albedo_s * L_cone;
//  * AO: the diffuse cones' cosine-weighted unoccluded fraction (an AOV; not applied:
//    the cones already carry the occlusion of the indirect light).
// The voxels hold reflected light only (emitters and the world reach the screen through
// DIRECT), so nothing DIRECT draws is counted twice. color += diffuse + glossy in place.
#define USE_SCENE_BUFFERS
#define VX_SAMPLING
#include "lib/common.glsl"
#include "lib/rng.glsl"
#include "lib/sampling.glsl"
#include "lib/brdf.glsl"
#include "lib/screen.glsl"
#include "screen_space/common.glsl"
#include "vxgi/common.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform image2D io_color;
layout(binding = 1, rgba32f) uniform writeonly image2D o_diffuse;
layout(binding = 2, rgba32f) uniform writeonly image2D o_glossy;
layout(binding = 3, rgba32f) uniform writeonly image2D o_ao;

uniform float u_normal_offset;  // voxels
uniform float u_step;
uniform float u_max_distance;
uniform float u_min_tan;
uniform int u_specular;
uniform float u_audit;  // > 0: energy audit: GI_IndirectDiffuse = E / pi (albedo 1)

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(px, imageSize(io_color)))) return;
    GPixel g = fetch_g(px);
    if (!g.valid) {
        imageStore(o_diffuse, px, vec4(0.0, 0.0, 0.0, 1.0));
        imageStore(o_glossy, px, vec4(0.0, 0.0, 0.0, 1.0));
        imageStore(o_ao, px, vec4(1.0));
        return;
    }
    Surface s = fetch_surface(px, g.mid);
    vec3 V = view_dir(g.P);
    vec3 N = g.N, Ng = g.Ng;
    if (dot(Ng, V) < 0.0) Ng = -Ng;
    if (dot(N, Ng) < 0.0) N = -N;
    float NoV = max(dot(N, V), 1e-4);
    vec3 kd = diffuse_albedo(s, NoV);
    vec3 ks = specular_albedo(s, NoV);
    float vs = vx_voxel_size_at(g.P);
    vec3 o = g.P + Ng * (u_normal_offset * vs);
    float vis = 1.0;
    vec3 E = vec3(0.0);
    if (max3(kd) > 0.0) E = vx_diffuse_cones(o, N, vs, u_max_distance, u_step, 0.0, 1.0, vis, u_normal_offset * vs);
    vec3 diffuse = (u_audit > 0.0 ? vec3(1.0) : kd) * E * INV_PI;
    vec3 glossy = vec3(0.0);
    if (u_specular == 1 && max3(ks) > 1e-4) {
        vec3 R = reflect(-V, N);
        if (dot(R, Ng) < 0.0) R = normalize(R - 1.01 * dot(R, Ng) * Ng);
        float a = s.alpha;
        float tan_half = clamp(a, u_min_tan, 0.57735);
        vec4 c = vx_cone(o, R, tan_half, vs, u_max_distance, u_step);
        glossy = ks * c.rgb;
    }
    vec4 col = imageLoad(io_color, px);
    vec3 total = sanitize(col.rgb + diffuse + glossy);
    imageStore(io_color, px, vec4(total, col.a));
    imageStore(o_diffuse, px, vec4(sanitize(diffuse), 1.0));
    imageStore(o_glossy, px, vec4(sanitize(glossy), 1.0));
    imageStore(o_ao, px, vec4(vec3(vis), 1.0));
}
