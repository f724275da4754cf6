// gbuffer.frag — writes the G-buffer from the material sampled at the fragment
// (lib/textures.glsl sample_material, the function the ray tracer uses): base colour and
// specular IOR level, shading normal (normal-mapped, facing the viewer as Cycles flips back
// faces) and roughness, world position + material id, geometric normal and metallic, motion
// vector in pixels (current - previous), emission. A fragment whose alpha is below a
// per-pixel, per-frame uniform random number is discarded (Cycles' stochastic
// transparency; the accumulation converges to the alpha-weighted mean).
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/textures.glsl"

in vec3 v_world;
in vec3 v_normal;
in vec4 v_tangent;
in vec4 v_color;
in vec2 v_uv;
flat in int v_material;
in vec4 v_clip;
in vec4 v_prev_clip;

uniform sampler2DArray u_textures;
uniform vec3 u_camera_pos;
uniform vec2 u_resolution;
uniform int u_material_count;
uniform int u_alpha_test;
uniform int u_alpha_seed;

layout(location = 0) out vec4 o_albedo;
layout(location = 1) out vec4 o_normal;
layout(location = 2) out vec4 o_position;
layout(location = 3) out vec4 o_geonormal;
layout(location = 4) out vec4 o_motion;
layout(location = 5) out vec4 o_emission;

void main() {
    int mid = (v_material >= 0 && v_material < u_material_count) ? v_material : u_material_count;
    Material m = materials[mid];
    g_vertex_color = v_color;
    MaterialSample ms = sample_material(u_textures, m, v_uv);  // as the ray tracer samples it
    if (u_alpha_test == 1 && ms.alpha < 1.0 &&
        alpha_hash_u01(uvec3(uvec2(gl_FragCoord.xy), uint(u_alpha_seed))) >= ms.alpha) discard;
    vec3 geo = normalize(cross(dFdx(v_world), dFdy(v_world)));
    vec3 view = normalize(u_camera_pos - v_world);
    if (dot(geo, view) < 0.0) geo = -geo;
    // dP/du, dP/dv from the screen derivatives (constant over the triangle, as the ray tracer's)
    vec3 dpdx = dFdx(v_world), dpdy = dFdy(v_world);
    vec2 dtdx = dFdx(v_uv), dtdy = dFdy(v_uv);
    float tdet = dtdx.x * dtdy.y - dtdx.y * dtdy.x;
    vec3 dpdu = vec3(0.0), dpdv = vec3(0.0);
    if (abs(tdet) > 1e-30) {
        dpdu = (dpdx * dtdy.y - dpdy * dtdx.y) / tdet;
        dpdv = (dpdy * dtdx.x - dpdx * dtdy.x) / tdet;
    }
    vec3 n = shading_normal(ms, normalize(v_normal), v_tangent, dpdu, dpdv);
    if (!gl_FrontFacing) n = -n;
    // keep the shading normal in the visible hemisphere of the geometric one
    if (dot(n, view) < 0.0) n = normalize(n - 1.01 * dot(n, view) * view);
    vec2 cur = (v_clip.xy / v_clip.w * 0.5 + 0.5) * u_resolution;
    vec2 prev = (v_prev_clip.xy / v_prev_clip.w * 0.5 + 0.5) * u_resolution;
    o_albedo = vec4(max(ms.base_color, vec3(0.0)), ms.specular_ior_level);
    o_normal = vec4(n, ms.roughness);
    o_position = vec4(v_world, float(mid));
    o_geonormal = vec4(geo, ms.metallic);
    o_motion = vec4(cur - prev, 0.0, 0.0);
    o_emission = vec4(max(ms.emission, vec3(0.0)), 1.0);
}
