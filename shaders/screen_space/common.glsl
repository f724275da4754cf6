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
    Material m = materials[mid];
    return gbuffer_surface(m, texelFetch(u_gb_albedo, px, 0), texelFetch(u_gb_normal, px, 0),
                           texelFetch(u_gb_geonormal, px, 0), m.emission.rgb);
}

// How far a pixel's radiance toward the camera (aov.direct) stands for its radiance in
// the direction Vr (towards a receiver: SSR's reflecting pixel, SSDO's receiver). Its diffuse share is the same in every direction;
// its glossy share only within the glossy lobe's width (about 2 alpha around the camera
// direction). A metal seen in a mirror from another side shows other highlights than the
// camera sees: its radiance is not known on screen, so that share falls back (the composite
// keeps DIRECT's world reflection for it) instead of copying the camera's highlights to
// the wrong place.
// view_trust in two halves: what depends on the pixel only (its diffuse share fd of the
// radiance toward the camera, and the glossy lobe's angular width sigma), and the weight
// for a receiver direction. SSDO evaluates the first half once per pixel into an image
// (ssdo_trust.comp) instead of once per sample.
vec2 trust_params(GPixel h, ivec2 hp) {
    Surface sh = fetch_surface(hp, h.mid);
    float NoVc = max(dot(h.N, view_dir(h.P)), 1e-4);
    float kd = luminance(diffuse_albedo(sh, NoVc));
    float ks = luminance(specular_albedo(sh, NoVc));
    return vec2(kd / max(kd + ks, 1e-6), 2.0 * sh.alpha + 0.02);
}

float trust_weight(vec2 fd_sigma, vec3 Vc, vec3 Vr) {
    float fd = fd_sigma.x, sigma = fd_sigma.y;
    float ang = acos(clamp(dot(Vc, Vr), -1.0, 1.0));
    return fd + (1.0 - fd) * exp(-0.5 * ang * ang / (sigma * sigma));
}

float view_trust(GPixel h, ivec2 hp, vec3 Vr) {
    return trust_weight(trust_params(h, hp), view_dir(h.P), Vr);
}

#endif

// Far field: does direction dir from O, already open within the radius r, still see the
// world further out? A coarse march of u_far_points points spaced geometrically from r to
// u_far_distance; a point behind the visible surface by less than the spacing (the
// assumed thickness) is blocked there. Returns the blocking pixel, ivec2(-1) (open: every
// point stayed on screen in front of the surfaces) or ivec2(-2) (unknown: the march left
// the screen, where screen space knows nothing).
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
        if (!on_screen(sp)) return ivec2(-2);
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

// GGX terms in a form that does not overflow for near-mirrors. lib/brdf.glsl's ggx_D
// computes 1 + NoH^2 (a2 - 1), which in fp32 cancels to 0 when a2 < 6e-8 (roughness < 0.016)
// and NoH = 1; the denominator here is sin^2 + cos^2 a2 with sin^2 = |N x H|^2, exact for
// small angles, so D <= 1 / (PI a2) and a VNDF pdf stays finite (<= ~1e11 at a2 = 1e-8).
float ss_ggx_D(vec3 N, vec3 H, float a2) {
    vec3 c = cross(N, H);
    float NoH = dot(N, H);
    float d = dot(c, c) + NoH * NoH * a2;
    return a2 / (PI * max(d * d, 1e-30));
}

// pdf (solid angle, of L) of GGX visible-normal sampling: G1(V) D(H) / (4 NoV).
float ss_vndf_pdf(vec3 N, vec3 V, vec3 H, float a2) {
    float NoV = max(dot(N, V), 1e-4);
    return ggx_G1(NoV, a2) * ss_ggx_D(N, H, a2) / (4.0 * NoV);
}

// Per-pixel, per-frame random numbers (the rotation of the kernels).
vec4 pixel_noise(ivec2 px, uint stream) {
    Rng r = rng_init(uvec2(px), u_sample, stream);
    return rng_next4(r);
}

#endif
