// vxgi/common.glsl — the voxel grid of VXGI (addon/render/passes/vxgi.py): cascades of
// N^3 voxels centred on the camera, stacked along z in one 3D texture N x N x (N * C), and
// cone tracing through its isotropic mips (Crassin et al. 2011).
//
// Anisotropic radiance volume: six directional volumes (the light a voxel emits towards +x,
// -x, +y, -y, +z, -z), each with C cascades, stacked along z as slabs of N texels: slab
// (face * C + cascade). Texel: rgb = opacity * radiance (premultiplied, W/m^2/sr), a =
// opacity. Level 0: opacity 1 where a triangle overlaps the voxel, radiance of the surface
// side facing that direction. Mips (vxgi_mip.comp): per direction, the 2 children along
// the axis composited front to back as seen from that direction, the 4 pairs averaged
// (Crassin et al. 2011); N is divisible by 2^(u_vx_levels - 1), so a mip never mixes two
// slabs. Sampling clamps z inside the slab at the mip used.
// Requires common.glsl.
#ifndef GI_VXGI_COMMON_GLSL
#define GI_VXGI_COMMON_GLSL

#define VX_MAX_CASCADES 4
#ifndef VX_BINDING_RECORDS
#define VX_BINDING_RECORDS 5
#endif
#ifndef VX_BINDING_LIST
#define VX_BINDING_LIST 4
#endif
// the occupied voxels of this frame: [0] = count, [1 + i] = flat index (z * N * N + y * N + x,
// z counting the cascades' slabs)
// One voxel record: word 0 = mask of the orientation buckets present, then one bucket of
// VX_BUCKET words per orientation (dominant axis and sign of the mesh normal: +x, -x, +y,
// -y, +z, -z): diffuse albedo sum rgb, triangle-fragment count (uint), normal sum xyz, sum of
// the voxel centre's signed distance to the triangle's plane along its normal (voxel units).
// Separate buckets keep two surfaces of one voxel at an angle (a room's corner) or facing
// away from each other (both faces of a closed thin wall) apart: each is lit on its own.
#define VX_BUCKET 8
#define VX_REC (1 + 6 * VX_BUCKET)

int vx_bucket(vec3 n) {
    vec3 a = abs(n);
    int axis = (a.x >= a.y && a.x >= a.z) ? 0 : (a.y >= a.z ? 1 : 2);
    return 2 * axis + (n[axis] < 0.0 ? 1 : 0);
}
int vx_bucket_offset(int b) { return 1 + b * VX_BUCKET; }

uniform int u_vx_n;                          // voxels per side of one cascade
uniform int u_vx_cascades;                   // cascades (cell size doubles)
uniform int u_vx_levels;                     // mip levels usable inside a cascade
uniform int u_vx_moving_levels;              // levels read in the cascades that move (all but the coarsest)
uniform vec4 u_vx_origin[VX_MAX_CASCADES];   // xyz corner (world), w = voxel size

// Finest cascade whose box, shrunk by `margin` voxels, contains p; -1 if none.
int vx_cascade_of(vec3 p, float margin) {
    for (int c = 0; c < u_vx_cascades; ++c) {
        vec4 o = u_vx_origin[c];
        vec3 g = (p - o.xyz) / o.w;
        if (all(greaterThanEqual(g, vec3(margin))) && all(lessThanEqual(g, vec3(float(u_vx_n) - margin))))
            return c;
    }
    return -1;
}

// Voxel size at p (finest cascade holding it; the coarsest's outside every cascade).
float vx_voxel_size_at(vec3 p) {
    int c = vx_cascade_of(p, 0.0);
    return u_vx_origin[c < 0 ? u_vx_cascades - 1 : c].w;
}

#ifdef VX_SAMPLING
uniform sampler3D u_vx_radiance;
uniform float u_vx_opacity_scale;  // opacity bias (>= 1 thickens occluders, against leaks)
uniform float u_vx_box_ramp;       // width in texels of the ramp across a texel boundary (0 = a hard box, 1 = the tent)
// a face whose weight d_k^2 is below this counts less than fully in the sample's opacity
// (a cone running within ~18 degrees of a surface's plane is not stopped by it outright)
#define VX_FACE_W_FULL 0.1

// Radiance volume at p filtered over a footprint `diam` (world units), as seen by a cone
// travelling along d (the light emitted towards -d): the three directional volumes facing
// the cone, weighted by d^2. Cascade: the finest containing p whose voxels are at most
// `diam` (mip = log2(diam / voxel)). Returns the premultiplied sample; `width` = the filter
// width used (opacity correction), 0 when p is outside every cascade.
// Radiance: the d^2-weighted faces un-premultiplied (sum w rgb / sum w a: a wall crossed at
// any angle shows its facing side's radiance, undiluted by the faces it is edge-on to).
// Opacity: the LARGEST of the three faces' opacities (a face weighted below VX_FACE_W_FULL
// counts proportionally less), not their d^2 mean: a plane is opaque to any ray crossing it,
// and the mean (cos^2 of the angle to the wall's normal per sample; the samples inside one
// wall layer are perfectly correlated, not independent) let oblique cones through walls.
// Energy audit (closed box, q0): the mean lost 13 % more of E than the max (0.73 -> 0.85).
// Each face is read at its mip's texel centre along the face's own axis (linear across it),
// the two mips of a fractional lod each at its own centre and blended. Along the direction a
// cone crosses a face the opacity is then a box of the texel's width, which is what the step
// correction 1 - (1-a)^(s/w) assumes: a trilinear tent of a one-voxel wall (opacity 1 at one
// point only) let e^-2 ~ 14 % of a cone through it, more or less depending on where the wall
// lay in the texel and on the sample phase. The box's edges are linear ramps u_vx_box_ramp
// (param box_ramp) texels wide, so the value is continuous in the sample's position; the hard
// box (0) jumps when a sample crosses a texel boundary as the receiver moves (q1 60 frames:
// largest step 1.37x -> 1.30x Cycles', mean 0.95x -> 0.88x at 0.5).
// The radiance weights each face by d^2 x its opacity (sum w a^2 L / sum w a^2, L = rgb / a),
// so the faces that occlude the sample show it; by d^2 alone, the black edge-on faces of a
// wall crossed obliquely (opacity edge_opacity) dimmed its radiance to cos^2/(cos^2 + 0.1 sin^2)
// (0.77 L at 60 degrees).
vec4 vx_sample(vec3 p, float diam, vec3 d, out float width) {
    width = 0.0;
    float n = float(u_vx_n);
    float max_lod = float(u_vx_levels - 1);
    float slabs = float(6 * u_vx_cascades);
    for (int c = 0; c < u_vx_cascades; ++c) {
        vec4 o = u_vx_origin[c];
        float lod = log2(max(diam / o.w, 1.0));
        // a cascade that follows the camera is read only at the mips its snap keeps in place;
        // wider footprints go to the next cascade (its mip one level down)
        float top = c < u_vx_cascades - 1 ? float(min(u_vx_levels, u_vx_moving_levels) - 1) : max_lod;
        if (lod > top && c < u_vx_cascades - 1) continue;  // a coarser cascade filters wider
        lod = min(lod, top);
        vec3 l = (p - o.xyz) / (o.w * n);
        if (any(lessThan(l, vec3(0.0))) || any(greaterThan(l, vec3(1.0)))) continue;
        float h = 0.5 * exp2(ceil(lod)) / n;  // half a texel of the coarser of the two mips
        l.z = clamp(l.z, h, 1.0 - h);
        width = o.w * exp2(lod);
        vec3 w = d * d;
        // face f holds the light emitted towards +axis (f even) or -axis (f odd)
        ivec3 f = ivec3(d.x > 0.0 ? 1 : 0, d.y > 0.0 ? 3 : 2, d.z > 0.0 ? 5 : 4);
        vec4 r = vec4(0.0);
        float amax = 0.0;
        float lo = floor(lod), fr = lod - lo;
        for (int k = 0; k < 3; ++k) {
            if (w[k] < 1e-4) continue;
            float slab = float(f[k] * u_vx_cascades + c);
            // box along the face's own axis: each of the two mips is read at its own texel
            // centre along axis k (linear across it), blended by the lod's fraction
            vec4 t = vec4(0.0);
            for (int j = 0; j < 2; ++j) {
                float lj = lo + float(j);
                float wj = j == 0 ? 1.0 - fr : fr;
                if (wj <= 0.0) continue;
                float m = n / exp2(lj);  // texels per side at this mip
                vec3 lk = l;
                // box with linear edges: flat over the texel's middle, a ramp u_vx_box_ramp
                // texels wide across each texel boundary (continuous in the sample's position);
                // 0: the hard box, the texel holding the sample (a sample on a boundary reads
                // the upper one)
                float x = l[k] * m - 0.5, i = floor(x);
                float e = u_vx_box_ramp > 0.0 ? clamp((x - i - 0.5) / u_vx_box_ramp + 0.5, 0.0, 1.0)
                                              : step(0.5, x - i);
                lk[k] = clamp((i + e + 0.5) / m, 0.5 / m, 1.0 - 0.5 / m);
                t += wj * finite_or_zero(textureLod(u_vx_radiance, vec3(lk.xy, (slab + lk.z) / slabs), lj));
            }
            r += w[k] * t.a * t;
            amax = max(amax, t.a * min(1.0, w[k] / VX_FACE_W_FULL));
        }
        if (r.a > 1e-6) r = vec4(r.rgb / r.a, 1.0) * amax;
        return r;
    }
    return vec4(0.0);
}

// Front-to-back cone march from o along unit d with tan(half aperture) `tan_half`, from t0
// to at most t1. Steps of `step_scale` x the cone diameter (at least the local voxel size
// times step_scale); each sample's opacity is biased by u_vx_opacity_scale and corrected
// for the step length (1 - (1-a)^(s/w)). Returns (radiance arriving along the cone, opacity).
// vx_cone_h: the same with the footprint capped for a cone leaving a receiver's plane: the
// diameter at t stays <= u_vx_cap x the sample's height over that plane, h0 + t cosn (h0:
// the start's height, cosn: d . n). A 30-degree cone at 60 degrees from the normal grazes the
// plane; uncapped, its coarse mips reach back over the receiver's own voxel layer and read
// that surface's far side (the sun-lit outside of a roof under it, the lit side of a wall).
// Trilinear filtering of a mip texel as wide as the footprint is a tent of half-width diam,
// so cap 1 still reached the plane itself; 0.35 keeps the tent above the receiver's own
// layer (the default, sunlit_room q0 relMSE 0.18 at 0.5 -> 0.12 at 0.35 with edge opacity 0).
uniform float u_vx_cap;  // 0: off
vec4 vx_cone_h(vec3 o, vec3 d, float tan_half, float t0, float t1, float step_scale, float h0, float cosn) {
    vec3 col = vec3(0.0);
    float a = 0.0;
    float t = t0;
    for (int i = 0; i < 256 && t < t1 && a < 0.995; ++i) {
        vec3 p = o + t * d;
        float vs = vx_voxel_size_at(p);
        float diam = 2.0 * tan_half * t;
        if (u_vx_cap > 0.0) diam = min(diam, u_vx_cap * (h0 + t * cosn));
        diam = max(diam, vs);
        float w;
        vec4 s = vx_sample(p, diam, d, w);
        if (w <= 0.0) break;  // left every cascade
        float step = diam * step_scale;
        if (s.a > 1e-5) {
            float as = clamp(s.a * u_vx_opacity_scale, 0.0, 0.9999);
            float ac = 1.0 - pow(1.0 - as, min(step / w, 4.0));
            vec3 L = s.rgb / s.a;  // the sample's radiance (un-premultiplied)
            col += (1.0 - a) * ac * L;
            a += (1.0 - a) * ac;
        }
        t += step;
    }
    return vec4(col, a);
}
vec4 vx_cone(vec3 o, vec3 d, float tan_half, float t0, float t1, float step_scale) {
    return vx_cone_h(o, d, tan_half, t0, t1, step_scale, 1e9, 0.0);
}

// Six cones around n: one along n and five at u_vx_side_angle from it, aperture tan(30 deg)
// (Crassin; Godot's layout at 60 degrees: weights pi/4 and 3 pi/20). The weights are each
// cone's cosine-weighted solid angle, Omega cos(theta), scaled so that they sum to pi: a
// uniform radiance L gives E = pi L. `world` (0 or 1): add the world's radiance
// for the part of each cone that escapes (1 - opacity), looked up along the cone in the
// world map prefiltered to the cone's width (vx_sky); `bounce` scales what the cones gather
// from the voxels (0: world light only). Returns E; `vis` = the cosine-weighted unoccluded
// fraction.
uniform float u_vx_side_angle;  // radians
#ifdef GI_WORLD_GLSL
// The world seen through a cone of half-angle 30 degrees (tan = 0.577): the map's mip whose
// texels span about that angle (lib/world.glsl world_glossy; a uniform world is its colour).
vec3 vx_sky(vec3 d) { return world_glossy(d, 0.52); }
#else
vec3 vx_sky(vec3 d) { return vec3(0.0); }
#endif
vec3 vx_diffuse_cones(vec3 o, vec3 n, float t0, float t1, float step_scale, float world,
                      float bounce, out float vis, float h0) {
    vec3 t, b;
    make_basis(n, t, b);
    const float TAN30 = 0.57735;
    float ct = cos(u_vx_side_angle), st = sin(u_vx_side_angle);
    float w0 = PI / (1.0 + 5.0 * ct);  // cone weights proportional to cos(theta), sum pi
    vec3 E = vec3(0.0);
    float occ = 0.0;
    for (int k = 0; k < 6; ++k) {
        vec3 d;
        float w;
        if (k == 0) {
            d = n;
            w = w0;
        } else {
            float phi = TWO_PI * float(k - 1) / 5.0;
            d = normalize(ct * n + st * (cos(phi) * t + sin(phi) * b));
            w = w0 * ct;
        }
        vec4 c = vx_cone_h(o, d, TAN30, t0, t1, step_scale, h0, dot(d, n));
        E += w * (bounce * c.rgb + (world > 0.0 ? (1.0 - c.a) * vx_sky(d) : vec3(0.0)));
        occ += w * c.a;
    }
    vis = clamp(1.0 - occ / PI, 0.0, 1.0);
    return E;
}
#endif

#endif
