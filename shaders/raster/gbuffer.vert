// gbuffer.vert — G-buffer geometry stage: world position, normals, tangent, uv, material,
// and the previous frame's clip position for motion vectors.
#include "lib/common.glsl"

in vec3 in_position;
in vec3 in_normal;
in vec2 in_uv;
in float in_material;
in vec4 in_tangent;  // xyz MikkTSpace tangent, w bitangent sign (zero: no normal map)
in vec4 in_color;    // the colour attribute a material reads (zero: none)

uniform mat4 u_model;
uniform mat4 u_prev_model;
uniform mat3 u_normal_matrix;
uniform mat4 u_view_proj;        // jittered
uniform mat4 u_view_proj_nojit;  // unjittered, for motion
uniform mat4 u_prev_view_proj;   // unjittered, previous frame

out vec3 v_world;
out vec3 v_normal;
out vec4 v_tangent;
out vec4 v_color;
out vec2 v_uv;
flat out int v_material;
out vec4 v_clip;
out vec4 v_prev_clip;

void main() {
    vec4 w = u_model * vec4(in_position, 1.0);
    v_world = w.xyz;
    v_normal = u_normal_matrix * in_normal;
    v_tangent = vec4(mat3(u_model) * in_tangent.xyz, in_tangent.w);
    v_uv = in_uv;
    v_color = in_color;
    v_material = int(in_material + 0.5);
    v_clip = u_view_proj_nojit * w;
    v_prev_clip = u_prev_view_proj * (u_prev_model * vec4(in_position, 1.0));
    gl_Position = u_view_proj * w;
}
