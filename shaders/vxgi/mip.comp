// mip.comp — one level of the anisotropic mips (Crassin et al. 2011): for each directional
// volume (light emitted towards +x, -x, ...), the two children along that axis are
// composited front to back as a viewer on that side sees them (near over far), and the
// four pairs are averaged. A one-voxel wall therefore stays opaque along its normal at
// every level (an isotropic average would halve it per level: the thin-wall leak).
layout(local_size_x = 4, local_size_y = 4, local_size_z = 4) in;
layout(binding = 0, rgba16f) uniform writeonly image3D o_dst;  // level k + 1
layout(binding = 1, rgba16f) uniform readonly image3D i_src;   // level k

uniform int u_n_dst;      // voxels per side of one slab at level k + 1
uniform int u_cascades;

vec4 over(vec4 near, vec4 far) { return vec4(near.rgb + (1.0 - near.a) * far.rgb, near.a + (1.0 - near.a) * far.a); }

void main() {
    ivec3 gid = ivec3(gl_GlobalInvocationID);
    int n = u_n_dst;
    if (gid.x >= n || gid.y >= n || gid.z >= n * 6 * u_cascades) return;
    int slab = gid.z / n;
    int face = slab / u_cascades;
    int axis = face / 2;
    bool towards_plus = (face & 1) == 0;  // the viewer is on the + side: the near child is the upper one
    ivec3 v = ivec3(gid.xy, gid.z - slab * n);
    ivec3 src0 = 2 * v;
    int zoff = slab * 2 * n;
    vec4 sum = vec4(0.0);
    for (int a = 0; a < 2; ++a) {
        for (int b = 0; b < 2; ++b) {
            ivec3 lo, hi;
            if (axis == 0) { lo = ivec3(0, a, b); hi = ivec3(1, a, b); }
            else if (axis == 1) { lo = ivec3(a, 0, b); hi = ivec3(a, 1, b); }
            else { lo = ivec3(a, b, 0); hi = ivec3(a, b, 1); }
            ivec3 pl = src0 + lo, ph = src0 + hi;
            vec4 cl = imageLoad(i_src, ivec3(pl.xy, pl.z + zoff));
            vec4 ch = imageLoad(i_src, ivec3(ph.xy, ph.z + zoff));
            sum += towards_plus ? over(ch, cl) : over(cl, ch);
        }
    }
    imageStore(o_dst, gid, 0.25 * sum);
}
