// textures.glsl — the one way every shader samples a material's textures (the G-buffer in
// raster/gbuffer.frag, shadow maps, RSM, VXGI's voxeliser and every ray-tracing pass through
// lib/scene_rt.glsl), so rasterised and ray-traced hits of the same point see the same
// material.
//
// As Cycles samples an Image Texture: Linear = bilinear between texel centres of the
// full-resolution image (x * size - 0.5), Closest = the texel under x * size; Repeat,
// Extend, Clip (zero outside [0, 1]) and Mirror extension. Each image sits unscaled at the
// origin of its array layer with its own size in the material's map record (common.glsl),
// and is read with texelFetch so no sampler state (mipmaps, anisotropy, driver filtering
// shortcuts) can blur it; the G-buffer's box-filter jitter over frames then averages the
// pixel footprint the way Cycles' samples do. A map's sample is one channel or RGB, times
// the map's scale.
#ifndef GI_TEXTURES_GLSL
#define GI_TEXTURES_GLSL

// a mod n in [0, n) for any sign of a (GLSL leaves % of negative operands undefined)
int tex_mod(int a, int n) { return a - n * int(floor(float(a) / float(n))); }

// texel index i along an axis of n texels under extension mode ext; valid = false outside (Clip)
int tex_wrap(int i, int n, int ext, inout bool valid) {
    if (ext == 0) return tex_mod(i, n);
    if (ext == 3) {
        int p = tex_mod(i, 2 * n);
        return p < n ? p : 2 * n - 1 - p;
    }
    if (ext == 2 && (i < 0 || i >= n)) valid = false;
    return clamp(i, 0, n - 1);
}

vec4 tex_fetch(sampler2DArray tex, int layer, ivec2 size, int ext, int x, int y) {
    bool valid = true;
    int xi = tex_wrap(x, size.x, ext, valid);
    int yi = tex_wrap(y, size.y, ext, valid);
    return valid ? texelFetch(tex, ivec3(xi, yi, layer), 0) : vec4(0.0);
}

// The colour attribute at the point being shaded (Color Attribute node): set by the caller
// before sample_material (gbuffer.frag from the vertex attribute, scene_trace from the hit's
// corners); a map whose layer is MAP_LAYER_VERTEX_COLOR reads it.
#define MAP_LAYER_VERTEX_COLOR -2.0
vec4 g_vertex_color = vec4(0.0);

// RGBA of one map at uv (no channel selection, no scale).
vec4 sample_map_rgba(sampler2DArray tex, vec4 map, vec2 uv) {
    if (map.x < -1.5) return g_vertex_color;
    int layer = int(map.x + 0.5);
    int wh = int(map.y + 0.5);
    ivec2 size = max(ivec2(wh / 4096, wh % 4096), ivec2(1));
    int flags = int(map.z + 0.5);
    int ext = (flags >> 4) & 3;
    if (ext == 2 && (uv.x < 0.0 || uv.x > 1.0 || uv.y < 0.0 || uv.y > 1.0)) return vec4(0.0);
    if ((flags & 8) != 0) {  // Closest
        ivec2 i = ivec2(floor(uv * vec2(size)));
        return tex_fetch(tex, layer, size, ext, i.x, i.y);
    }
    vec2 x = uv * vec2(size) - 0.5;
    vec2 f = floor(x);
    vec2 t = x - f;
    ivec2 i0 = ivec2(f);
    vec4 c00 = tex_fetch(tex, layer, size, ext, i0.x, i0.y);
    vec4 c10 = tex_fetch(tex, layer, size, ext, i0.x + 1, i0.y);
    vec4 c01 = tex_fetch(tex, layer, size, ext, i0.x, i0.y + 1);
    vec4 c11 = tex_fetch(tex, layer, size, ext, i0.x + 1, i0.y + 1);
    return mix(mix(c00, c10, t.x), mix(c01, c11, t.x), t.y);
}

// The map's value: its channel (flags & 7 = channel + 1) or RGB, times its scale.
vec3 sample_map_rgb(sampler2DArray tex, vec4 map, vec2 uv) {
    vec4 c = sample_map_rgba(tex, map, uv);
    int ch = (int(map.z + 0.5) & 7) - 1;
    return (ch < 0 ? c.rgb : vec3(c[ch])) * map.w;
}

float sample_map_float(sampler2DArray tex, vec4 map, vec2 uv) {
    vec4 c = sample_map_rgba(tex, map, uv);
    int ch = (int(map.z + 0.5) & 7) - 1;
    return (ch < 0 ? luminance(c.rgb) : c[ch]) * map.w;
}

// d(value)/du, d(value)/dv of a map at uv: the derivative of its bilinear interpolation
// (zero for Closest, and outside [0, 1] under Clip), its channel (RGB: luminance), times its scale.
vec2 sample_map_float_grad(sampler2DArray tex, vec4 map, vec2 uv) {
    int layer = int(map.x + 0.5);
    int wh = int(map.y + 0.5);
    ivec2 size = max(ivec2(wh / 4096, wh % 4096), ivec2(1));
    int flags = int(map.z + 0.5);
    int ext = (flags >> 4) & 3;
    if ((flags & 8) != 0 || map.x < -1.5) return vec2(0.0);
    if (ext == 2 && (uv.x < 0.0 || uv.x > 1.0 || uv.y < 0.0 || uv.y > 1.0)) return vec2(0.0);
    vec2 x = uv * vec2(size) - 0.5;
    vec2 f = floor(x);
    vec2 t = x - f;
    ivec2 i0 = ivec2(f);
    int ch = (flags & 7) - 1;
    vec4 c00 = tex_fetch(tex, layer, size, ext, i0.x, i0.y);
    vec4 c10 = tex_fetch(tex, layer, size, ext, i0.x + 1, i0.y);
    vec4 c01 = tex_fetch(tex, layer, size, ext, i0.x, i0.y + 1);
    vec4 c11 = tex_fetch(tex, layer, size, ext, i0.x + 1, i0.y + 1);
    vec4 du = mix(c10 - c00, c11 - c01, t.y) * float(size.x);
    vec4 dv = mix(c01 - c00, c11 - c10, t.x) * float(size.y);
    vec2 g = ch < 0 ? vec2(luminance(du.rgb), luminance(dv.rgb)) : vec2(du[ch], dv[ch]);
    return g * map.w;
}

bool has_map(Material m, int k) { return m.maps[k].x >= 0.0 || m.maps[k].x < -1.5; }

// Base colour of material m at uv.
vec3 material_base_color(sampler2DArray tex, Material m, vec2 uv) {
    return has_map(m, MAP_BASE_COLOR) ? sample_map_rgb(tex, m.maps[MAP_BASE_COLOR], uv) : m.base_color.rgb;
}

// Alpha of material m at uv (1 = opaque).
float material_alpha(sampler2DArray tex, Material m, vec2 uv) {
    return has_map(m, MAP_ALPHA) ? sample_map_float(tex, m.maps[MAP_ALPHA], uv) : m.emission.w;
}

struct MaterialSample {
    vec3 base_color;
    float metallic;
    float roughness;
    float specular_ior_level;
    float alpha;
    vec3 emission;       // radiance
    vec4 normal_map;     // xyz: tangent-space normal in [-1, 1]^3, w = strength (0 = no normal map)
    vec3 bump;           // xy: the Bump height's UV gradient times Distance, z = Strength (0 = no bump)
};

// Every textured input of material m at uv (constants where a map is missing).
MaterialSample sample_material(sampler2DArray tex, Material m, vec2 uv) {
    MaterialSample s;
    s.base_color = material_base_color(tex, m, uv);
    s.roughness = has_map(m, MAP_ROUGHNESS) ? sample_map_float(tex, m.maps[MAP_ROUGHNESS], uv) : m.params.y;
    s.metallic = has_map(m, MAP_METALLIC) ? sample_map_float(tex, m.maps[MAP_METALLIC], uv) : m.params.x;
    s.specular_ior_level = has_map(m, MAP_SPECULAR) ? sample_map_float(tex, m.maps[MAP_SPECULAR], uv) : m.params.w;
    s.alpha = material_alpha(tex, m, uv);
    s.emission = has_map(m, MAP_EMISSION) ? sample_map_rgb(tex, m.maps[MAP_EMISSION], uv) : m.emission.rgb;
    s.normal_map = vec4(0.0, 0.0, 1.0, 0.0);
    if (has_map(m, MAP_NORMAL)) {
        vec4 map = m.maps[MAP_NORMAL];
        s.normal_map = vec4(2.0 * sample_map_rgba(tex, map, uv).rgb - 1.0, max(map.w, 0.0));
    }
    s.bump = vec3(0.0);
    if (has_map(m, MAP_BUMP) && m.lobes.z > 0.0)
        s.bump = vec3(sample_map_float_grad(tex, m.maps[MAP_BUMP], uv), m.lobes.z);
    return s;
}

// The material record with the sampled values in place of the constants (make_surface reads it).
Material material_at(Material m, MaterialSample s) {
    m.base_color.rgb = s.base_color;
    m.params.x = s.metallic;
    m.params.y = s.roughness;
    m.params.w = s.specular_ior_level;
    m.emission = vec4(s.emission, s.alpha);
    return m;
}

// Cycles' Normal Map node (tangent space): N' = normalize(c.x T + c.y B + c.z N) with
// B = sign * cross(N, T), then N + (N' - N) * strength renormalised. N: the interpolated
// (unflipped) shading normal, T: the interpolated tangent (xyz) and bitangent sign (w), both
// in world space. Without a normal map, or without tangents, N is returned unchanged.
vec3 apply_normal_map(MaterialSample s, vec3 N, vec4 T) {
    if (s.normal_map.w <= 0.0 || dot(T.xyz, T.xyz) <= 0.0) return N;
    vec3 B = (T.w < 0.0 ? -1.0 : 1.0) * cross(N, T.xyz);
    vec3 Nm = s.normal_map.x * T.xyz + s.normal_map.y * B + s.normal_map.z * N;
    float l = length(Nm);
    if (l <= 0.0) return N;
    Nm /= l;
    if (s.normal_map.w != 1.0) {
        Nm = N + (Nm - N) * s.normal_map.w;
        l = length(Nm);
        Nm = l > 0.0 ? Nm / l : N;
    }
    return Nm;
}

// Cycles' Bump node (svm_node_set_bump) with the height's screen differentials replaced by
// its UV derivatives: for the surface differentials dx = dP/du, dy = dP/dv (world space, the
// triangle's), h_x - h_c = dh/du and h_y - h_c = dh/dv (Distance included), Rx = dy x N,
// Ry = N x dx, det = dx . Rx: N' = normalize(|det| N - sign(det) (dh/du Rx + dh/dv Ry)), then
// N + (N' - N) * strength renormalised. The formula is the same for any basis of the tangent
// plane, so it equals Cycles' with its ray differentials. N: the normal-mapped normal (a Normal
// Map feeding the Bump node's Normal input).
vec3 apply_bump(MaterialSample s, vec3 N, vec3 dpdu, vec3 dpdv) {
    if (s.bump.z <= 0.0) return N;
    vec3 Rx = cross(dpdv, N);
    vec3 Ry = cross(N, dpdu);
    float det = dot(dpdu, Rx);
    if (det == 0.0) return N;
    vec3 surfgrad = s.bump.x * Rx + s.bump.y * Ry;
    vec3 n = abs(det) * N - sign(det) * surfgrad;
    float l = length(n);
    if (l <= 0.0) return N;
    n /= l;
    return normalize(s.bump.z * n + (1.0 - s.bump.z) * N);
}

// The shading normal of a sample: the normal map, then the bump.
vec3 shading_normal(MaterialSample s, vec3 N, vec4 T, vec3 dpdu, vec3 dpdv) {
    return apply_bump(s, apply_normal_map(s, N, T), dpdu, dpdv);
}

// Stochastic alpha (Cycles' transparency): a surface of alpha a is a hole for a uniform
// random u >= a. hash_u01 gives u from any 32-bit seed.
float alpha_hash_u01(uvec3 v) {
    v = v * 1664525u + 1013904223u;
    v.x += v.y * v.z; v.y += v.z * v.x; v.z += v.x * v.y;
    v ^= v >> 16u;
    v.x += v.y * v.z; v.y += v.z * v.x; v.z += v.x * v.y;
    return float(v.x >> 8) * (1.0 / 16777216.0);
}

#endif
