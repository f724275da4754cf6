// octahedral.glsl — octahedral maps of the unit sphere (Cigolle et al. 2014, "A Survey of
// Efficient Representations for Independent Unit Vectors") and the bordered atlas tiles
// probe techniques store them in (DDGI, RTXGI; later surfels and screen probes).
//
//   vec2 e = oct_encode(dir);    // unit vector -> [-1, 1]^2 (lower hemisphere folded out)
//   vec3 d = oct_decode(e);      // inverse, unit vector
// Bordered tiles: a tile of `size` texels per side holds (size - 2)^2 interior texels and a
// one-texel border that repeats the interior texel across the octahedral seam, so bilinear
// filtering inside one tile is continuous over the sphere:
//   ivec2 t = oct_border_source(texel_in_tile, size);  // interior texel a border texel copies
//   vec3  d = oct_texel_dir(texel_in_tile, size);       // direction of a texel (borders: mirrored)
//   vec2 uv = oct_tile_uv(dir, size);                   // continuous texel coords inside the tile
// Spherical Fibonacci directions (fixed, well spread ray sets):
//   vec3 d = spherical_fibonacci(i, n);
#ifndef GI_OCTAHEDRAL_GLSL
#define GI_OCTAHEDRAL_GLSL

vec2 oct_sign_not_zero(vec2 v) { return vec2(v.x >= 0.0 ? 1.0 : -1.0, v.y >= 0.0 ? 1.0 : -1.0); }

vec2 oct_encode(vec3 d) {
    vec2 p = d.xy / max(abs(d.x) + abs(d.y) + abs(d.z), 1e-20);
    if (d.z < 0.0) p = (1.0 - abs(p.yx)) * oct_sign_not_zero(p);
    return p;
}

vec3 oct_decode(vec2 e) {
    vec3 v = vec3(e, 1.0 - abs(e.x) - abs(e.y));
    if (v.z < 0.0) v.xy = (1.0 - abs(v.yx)) * oct_sign_not_zero(v.xy);
    return normalize(v);
}

// The interior texel (in [1, size-2]^2) that texel t of a bordered tile shows. Interior texels
// map to themselves; an edge texel mirrors the interior texel on the same edge (the octahedral
// seam folds the square's edges onto themselves reversed); a corner takes the opposite corner.
ivec2 oct_border_source(ivec2 t, int size) {
    int n = size - 2;  // interior size
    int last = size - 1;
    bool bx = t.x == 0 || t.x == last, by = t.y == 0 || t.y == last;
    if (bx && by) return ivec2(t.x == 0 ? n : 1, t.y == 0 ? n : 1);
    if (by) return ivec2(size - 1 - t.x, t.y == 0 ? 1 : n);
    if (bx) return ivec2(t.x == 0 ? 1 : n, size - 1 - t.y);
    return t;
}

// Direction of texel t of a bordered tile (its centre in the interior square).
vec3 oct_texel_dir(ivec2 t, int size) {
    ivec2 s = oct_border_source(t, size);
    vec2 e = (vec2(s - 1) + 0.5) / float(size - 2) * 2.0 - 1.0;
    return oct_decode(e);
}

// Continuous texel coordinates of dir inside a bordered tile (0 = the tile's left edge,
// interior from 1 to size-1): add the tile origin and divide by the atlas size to sample.
vec2 oct_tile_uv(vec3 dir, int size) {
    vec2 e = oct_encode(normalize(dir)) * 0.5 + 0.5;
    return vec2(1.0) + e * float(size - 2);
}

vec3 spherical_fibonacci(float i, float n) {
    const float GOLDEN = 1.61803398875;
    float phi = 6.28318530718 * fract(i * (GOLDEN - 1.0));
    float cos_t = 1.0 - (2.0 * i + 1.0) / n;
    float sin_t = sqrt(clamp(1.0 - cos_t * cos_t, 0.0, 1.0));
    return vec3(cos(phi) * sin_t, sin(phi) * sin_t, cos_t);
}

#endif
