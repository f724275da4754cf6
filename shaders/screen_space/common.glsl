// common.glsl (screen_space) — what every screen-space pass of the family shares:
// G-buffer samplers and fetches (the diffuse/specular albedos are in lib/albedo.glsl), and
// per-pixel rotation noise. Include after lib/common.glsl (with USE_SCENE_BUFFERS), lib/rng.glsl,
// lib/sampling.glsl, lib/brdf.glsl and lib/screen.glsl.
#ifndef GI_SS_COMMON_GLSL
#define GI_SS_COMMON_GLSL

uniform sampler2D u_gb_albedo;
uniform sampler2D u_gb_normal;     // w = roughness
uniform sampler2D u_gb_position;   // w = material id, < 0 background
uniform sampler2D u_gb_geonormal;  // w = metallic
uniform vec3 u_world;              // uniform world radiance
uniform uint u_sample;

struct GPixel {
    bool valid;
    vec3 P;
    vec3 N;
    vec3 Ng;
    int mid;
};

GPixel fetch_g(ivec2 px) {
    GPixel g;
    px = clamp(px, ivec2(0), ivec2(u_resolution) - 1);
    vec4 pos = texelFetch(u_gb_position, px, 0);
    g.valid = pos.w >= 0.0;
    g.P = pos.xyz;
    g.mid = int(pos.w + 0.5);
    g.N = normalize(texelFetch(u_gb_normal, px, 0).xyz + vec3(0.0, 0.0, 1e-12));
    g.Ng = normalize(texelFetch(u_gb_geonormal, px, 0).xyz + vec3(0.0, 0.0, 1e-12));
    return g;
}

#include "lib/albedo.glsl"

#ifdef USE_SCENE_BUFFERS
Surface fetch_surface(ivec2 px, int mid) {
    return make_surface(materials[mid], texelFetch(u_gb_albedo, px, 0).rgb);
}

#endif

// Far field: does direction dir from O, already open within the radius r, still see the
// world further out? A coarse march of u_far_points points spaced geometrically from r to
// u_far_distance; a point behind the visible surface by less than the spacing (the
// assumed thickness) is blocked there. Returns the blocking pixel (or ivec2(-1): open).
// Points leaving the screen stop the march: open (screen space knows nothing beyond).
uniform float u_far_distance;
uniform int u_far_points;

ivec2 far_blocker(vec3 O, vec3 dir, float r, float jitter) {
    int m = u_far_points;
    if (m <= 0 || u_far_distance <= r) return ivec2(-1);
    float ratio = u_far_distance / r;
    float prev_t = r;
    for (int j = 0; j < m; ++j) {
        float t = r * pow(ratio, (float(j) + jitter) / float(m));
        vec3 S = O + dir * t;
        vec2 sp = to_pixel(S);
        if (!on_screen(sp)) break;
        ivec2 hp = ivec2(sp);
        vec4 hpos = texelFetch(u_gb_position, hp, 0);
        if (hpos.w >= 0.0) {
            float ds = view_depth(S), dh = view_depth(hpos.xyz);
            if (dh < ds && ds - dh < (t - prev_t) + 0.05 * t) return hp;
        }
        prev_t = t;
    }
    return ivec2(-1);
}

// Per-pixel, per-frame random numbers (the rotation of the kernels).
vec4 pixel_noise(ivec2 px, uint stream) {
    Rng r = rng_init(uvec2(px), u_sample, stream);
    return rng_next4(r);
}

#endif
