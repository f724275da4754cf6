// hiz.comp — hierarchical depth (Hi-Z) pyramid for screen-space ray marching.
// Paper: Uludag 2014 ("Hi-Z screen-space cone-traced reflections", GPU Pro 5); used by the
// SSR tracer after McGuire & Mara 2014.
// Level 0: the nearest device depth z_ndc (the frame's jittered view-projection; linear in
// screen space, so a projected ray interpolates it exactly; background = 2, beyond the far
// plane) over the pixel's footprint: the G-buffer position's plane (geometric normal)
// evaluated at the pixel's corners, z_c - (|dz/dx| + |dz/dy|) / 2. Storing the centre's
// depth alone was not conservative: on a wall or floor seen at a grazing angle the depth
// changes a lot within one pixel, a ray could pass a coarse cell "in front of" every
// centre while crossing the surface, and arrive at level 0 far behind it (a miss: the
// speckles and bands in reflections of walls). Level L: the minimum (nearest) of the 2x2 texels
// of level L-1, plus the third row/column when the finer level has an odd size, so every
// fine texel is covered by the coarse texel that contains it.
#include "lib/common.glsl"
#include "lib/screen.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
#ifdef HIZ_INIT
layout(binding = 1, r32f) uniform writeonly image2D o_dst;
uniform sampler2D u_gb_position;
uniform sampler2D u_gb_geonormal;

vec3 to_screen(vec3 P) {
    vec4 c = to_clip(P);
    return vec3((c.xy / c.w * 0.5 + 0.5) * u_resolution, c.z / c.w);
}

void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (any(greaterThanEqual(p, imageSize(o_dst)))) return;
    vec4 pos = texelFetch(u_gb_position, p, 0);
    float z = 2.0;
    if (pos.w >= 0.0) {
        vec4 c = to_clip(pos.xyz);
        z = c.w > 1e-7 ? clamp(c.z / c.w, -1.0, 1.0) : -1.0;
        if (c.w > 1e-7) {
            // the plane's depth gradient in screen space, from two tangent directions
            vec3 Ng = normalize(texelFetch(u_gb_geonormal, p, 0).xyz + vec3(0.0, 0.0, 1e-12));
            vec3 T1 = normalize(abs(Ng.z) < 0.9 ? cross(Ng, vec3(0.0, 0.0, 1.0)) : cross(Ng, vec3(1.0, 0.0, 0.0)));
            vec3 T2 = cross(Ng, T1);
            float eps = 1e-3 * max(c.w, 1e-3);
            vec3 s0 = to_screen(pos.xyz);
            vec3 a = to_screen(pos.xyz + T1 * eps) - s0;
            vec3 b = to_screen(pos.xyz + T2 * eps) - s0;
            float det = a.x * b.y - a.y * b.x;
            float dz = 1.0;    // edge-on plane: fully conservative
            if (abs(det) > 1e-12) {
                float gx = (a.z * b.y - b.z * a.y) / det;   // dz/dx
                float gy = (a.x * b.z - b.x * a.z) / det;   // dz/dy
                dz = 0.5 * (abs(gx) + abs(gy));
            }
            z = clamp(z - dz, -1.0, z);
        }
    }
    imageStore(o_dst, p, vec4(z));
}
#else
layout(binding = 0, r32f) uniform readonly image2D i_src;
layout(binding = 1, r32f) uniform writeonly image2D o_dst;
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    ivec2 dsize = imageSize(o_dst);
    if (any(greaterThanEqual(p, dsize))) return;
    ivec2 ssize = imageSize(i_src);
    ivec2 lo = 2 * p;
    ivec2 hi = min(2 * p + 1, ssize - 1);
    if (p.x == dsize.x - 1) hi.x = ssize.x - 1;   // odd sizes: the last texel takes the rest
    if (p.y == dsize.y - 1) hi.y = ssize.y - 1;
    float z = 3.0;
    for (int y = lo.y; y <= hi.y; ++y)
        for (int x = lo.x; x <= hi.x; ++x)
            z = min(z, imageLoad(i_src, ivec2(x, y)).r);
    imageStore(o_dst, p, vec4(z));
}
#endif
