// shadow.frag — stores the distance metric of a shadow view: distance to the view origin
// for perspective views, depth along the light direction for orthographic (sun) views.
// Alpha holes (lib/textures.glsl material_alpha) let light through: a fragment is dropped
// when its alpha is below a per-texel, per-frame uniform random number, as the G-buffer and
// the ray tracer do (Cycles' stochastic transparency).
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/textures.glsl"
in vec3 v_world;
in vec2 v_uv;
flat in int v_material;
uniform vec3 u_origin;
uniform vec3 u_dir;
uniform int u_ortho;
uniform sampler2DArray u_textures;
uniform int u_material_count;
uniform int u_alpha_test;
uniform int u_alpha_seed;
layout(location = 0) out float o_dist;
void main() {
    if (u_alpha_test == 1) {
        int mid = (v_material >= 0 && v_material < u_material_count) ? v_material : u_material_count;
        float a = material_alpha(u_textures, materials[mid], v_uv);
        if (a < 1.0 && alpha_hash_u01(uvec3(uvec2(gl_FragCoord.xy), uint(u_alpha_seed))) >= a) discard;
    }
    o_dist = u_ortho == 1 ? dot(v_world - u_origin, u_dir) : length(v_world - u_origin);
}
