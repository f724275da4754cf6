// modulate.comp — end of ATROUS/SVGF: colour = filtered illumination x demodulation albedo
// + the surface's emission (background pixels carry the colour itself). With u_demod = 1 the
// input of the filter is demodulated here instead: u_in = colour -> o_out = (colour -
// emission) / albedo, a = 0. Emission bypasses the filter (filters/common.glsl gb_emission).
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/screen.glsl"
#include "lib/sampling.glsl"
#include "lib/brdf.glsl"
#include "lib/albedo.glsl"
#include "filters/common.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform writeonly image2D o_out;
uniform sampler2D u_in;
uniform sampler2D u_gb_albedo;
uniform sampler2D u_gb_position;
uniform sampler2D u_gb_normal;
uniform sampler2D u_gb_geonormal;
uniform int u_demod;

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    ivec2 size = textureSize(u_in, 0);
    if (any(greaterThanEqual(px, size))) return;
    vec4 s = texelFetch(u_in, px, 0);
    vec3 c = sanitize(s.rgb);
    vec4 pos = texelFetch(u_gb_position, px, 0);
    if (pos.w >= 0.0) {
        vec3 a = demod_albedo(texelFetch(u_gb_albedo, px, 0), texelFetch(u_gb_normal, px, 0),
                              texelFetch(u_gb_geonormal, px, 0), pos, view_dir(pos.xyz));
        vec3 e = gb_emission(pos, px);
        c = u_demod == 1 ? max(c - e, vec3(0.0)) / a : c * a + e;
    }
    imageStore(o_out, px, vec4(c, u_demod == 1 ? 0.0 : 1.0));
}
