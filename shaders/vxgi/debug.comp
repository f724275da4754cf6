// debug.comp — GI_VXGI_Voxels: the voxel radiance at mip u_mip as the camera sees it: the
// camera ray marched front to back through the cascades (steps of the mip's voxel width,
// the directional volumes facing the camera), rgb = the composited radiance (W/m^2/sr),
// a = opacity. What the cones see, without the G-buffer.
#define VX_SAMPLING
#include "lib/common.glsl"
#include "lib/sampling.glsl"
#include "vxgi/common.glsl"

layout(local_size_x = 8, local_size_y = 8) in;
layout(binding = 0, rgba32f) uniform writeonly image2D o_debug;
uniform mat4 u_inv_view_proj;
uniform vec3 u_camera_pos;
uniform int u_ortho;
uniform float u_mip;

void main() {
    ivec2 px = ivec2(gl_GlobalInvocationID.xy);
    ivec2 size = imageSize(o_debug);
    if (any(greaterThanEqual(px, size))) return;
    vec2 ndc = (vec2(px) + 0.5) / vec2(size) * 2.0 - 1.0;
    vec4 a = u_inv_view_proj * vec4(ndc, -1.0, 1.0);
    vec4 b = u_inv_view_proj * vec4(ndc, 1.0, 1.0);
    vec3 p0 = a.xyz / a.w, p1 = b.xyz / b.w;
    vec3 d = normalize(p1 - p0);
    vec3 o = u_ortho == 1 ? p0 : u_camera_pos;
    vec3 col = vec3(0.0);
    float alpha = 0.0;
    // start where the ray enters the coarsest cascade (slab test), end where it leaves it
    vec4 co = u_vx_origin[u_vx_cascades - 1];
    vec3 inv = 1.0 / (abs(d) + 1e-20) * sign(d + 1e-20);
    vec3 ta = (co.xyz - o) * inv, tb = (co.xyz + co.w * float(u_vx_n) - o) * inv;
    float tin = max(max(min(ta.x, tb.x), min(ta.y, tb.y)), min(ta.z, tb.z));
    float tout = min(min(max(ta.x, tb.x), max(ta.y, tb.y)), max(ta.z, tb.z));
    float t = max(tin, 0.0);
    float tmax = min(length(p1 - o), tout);
    for (int i = 0; i < 1024 && t < tmax && alpha < 0.995; ++i) {
        vec3 p = o + t * d;
        int c = vx_cascade_of(p, 0.0);
        float vs = c < 0 ? u_vx_origin[u_vx_cascades - 1].w : u_vx_origin[c].w;
        float diam = vs * exp2(u_mip);
        float w;
        vec4 s = vx_sample(p, diam, d, w);
        float step = 0.5 * max(w, vs);
        if (w > 0.0 && s.a > 1e-5) {
            float as = clamp(s.a, 0.0, 0.9999);
            float ac = 1.0 - pow(1.0 - as, step / w);
            col += (1.0 - alpha) * ac * s.rgb / s.a;
            alpha += (1.0 - alpha) * ac;
        }
        t += step;
    }
    imageStore(o_debug, px, vec4(sanitize(col), alpha));
}
