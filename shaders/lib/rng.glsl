// rng.glsl — stateless hashing random numbers (PCG, Jarzynski & Olano 2020,
// "Hash Functions for GPU Rendering"). Seeds from pixel, sample index and a stream id.
#ifndef GI_RNG_GLSL
#define GI_RNG_GLSL

uvec4 pcg4d(uvec4 v) {
    v = v * 1664525u + 1013904223u;
    v.x += v.y * v.w; v.y += v.z * v.x; v.z += v.x * v.y; v.w += v.y * v.z;
    v ^= v >> 16u;
    v.x += v.y * v.w; v.y += v.z * v.x; v.z += v.x * v.y; v.w += v.y * v.z;
    return v;
}

struct Rng { uvec4 state; };

Rng rng_init(uvec2 pixel, uint sample_index, uint stream) {
    Rng r;
    r.state = uvec4(pixel, sample_index, stream);
    return r;
}

// Four uniform floats in [0, 1).
vec4 rng_next4(inout Rng r) {
    r.state.w += 0x9E3779B9u;
    uvec4 h = pcg4d(r.state);
    r.state = h ^ uvec4(0x85EBCA6Bu, 0xC2B2AE35u, 0x27D4EB2Fu, 0x165667B1u) ^ r.state.wxyz;
    return vec4(h >> 8u) * (1.0 / 16777216.0);
}

vec2 rng_next2(inout Rng r) { return rng_next4(r).xy; }
float rng_next(inout Rng r) { return rng_next4(r).x; }

// Halton(2,3) point i in [0,1)^2 (radical inverses; base 2 by bit reversal): a low-discrepancy
// sequence (any 2^k consecutive indices fill every 1/2^k strip in x once, 3^k in y).
vec2 halton23(uint i) {
    float h2 = float(bitfieldReverse(i) >> 8u) * (1.0 / 16777216.0);
    float h3 = 0.0, f = 1.0 / 3.0;
    for (uint n = i; n > 0u; n /= 3u) { h3 += f * float(n % 3u); f /= 3.0; }
    return vec2(h2, h3);
}

#endif
