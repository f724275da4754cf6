// lpv_inject.frag — adds a VPL's SH intensity (or a surfel's blocking) to its cell
// (additive blending).
in vec4 g_r;
in vec4 g_g;
in vec4 g_b;
layout(location = 0) out vec4 o_r;
layout(location = 1) out vec4 o_g;
layout(location = 2) out vec4 o_b;
void main() {
    o_r = g_r;
    o_g = g_g;
    o_b = g_b;
}
