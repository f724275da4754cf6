// world.glsl — the world's radiance as every pass reads it (host: addon/render/world_map.py,
// bound by GPUScene.bind). A uniform world (u_world_mode 0) is the colour u_world_color; a
// map (u_world_mode 1) is an equirectangular radiance texture in Blender's Environment
// Texture convention (+X at the centre, row 0 at the bottom), with:
//   world_radiance(d)        radiance arriving from direction d (background, BSDF-ray misses)
//   world_irradiance(n)      irradiance E(n) on a surface facing n (a small cosine-convolved map)
//   world_glossy(r, alpha)   radiance prefiltered over a GGX lobe of roughness alpha around r
//                            (a mip level of the map: the split-sum approximation's first half)
// Importance sampling of the map (world_sample / world_pdf) needs the ray tracer's light
// table and lives in lib/scene_rt.glsl.
#ifndef GI_WORLD_GLSL
#define GI_WORLD_GLSL

uniform sampler2D u_world_map;
uniform int u_world_mode;       // 0 = uniform colour, 1 = map
uniform vec3 u_world_color;     // uniform radiance, or the map's solid-angle mean
uniform sampler2D u_world_irr;  // irradiance E(n) over directions, equirectangular (map only)
uniform float u_world_lods;     // highest mip level of the map
uniform int u_film_transparent; // 1: the camera sees no world (Render > Film > Transparent)

// v by the arc tangent, not asin(d.z): GPUs' asin is coarse (about 1 % of a sampling cell
// of the map on llvmpipe), and world_pdf must find the very cell world_sample drew from
vec2 world_uv(vec3 d) {
    float u = 0.5 - atan(d.y, d.x) * (0.5 * INV_PI);
    float v = 0.5 + atan(d.z, length(d.xy)) * INV_PI;
    return vec2(u, v);
}

vec3 world_uv_to_dir(vec2 uv) {
    float az = PI * (1.0 - 2.0 * uv.x);
    float el = PI * (uv.y - 0.5);
    float ce = cos(el);
    return vec3(ce * cos(az), ce * sin(az), sin(el));
}

// The background a pixel shows (the world seen through the camera): u_inv_view_proj is the
// inverse of the frame's (jittered) view-projection; px in pixels (centre +0.5).
uniform mat4 u_inv_view_proj;
vec3 camera_ray_dir(vec2 px, vec2 size) {
    vec2 ndc = px / size * 2.0 - 1.0;
    vec4 a = u_inv_view_proj * vec4(ndc, -1.0, 1.0);
    vec4 b = u_inv_view_proj * vec4(ndc, 1.0, 1.0);
    return normalize(b.xyz / b.w - a.xyz / a.w);
}

vec3 world_radiance(vec3 d) {
    if (u_world_mode == 0) return u_world_color;
    return textureLod(u_world_map, world_uv(d), 0.0).rgb;
}

vec3 world_irradiance(vec3 n) {
    if (u_world_mode == 0) return PI * u_world_color;
    // rows from pole to pole (world_map.irradiance_uv): texel centre i at v = i / (h - 1)
    vec2 uv = world_uv(n);
    float h = float(textureSize(u_world_irr, 0).y);
    return textureLod(u_world_irr, vec2(uv.x, (uv.y * (h - 1.0) + 0.5) / h), 0.0).rgb;
}

// The lobe's angular radius is about alpha radians; one texel of level 0 spans 2 pi / W.
vec3 world_glossy(vec3 r, float alpha) {
    if (u_world_mode == 0) return u_world_color;
    float w = float(textureSize(u_world_map, 0).x);
    float lod = clamp(log2(max(alpha, 1e-4) * w / TWO_PI) + 0.5, 0.0, u_world_lods);
    return textureLod(u_world_map, world_uv(r), lod).rgb;
}

vec3 world_background(ivec2 px, ivec2 size) {
    if (u_film_transparent != 0) return vec3(0.0);
    if (u_world_mode == 0) return u_world_color;
    return world_radiance(camera_ray_dir(vec2(px) + 0.5, vec2(size)));
}

#endif
