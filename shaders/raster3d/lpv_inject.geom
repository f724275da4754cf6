// lpv_inject.geom — routes each injected VPL point to its grid layer (gl_Layer).
layout(points) in;
layout(points, max_vertices = 1) out;
in vec4 v_r[];
in vec4 v_g[];
in vec4 v_b[];
flat in int v_layer[];
out vec4 g_r;
out vec4 g_g;
out vec4 g_b;
void main() {
    if (v_layer[0] < 0) return;
    gl_Layer = v_layer[0];
    gl_Position = gl_in[0].gl_Position;
    g_r = v_r[0];
    g_g = v_g[0];
    g_b = v_b[0];
    EmitVertex();
    EndPrimitive();
}
