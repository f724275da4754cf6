// screen.glsl — screen-space helpers shared by the screen-space family (and any pass that
// works from the G-buffer): projecting world points to pixels, linear view depth,
// perspective-correct interpolation along a projected segment, and G-buffer fetches.
// Requires common.glsl. Uniforms: u_view_proj (the frame's jittered view-projection, the
// one the G-buffer was rasterised with), u_camera_pos, u_camera_fwd, u_ortho, u_resolution.
#ifndef GI_SCREEN_GLSL
#define GI_SCREEN_GLSL

uniform mat4 u_view_proj;
uniform vec3 u_camera_pos;
uniform vec3 u_camera_fwd;
uniform int u_ortho;
uniform vec2 u_resolution;   // full-resolution G-buffer size in pixels

// Distance along the view axis (what "depth" means in every screen-space test).
float view_depth(vec3 P) { return dot(P - u_camera_pos, u_camera_fwd); }

// Unit vector from P towards the eye.
vec3 view_dir(vec3 P) { return u_ortho == 1 ? -u_camera_fwd : normalize(u_camera_pos - P); }

// World point -> clip space.
vec4 to_clip(vec3 P) { return u_view_proj * vec4(P, 1.0); }

// World point -> pixel coordinates (continuous, pixel centres at +0.5); w <= 0 gives -1e9.
vec2 to_pixel(vec3 P) {
    vec4 c = to_clip(P);
    if (c.w <= 1e-7) return vec2(-1e9);
    return (c.xy / c.w * 0.5 + 0.5) * u_resolution;
}

bool on_screen(vec2 pix) {
    return all(greaterThanEqual(pix, vec2(0.0))) && all(lessThan(pix, u_resolution));
}

// How many pixels a world-space length covers at view depth d (for radius -> pixels).
float pixels_per_unit(float d) {
    // u_view_proj[1][1] is the y focal scale for perspective (and 1/half-height for ortho)
    float f = length(vec3(u_view_proj[0][1], u_view_proj[1][1], u_view_proj[2][1]));
    return 0.5 * u_resolution.y * f / (u_ortho == 1 ? 1.0 : max(d, 1e-4));
}

// Smooth fade to 0 within `margin` (fraction of the screen) of the border.
float edge_fade(vec2 pix, float margin) {
    vec2 uv = pix / u_resolution;
    vec2 d = min(uv, 1.0 - uv);
    float m = max(margin, 1e-4);
    return clamp(min(d.x, d.y) / m, 0.0, 1.0);
}

#endif
