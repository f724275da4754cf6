// material_sample.comp — samples material u_material's inputs at given uvs through
// lib/textures.glsl (sample_material, the function the G-buffer and the ray tracer use),
// for blender_tests/test_materials.py to compare with the numpy evaluator's sampling.
// Bindings: the GPUScene's (materials at 0, texture array at unit 0), uvs at 4, results at 5.
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/textures.glsl"

layout(local_size_x = 64) in;
layout(std430, binding = 4) readonly buffer Uvs { vec2 uvs[]; };
layout(std430, binding = 5) writeonly buffer Out { vec4 result[]; };  // 3 per uv
uniform sampler2DArray u_textures;
uniform int u_material;
uniform int u_count;

void main() {
    int i = int(gl_GlobalInvocationID.x);
    if (i >= u_count) return;
    MaterialSample s = sample_material(u_textures, materials[u_material], uvs[i]);
    result[3 * i + 0] = vec4(s.base_color, s.alpha);
    result[3 * i + 1] = vec4(s.roughness, s.metallic, s.specular_ior_level, 0.0);
    result[3 * i + 2] = vec4(s.emission, 0.0);
}
