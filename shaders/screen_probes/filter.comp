// filter.comp — one invocation per probe: the spatial filter of the probes' SH (GI-1.0 and
// Lumen filter their screen probes over their neighbours): the mean over the probes of the
// (2r+1)² tiles around, each weighted by its traces so far and kept only when it lies in this
// probe's plane (|n·(p_j - p)| within u_sp_plane_tol of the view depth) and faces within
// ~37° of its normal (a wall's probes do not mix with the floor's). Not fed back: the history
// stays unfiltered.
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/rng.glsl"
#include "lib/sampling.glsl"
#include "lib/screen.glsl"
#include "screen_probes/common.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform writeonly image2D o_sh_r;
layout(binding = 1, rgba32f) uniform writeonly image2D o_sh_g;
layout(binding = 2, rgba32f) uniform writeonly image2D o_sh_b;
layout(binding = 3, rgba32f) uniform writeonly image2D o_sh_n;
uniform sampler2D u_sp_pos;
uniform sampler2D u_sp_nrm;
uniform sampler2D u_sh_r;
uniform sampler2D u_sh_g;
uniform sampler2D u_sh_b;
uniform sampler2D u_sh_n;
uniform int u_radius;
uniform float u_sp_plane_tol;

void main() {
    ivec2 t = ivec2(gl_GlobalInvocationID.xy);
    if (!sp_in_grid(t)) return;
    vec4 pp = texelFetch(u_sp_pos, t, 0);
    vec4 pn = texelFetch(u_sp_nrm, t, 0);
    vec4 r = vec4(0.0), g = vec4(0.0), b = vec4(0.0), e = vec4(0.0);
    if (pp.w > 0.5) {
        float depth = max(view_depth(pp.xyz), 1e-4), wsum = 0.0;
        for (int dy = -u_radius; dy <= u_radius; ++dy)
            for (int dx = -u_radius; dx <= u_radius; ++dx) {
                ivec2 q = t + ivec2(dx, dy);
                if (!sp_in_grid(q)) continue;
                vec4 qp = texelFetch(u_sp_pos, q, 0), qn = texelFetch(u_sp_nrm, q, 0);
                if (qp.w < 0.5 || dot(qn.xyz, pn.xyz) < 0.8) continue;
                if (abs(dot(pn.xyz, qp.xyz - pp.xyz)) > u_sp_plane_tol * depth) continue;
                float w = max(qn.w, 0.0) + 1e-3;
                r += w * texelFetch(u_sh_r, q, 0);
                g += w * texelFetch(u_sh_g, q, 0);
                b += w * texelFetch(u_sh_b, q, 0);
                e += w * texelFetch(u_sh_n, q, 0);
                wsum += w;
            }
        if (wsum > 0.0) { r /= wsum; g /= wsum; b /= wsum; e /= wsum; }
    }
    imageStore(o_sh_r, t, finite_or_zero(r));
    imageStore(o_sh_g, t, finite_or_zero(g));
    imageStore(o_sh_b, t, finite_or_zero(b));
    imageStore(o_sh_n, t, finite_or_zero(e));
}
