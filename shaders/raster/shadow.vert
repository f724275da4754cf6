// shadow.vert — renders scene depth into one view (tile) of the shadow atlas.
in vec3 in_position;
uniform mat4 u_model;
uniform mat4 u_view_proj;
out vec3 v_world;
void main() {
    vec4 w = u_model * vec4(in_position, 1.0);
    v_world = w.xyz;
    gl_Position = u_view_proj * w;
}
