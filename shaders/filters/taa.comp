// taa.comp — temporal anti-aliasing (Karis 2014, "High quality temporal supersampling").
// Camera jitter: the session's R2 sequence (see docs/techniques/TAA.md: R2 covers the pixel
// more evenly than Halton(2,3) and the G-buffer and every pass already use it). History is
// reprojected through gbuffer.motion (bilinear), converted to YCoCg and clipped towards the
// centre of the 3x3 neighbourhood's YCoCg box (min/max, tightened by mean ± gamma sigma,
// Salvi 2016), then blended with weight u_alpha using Karis' luminance weighting (1/(1+Y))
// against flicker. Off-screen, background-changed or non-finite history is dropped.
#include "lib/common.glsl"
#include "lib/screen.glsl"
#include "filters/common.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform writeonly image2D o_hist;   // rgb result, a = 1 valid

uniform sampler2D u_color;
uniform sampler2D u_hist;       // last frame's result (bilinear)
uniform sampler2D u_gb_motion;
uniform sampler2D u_gb_position;
uniform int u_reset;
uniform float u_alpha;
uniform float u_gamma;

vec3 rgb2ycocg(vec3 c) {
    return vec3(0.25 * c.r + 0.5 * c.g + 0.25 * c.b, 0.5 * c.r - 0.5 * c.b, -0.25 * c.r + 0.5 * c.g - 0.25 * c.b);
}
vec3 ycocg2rgb(vec3 c) { return vec3(c.x + c.y - c.z, c.x + c.z, c.x - c.y - c.z); }

// clip q towards the box centre (Karis 2014: clip, not clamp, avoids the box-corner colours)
vec3 clip_aabb(vec3 mn, vec3 mx, vec3 q) {
    vec3 c = 0.5 * (mx + mn);
    vec3 e = 0.5 * (mx - mn) + 1e-6;
    vec3 v = q - c;
    vec3 a = abs(v / e);
    float m = max(a.x, max(a.y, a.z));
    return m > 1.0 ? c + v / m : q;
}

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    ivec2 size = textureSize(u_color, 0);
    if (any(greaterThanEqual(px, size))) return;
    vec3 cur = sanitize(texelFetch(u_color, px, 0).rgb);
    vec3 m1 = vec3(0.0), m2 = vec3(0.0), mn = vec3(1e30), mx = vec3(-1e30);
    for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
            ivec2 q = clamp(px + ivec2(dx, dy), ivec2(0), size - 1);
            // tone-mapped YCoCg (bright outliers of a noisy input do not widen the box)
            vec3 cq = sanitize(texelFetch(u_color, q, 0).rgb);
            vec3 y = rgb2ycocg(cq / (1.0 + luminance(cq)));
            m1 += y;
            m2 += y * y;
            mn = min(mn, y);
            mx = max(mx, y);
        }
    m1 /= 9.0;
    vec3 sig = sqrt(max(m2 / 9.0 - m1 * m1, vec3(0.0)));
    mn = max(mn, m1 - u_gamma * sig);
    mx = min(mx, m1 + u_gamma * sig);
    vec3 outc = cur;
    if (u_reset == 0) {
        vec2 uv = (vec2(px) + 0.5 - texelFetch(u_gb_motion, px, 0).xy) / vec2(size);
        if (all(greaterThanEqual(uv, vec2(0.0))) && all(lessThanEqual(uv, vec2(1.0)))) {
            vec4 h = texture(u_hist, uv);
            if (finite4(h) && h.a > 0.5) {
                vec3 hy = rgb2ycocg(max(h.rgb, vec3(0.0)) / (1.0 + luminance(max(h.rgb, vec3(0.0)))));
                hy = clip_aabb(mn, mx, hy);
                vec3 cy = rgb2ycocg(cur / (1.0 + luminance(cur)));
                // blend in the tone-mapped space (Karis' 1/(1+Y) weighting), then invert
                vec3 by = mix(hy, cy, u_alpha);
                vec3 t = max(ycocg2rgb(by), vec3(0.0));
                float lt = luminance(t);
                outc = lt < 0.999 ? t / (1.0 - lt) : cur;
            }
        }
    }
    imageStore(o_hist, px, vec4(sanitize(outc), 1.0));
}
