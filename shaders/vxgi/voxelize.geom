// voxelize.geom — dominant-axis projection with conservative enlargement (Hasselgren et
// al. 2005, as in Crassin & Green 2012): the triangle, in voxel units of cascade
// u_cascade, is projected along the axis where its normal is largest onto the N x N
// viewport, and every edge is pushed out by (0.5 + u_thickness) pixels (the semi-diagonal
// in the edge's normal direction), so every column the triangle (thickened) touches gets a
// fragment. The fragment stage tests each voxel of the column exactly (triangle/box SAT),
// so over-enlarged slivers cost time, never correctness.
#include "lib/common.glsl"
#include "vxgi/common.glsl"

layout(triangles) in;
layout(triangle_strip, max_vertices = 3) out;

in vec3 v_world[];
in vec3 v_normal[];
in vec2 v_uv[];
in vec4 v_color[];
flat in int v_material[];

uniform int u_cascade;
uniform float u_thickness;  // extra voxels of dilation around each triangle

out vec2 g_uv;
out vec4 g_color;
out vec3 g_normal;
flat out int g_material;
flat out int g_axis;
flat out vec3 g_v0;  // triangle in voxel units of the cascade (x, y, z unpermuted)
flat out vec3 g_v1;
flat out vec3 g_v2;
flat out vec4 g_box;  // 2D bounds of the projected triangle (pixels), dilated

vec2 proj(vec3 g, int axis) { return axis == 0 ? g.yz : (axis == 1 ? g.zx : g.xy); }

void main() {
    vec4 o = u_vx_origin[u_cascade];
    vec3 gv[3];
    for (int i = 0; i < 3; ++i) gv[i] = (v_world[i] - o.xyz) / o.w;
    vec3 nrm = cross(gv[1] - gv[0], gv[2] - gv[0]);
    if (dot(nrm, nrm) < 1e-20) return;  // degenerate
    vec3 an = abs(nrm);
    int axis = (an.x >= an.y && an.x >= an.z) ? 0 : (an.y >= an.z ? 1 : 2);
    float n = float(u_vx_n);
    // reject triangles entirely outside the cascade (dilated)
    vec3 lo = min(gv[0], min(gv[1], gv[2])), hi = max(gv[0], max(gv[1], gv[2]));
    if (any(greaterThan(lo, vec3(n + 1.0 + u_thickness))) || any(lessThan(hi, vec3(-1.0 - u_thickness)))) return;
    vec2 p[3];
    int idx[3] = int[3](0, 1, 2);
    for (int i = 0; i < 3; ++i) p[i] = proj(gv[i], axis);
    float area = (p[1].x - p[0].x) * (p[2].y - p[0].y) - (p[2].x - p[0].x) * (p[1].y - p[0].y);
    if (area < 0.0) {  // make it counter-clockwise
        vec2 t = p[1]; p[1] = p[2]; p[2] = t;
        idx[1] = 2; idx[2] = 1;
    }
    float hp = 0.5 + u_thickness;
    // edge lines pushed out: n_i . x = c_i, n_i the outward unit normal of edge i (p_i -> p_i+1)
    vec2 en[3];
    float ec[3];
    for (int i = 0; i < 3; ++i) {
        vec2 e = p[(i + 1) % 3] - p[i];
        vec2 nn = normalize(vec2(e.y, -e.x));
        en[i] = nn;
        ec[i] = dot(nn, p[i]) + hp * (abs(nn.x) + abs(nn.y));
    }
    vec2 bl = min(p[0], min(p[1], p[2])) - hp, bh = max(p[0], max(p[1], p[2])) + hp;
    for (int i = 0; i < 3; ++i) {
        int a = (i + 2) % 3;  // the edge ending at vertex i, and edge i starting there
        float det = en[a].x * en[i].y - en[a].y * en[i].x;
        vec2 q;
        if (abs(det) < 1e-6) {
            q = p[i] + hp * en[i];
        } else {
            q = vec2(ec[a] * en[i].y - en[a].y * ec[i], en[a].x * ec[i] - ec[a] * en[i].x) / det;
        }
        // a sharp corner puts the mitred vertex far out (finite: det >= 1e-6); the fragment
        // stage's box test discards what lies beyond the dilated bounds
        int k = idx[i];
        gl_Position = vec4(q / n * 2.0 - 1.0, 0.5, 1.0);
        g_uv = v_uv[k];
        g_color = v_color[k];
        g_normal = v_normal[k];
        g_material = v_material[0];
        g_axis = axis;
        g_v0 = gv[0];
        g_v1 = gv[1];
        g_v2 = gv[2];
        g_box = vec4(bl, bh);
        EmitVertex();
    }
    EndPrimitive();
}
