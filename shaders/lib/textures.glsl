// textures.glsl — the one way every shader samples a material's base-colour texture
// (the G-buffer in raster/gbuffer.frag and every ray-tracing pass through lib/scene_rt.glsl),
// so rasterised and ray-traced hits of the same point see the same colour.
//
// As Cycles samples an Image Texture with Linear interpolation and Repeat extension:
// bilinear between texel centres of the full-resolution image (x * width - 0.5), wrapping.
// Done by hand with texelFetch so no sampler state (mipmaps, anisotropy, driver filtering
// shortcuts) can blur it; the G-buffer's box-filter jitter over frames then averages the
// pixel footprint the way Cycles' samples do.
#ifndef GI_TEXTURES_GLSL
#define GI_TEXTURES_GLSL

vec3 sample_base_texture(sampler2DArray tex, vec2 uv, int layer) {
    ivec2 size = textureSize(tex, 0).xy;
    vec2 x = uv * vec2(size) - 0.5;
    vec2 f = floor(x);
    vec2 t = x - f;
    ivec2 i0 = ivec2(f);
    ivec2 a = ((i0 % size) + size) % size;
    ivec2 b = (((i0 + 1) % size) + size) % size;
    vec3 c00 = texelFetch(tex, ivec3(a.x, a.y, layer), 0).rgb;
    vec3 c10 = texelFetch(tex, ivec3(b.x, a.y, layer), 0).rgb;
    vec3 c01 = texelFetch(tex, ivec3(a.x, b.y, layer), 0).rgb;
    vec3 c11 = texelFetch(tex, ivec3(b.x, b.y, layer), 0).rgb;
    return mix(mix(c00, c10, t.x), mix(c01, c11, t.x), t.y);
}

// Base colour of material m at uv: the texture when it has one (layer in base_color.w).
vec3 material_base_color(sampler2DArray tex, Material m, vec2 uv) {
    return m.base_color.w >= 0.0 ? sample_base_texture(tex, uv, int(m.base_color.w + 0.5)) : m.base_color.rgb;
}

#endif
