// gather.comp — adds the probes' indirect light to DIRECT's colour, per pixel.
// Diffuse: color += diffuse albedo x E / pi, E = probe_irradiance() at the G-buffer point
// (probes/common.glsl; DDGI/RTXGI with visibility, IRRADIANCE_VOLUME without).
// PROBE_GLOSSY (RTXGI): glossy indirect from the probes in the reflection direction:
// color += specular albedo x E(R) / pi (the irradiance field read with the mirror direction
// as its normal: the radiance of a rough reflection, blurry for sharp ones).
// PROBE_GLOSSY_OUT (RTXGI_SSR): also writes o_glossy = DIRECT's world reflection (u_world_spec)
// + the probe glossy term just added: the whole glossy light already in colour, which SSR's
// composite uses as its miss fallback and replaces by its own result.
// Debug views (render passes): the irradiance field E/pi at surfaces with the probes drawn as
// small spheres shaded by their own irradiance (GI_ProbeIrradiance), the probes coloured by
// state over a grey image (GI_ProbeState: green active, red inactive, blue relocated), and the
// irradiance atlas stretched over the frame (GI_ProbeAtlas).
#define USE_SCENE_BUFFERS
#include "lib/common.glsl"
#include "lib/rng.glsl"
#include "lib/sampling.glsl"
#include "lib/brdf.glsl"
#include "lib/screen.glsl"
#include "screen_space/common.glsl"
#define PROBE_LOOKUP 1
#include "probes/common.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform image2D io_color;
layout(binding = 1, rgba32f) uniform writeonly image2D o_effect;
layout(binding = 2, rgba32f) uniform writeonly image2D o_view_irr;
layout(binding = 3, rgba32f) uniform writeonly image2D o_view_state;
layout(binding = 4, rgba32f) uniform writeonly image2D o_view_atlas;
#ifdef PROBE_GLOSSY_OUT
layout(binding = 5, rgba32f) uniform writeonly image2D o_glossy;
uniform sampler2D u_world_spec;
#endif
uniform float u_sphere_radius;
uniform int u_debug;   // 1: write the debug views

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    ivec2 size = imageSize(io_color);
    if (any(greaterThanEqual(px, size))) return;
    GPixel g = fetch_g(px);
    vec4 c = imageLoad(io_color, px);
    vec3 add = vec3(0.0), field = vec3(0.0), gloss = vec3(0.0);
    if (g.valid) {
        Surface s = fetch_surface(px, g.mid);
        vec3 V = view_dir(g.P);
        float NoV = max(dot(g.N, V), 1e-4);
        vec3 kd = diffuse_albedo(s, NoV);
        float w;
        vec3 E = probe_irradiance(g.P, g.N, V, w);
        field = E * INV_PI;
        add = kd * field;
#ifdef PROBE_GLOSSY
        vec3 ks = specular_albedo(s, NoV);
        if (max3(ks) > 0.0) {
            vec3 R = reflect(-V, g.N);
            float wr;
            vec3 ER = probe_irradiance(g.P, R, V, wr);
            gloss = ks * ER * INV_PI;
            add += gloss;
        }
#endif
    }
#ifdef PROBE_GLOSSY_OUT
    imageStore(o_glossy, px, vec4(sanitize(texelFetch(u_world_spec, px, 0).rgb + gloss), 1.0));
#endif
    vec3 total = sanitize(c.rgb + add);
    imageStore(io_color, px, vec4(total, c.a));
    imageStore(o_effect, px, vec4(total - c.rgb, 1.0));
    if (u_debug == 0) return;
    // camera ray through the pixel centre (unjittered enough for a debug view)
    mat4 inv = inverse(u_view_proj);
    vec2 ndc = (vec2(px) + 0.5) / vec2(size) * 2.0 - 1.0;
    vec4 a0 = inv * vec4(ndc, -1.0, 1.0), a1 = inv * vec4(ndc, 1.0, 1.0);
    vec3 o = a0.xyz / a0.w, d = normalize(a1.xyz / a1.w - o);
    float t_max = g.valid ? length(g.P - o) : 1e30;
    vec3 n;
    ivec3 slot;
    vec4 st;
    int hp = hit_probe(o, d, t_max, u_sphere_radius, n, slot, st);
    vec3 irr_view = field, state_view = vec3(luminance(total) * 0.25);
    if (hp >= 0) {
        irr_view = sample_probe_irradiance(slot, n) * INV_PI;
        float shade = 0.35 + 0.65 * max(dot(n, -d), 0.0);
        vec3 col = st.w > 0.5 ? vec3(1.0, 0.1, 0.1) : (dot(st.xyz, st.xyz) > 1e-12 ? vec3(0.15, 0.35, 1.0)
                                                                                     : vec3(0.1, 1.0, 0.2));
        state_view = col * shade;
    }
    imageStore(o_view_irr, px, vec4(sanitize(irr_view), 1.0));
    imageStore(o_view_state, px, vec4(state_view, 1.0));
    vec2 uv = (vec2(px) + 0.5) / vec2(size);
    imageStore(o_view_atlas, px, vec4(sanitize(textureLod(u_probe_irr, uv, 0.0).rgb * INV_PI), 1.0));
}
