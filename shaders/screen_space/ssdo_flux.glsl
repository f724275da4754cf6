// ssdo_flux.glsl — what ssdo_flux.comp (which builds SSDO's sender-flux pyramid) and ssdo.comp
// (which picks senders from it and weights them by MIS) must compute alike. Include after
// lib/screen.glsl and screen_space/common.glsl.
// The pyramid's level 0 is at the SSDO pass's own resolution (u_scale of the frame: q0 runs at
// half resolution): texel t holds the flux of a block of full-resolution G-buffer pixels, those
// hp with hp * osize / res == t (integer division; 1 pixel at full resolution, 2x2 at half), and
// the block's pixel count. A sender is picked in two steps: a block in proportion to its flux,
// then one of its pixels uniformly, so the area-measure pdf of sender pixel hp is
// (flux_t / total) / (count_t * area(hp)) (sender_pdf in ssdo.comp).
#ifndef GI_SSDO_FLUX_GLSL
#define GI_SSDO_FLUX_GLSL

// world area a G-buffer pixel covers (its footprint / cos, the 1/cos capped at 20)
float sender_area(vec3 P, vec3 N) {
    float foot = 1.0 / pixels_per_unit(view_depth(P));
    return foot * foot / max(abs(dot(N, view_dir(P))), 0.05);
}

// the pyramid texel (block) of full-resolution pixel hp, the pass being osize
ivec2 flux_block(ivec2 hp, ivec2 osize) {
    return hp * osize / ivec2(u_resolution);
}

// the full-resolution pixels [lo, hi) of block t
void flux_block_range(ivec2 t, ivec2 osize, out ivec2 lo, out ivec2 hi) {
    ivec2 res = ivec2(u_resolution);
    lo = (t * res + osize - 1) / osize;
    hi = min(((t + 1) * res + osize - 1) / osize, res);
}

#endif
