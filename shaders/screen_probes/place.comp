// place.comp — one invocation per probe tile: keep last frame's probe or spawn a new one, and
// decide who traces this frame (GI-1.0's reprojection, refresh and spawn queue).
// Keep: among last frame's probes of the 3×3 tiles around this one, those whose world position
// projects (this frame's camera) into this tile onto a surface in their plane (|n·(P - p)|
// within u_sp_plane_tol of the view depth) with a normal within ~25°; the one with the most
// traces is kept where it is, and its SH history comes along (o_src = its tile). Spawn: otherwise a pixel of the tile, chosen by a hash of the tile and frame
// among those that see a surface (up to 8 tries); no probe when none does.
// Refresh: a kept probe traces once in u_sp_refresh frames (a rotating pattern over 2×2 tiles
// for 4: a quarter of the probes per frame) and every frame while it has fewer than
// u_sp_spawn_traces traces; a new probe traces at once.
// SP_ADAPTIVE (SCREEN_PROBES' adaptive refinement, after Lumen): the set of half-size tiles
// that get a probe only where the coarse probes' interpolation weight at the tile's centre
// pixel is below u_min_weight (a corner, an edge, a thin object); the new probe sits on that
// pixel.
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/rng.glsl"
#include "lib/sampling.glsl"
#include "lib/brdf.glsl"
#include "lib/screen.glsl"
#include "screen_space/common.glsl"
#include "screen_probes/common.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform writeonly image2D o_pos;
layout(binding = 1, rgba32f) uniform writeonly image2D o_nrm;
layout(binding = 2, r32i) uniform writeonly iimage2D o_src;
uniform sampler2D u_prev_pos;
uniform sampler2D u_prev_nrm;
uniform int u_history;           // 0: last frame's probes are not valid (reset)
uniform float u_sp_plane_tol;
uniform int u_sp_refresh;
uniform float u_sp_spawn_traces;
#ifdef SP_ADAPTIVE
// adaptive refinement (SCREEN_PROBES): this set's tiles are half the coarse set's; a tile gets
// a probe only where the coarse probes fail to interpolate at its centre pixel
uniform sampler2D u_coarse_pos;
uniform sampler2D u_coarse_nrm;
uniform int u_coarse_tile;
uniform ivec2 u_coarse_grid;
uniform float u_min_weight;
#endif

void main() {
    ivec2 t = ivec2(gl_GlobalInvocationID.xy);
    if (!sp_in_grid(t)) return;
    ivec2 lo = t * u_sp_tile, hi = min(lo + u_sp_tile, ivec2(u_resolution));
#ifdef SP_ADAPTIVE
    ivec2 c = min((lo + hi) / 2, ivec2(u_resolution) - 1);
    GPixel gc = fetch_g(c);
    vec3 unused = vec3(0.0);
    if (!gc.valid || sp_gather_grid(u_coarse_pos, u_coarse_nrm, u_coarse_pos, u_coarse_pos, u_coarse_pos,
                                    u_coarse_pos, false, u_coarse_tile, u_coarse_grid, vec2(c) + 0.5, gc.P,
                                    gc.Ng, gc.N, gc.N, false, max(view_depth(gc.P), 1e-4), u_sp_plane_tol,
                                    unused, unused) >= u_min_weight) {
        imageStore(o_pos, t, vec4(0.0));
        imageStore(o_nrm, t, vec4(0.0, 0.0, 1.0, 0.0));
        imageStore(o_src, t, ivec4(-1));
        return;
    }
#endif
    int src = -1;
    float best = -1.0;
    vec3 P = vec3(0.0), N = vec3(0.0, 0.0, 1.0);
    if (u_history != 0) {
        for (int dy = -1; dy <= 1; ++dy)
            for (int dx = -1; dx <= 1; ++dx) {
                ivec2 q = t + ivec2(dx, dy);
                if (!sp_in_grid(q)) continue;
                vec4 pp = texelFetch(u_prev_pos, q, 0);
                if (pp.w < 0.5) continue;
                vec2 pix = to_pixel(pp.xyz);
                if (any(lessThan(pix, vec2(lo))) || any(greaterThanEqual(pix, vec2(hi)))) continue;
                GPixel g = fetch_g(ivec2(pix));
                if (!g.valid) continue;
                vec4 pn = texelFetch(u_prev_nrm, q, 0);
                float depth = max(view_depth(g.P), 1e-4);
                if (abs(dot(g.Ng, pp.xyz - g.P)) > u_sp_plane_tol * depth || dot(g.Ng, pn.xyz) < 0.9) continue;
                if (pn.w > best) {  // kept where it was: the surface under it has not moved
                    best = pn.w;
                    src = q.x + q.y * u_sp_grid.x;
                    P = pp.xyz;
                    N = normalize(pn.xyz);
                }
            }
    }
    float traces = max(best, 0.0);
    float state = 0.0;
    if (src >= 0) {
        int phase = (t.x & 1) + 2 * (t.y & 1);  // 2x2 pattern: a quarter per frame for refresh 4
        bool refresh = u_sp_refresh <= 1 || int(u_sp_frame % uint(u_sp_refresh)) == phase % u_sp_refresh
                       || traces < u_sp_spawn_traces;
        state = refresh ? 2.0 : 1.0;
    } else {
        for (int k = 0; k < 8; ++k) {
            uvec4 h = pcg4d(uvec4(uvec2(t), u_sp_frame, uint(k) + 0x51u));
            ivec2 px = lo + ivec2(h.xy % uvec2(max(hi - lo, ivec2(1))));
#ifdef SP_ADAPTIVE
            if (k == 0) px = c;  // where interpolation failed
#endif
            GPixel g = fetch_g(px);
            if (g.valid) {
                P = g.P;
                N = g.Ng;
                state = 3.0;
                traces = 0.0;
                break;
            }
        }
    }
    if (state >= 2.0) traces += 1.0;
    imageStore(o_pos, t, vec4(P, state));
    imageStore(o_nrm, t, vec4(N, traces));
    imageStore(o_src, t, ivec4(src));
}
