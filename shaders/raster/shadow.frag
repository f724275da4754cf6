// shadow.frag — stores the distance metric of a shadow view: distance to the view origin
// for perspective views, depth along the light direction for orthographic (sun) views.
in vec3 v_world;
uniform vec3 u_origin;
uniform vec3 u_dir;
uniform int u_ortho;
layout(location = 0) out float o_dist;
void main() {
    o_dist = u_ortho == 1 ? dot(v_world - u_origin, u_dir) : length(v_world - u_origin);
}
