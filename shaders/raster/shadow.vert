// shadow.vert — renders scene depth into one view (tile) of the shadow atlas.
in vec3 in_position;
in vec2 in_uv;
in float in_material;
uniform mat4 u_model;
uniform mat4 u_view_proj;
out vec3 v_world;
out vec2 v_uv;
flat out int v_material;
void main() {
    vec4 w = u_model * vec4(in_position, 1.0);
    v_world = w.xyz;
    v_uv = in_uv;
    v_material = int(in_material + 0.5);
    gl_Position = u_view_proj * w;
}
