// voxelize.vert — VXGI voxelisation, geometry stage input: world-space vertices.
#include "lib/common.glsl"

in vec3 in_position;
in vec3 in_normal;
in vec2 in_uv;
in vec4 in_color;  // the colour attribute a material reads (zero: none)
in float in_material;

uniform mat4 u_model;
uniform mat3 u_normal_matrix;

out vec3 v_world;
out vec3 v_normal;
out vec2 v_uv;
out vec4 v_color;
flat out int v_material;

void main() {
    vec4 w = u_model * vec4(in_position, 1.0);
    v_world = w.xyz;
    v_normal = u_normal_matrix * in_normal;
    v_uv = in_uv;
    v_color = in_color;
    v_material = int(in_material + 0.5);
    gl_Position = vec4(0.0, 0.0, 0.0, 1.0);
}
