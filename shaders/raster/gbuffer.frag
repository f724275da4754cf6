// gbuffer.frag — writes the G-buffer: base colour (textured: lib/textures.glsl, the same
// function the ray tracer uses), shading normal (facing the
// viewer, as Cycles flips back faces), world position + material id, geometric normal,
// motion vector in pixels (current - previous).
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/textures.glsl"

in vec3 v_world;
in vec3 v_normal;
in vec2 v_uv;
flat in int v_material;
in vec4 v_clip;
in vec4 v_prev_clip;

uniform sampler2DArray u_textures;
uniform vec3 u_camera_pos;
uniform vec2 u_resolution;
uniform int u_material_count;

layout(location = 0) out vec4 o_albedo;
layout(location = 1) out vec4 o_normal;
layout(location = 2) out vec4 o_position;
layout(location = 3) out vec4 o_geonormal;
layout(location = 4) out vec4 o_motion;

void main() {
    int mid = (v_material >= 0 && v_material < u_material_count) ? v_material : u_material_count;
    Material m = materials[mid];
    vec3 base = material_base_color(u_textures, m, v_uv);  // as the ray tracer samples it
    vec3 geo = normalize(cross(dFdx(v_world), dFdy(v_world)));
    vec3 view = normalize(u_camera_pos - v_world);
    if (dot(geo, view) < 0.0) geo = -geo;
    vec3 n = normalize(v_normal);
    if (!gl_FrontFacing) n = -n;
    // keep the shading normal in the visible hemisphere of the geometric one
    if (dot(n, view) < 0.0) n = normalize(n - 1.01 * dot(n, view) * view);
    vec2 cur = (v_clip.xy / v_clip.w * 0.5 + 0.5) * u_resolution;
    vec2 prev = (v_prev_clip.xy / v_prev_clip.w * 0.5 + 0.5) * u_resolution;
    o_albedo = vec4(max(base, vec3(0.0)), 1.0);
    o_normal = vec4(n, m.params.y);
    o_position = vec4(v_world, float(mid));
    o_geonormal = vec4(geo, m.params.x);
    o_motion = vec4(cur - prev, 0.0, 0.0);
}
