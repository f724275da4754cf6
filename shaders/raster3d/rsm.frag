// rsm.frag — one texel of a reflective shadow map (Dachsbacher & Stamminger 2005): world
// position, normal turned towards the light, and the flux the texel's surface patch
// reflects diffusely, in W, from the light in Cycles' units:
//   perspective view (point, spot, area from its centre): Φ = ρ_d(NoL) · I(ω) · dω,
//     dω = t² cos³α (t: texel size on the unit image plane, α: angle to the view axis);
//     I = intensity (W/sr) · spot cone, or for an area light L_e · A · max(0, cos θ_L);
//   orthographic view (sun): Φ = ρ_d(NoL) · E · A_texel; a view of the world light
//     (u_light < 0) has its E in u_world_e (passes/rsm.py world_views).
// The first surface along each texel is the one the light reaches (no visibility needed).
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/textures.glsl"
#include "lib/sampling.glsl"
#include "lib/brdf.glsl"
#include "lib/albedo.glsl"
#include "lib/lights.glsl"

in vec3 v_world;
in vec3 v_normal;
in vec2 v_uv;
in vec4 v_color;
flat in int v_material;

uniform sampler2DArray u_textures;
uniform int u_material_count;
uniform int u_alpha_test;
uniform int u_alpha_seed;
uniform int u_light;        // < 0: a view of the world light
uniform vec3 u_world_e;     // its irradiance at normal incidence
uniform vec3 u_origin;
uniform vec3 u_fwd;
uniform int u_ortho;
uniform float u_texel;

layout(location = 0) out vec4 o_pos;
layout(location = 1) out vec4 o_nrm;
layout(location = 2) out vec4 o_flux;

void main() {
    int mid = (v_material >= 0 && v_material < u_material_count) ? v_material : u_material_count;
    Material m = materials[mid];
    vec3 toL = u_ortho == 1 ? -u_fwd : normalize(u_origin - v_world);
    vec3 n = normalize(v_normal);
    if (dot(n, toL) < 0.0) n = -n;
    float NoL = clamp(dot(n, toL), 0.0, 1.0);
    g_vertex_color = v_color;
    MaterialSample ms = sample_material(u_textures, m, v_uv);
    // alpha holes let light through (stochastic, as the shadow maps)
    if (u_alpha_test == 1 && ms.alpha < 1.0 &&
        alpha_hash_u01(uvec3(uvec2(gl_FragCoord.xy), uint(u_alpha_seed))) >= ms.alpha) discard;
    Surface s = make_surface(material_at(m, ms), ms.base_color);
    vec3 rho = diffuse_albedo(s, max(NoL, 1e-4));
    vec3 flux;
    float area;  // the texel's surface area (the LPV geometry volume's blockers)
    if (u_ortho == 1) {
        vec3 E = u_light >= 0 ? lights[u_light].color.rgb : u_world_e;
        flux = rho * E * (u_texel * u_texel);
        area = u_texel * u_texel / max(NoL, 0.05);
    } else {
        vec3 w = normalize(v_world - u_origin);
        float ca = max(dot(w, u_fwd), 1e-4);
        float domega = u_texel * u_texel * ca * ca * ca;
        flux = rho * light_intensity(lights[u_light], w) * domega;
        vec3 dv = v_world - u_origin;
        area = domega * dot(dv, dv) / max(NoL, 0.05);
    }
    o_pos = vec4(v_world, 1.0);
    o_nrm = vec4(n, area);
    o_flux = vec4(sanitize(flux), 1.0);
}
