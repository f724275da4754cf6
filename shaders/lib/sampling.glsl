// sampling.glsl — warps from [0,1)^2 to directions and shapes, with their pdfs, and MIS.
// Orthonormal basis: Duff et al. 2017, "Building an Orthonormal Basis, Revisited".
#ifndef GI_SAMPLING_GLSL
#define GI_SAMPLING_GLSL

void make_basis(vec3 n, out vec3 t, out vec3 b) {
    float s = n.z >= 0.0 ? 1.0 : -1.0;
    float a = -1.0 / (s + n.z);
    float c = n.x * n.y * a;
    t = vec3(1.0 + s * n.x * n.x * a, s * c, -s * n.x);
    b = vec3(c, s + n.y * n.y * a, -n.y);
}

vec3 to_world(vec3 v, vec3 n) {
    vec3 t, b;
    make_basis(n, t, b);
    return v.x * t + v.y * b + v.z * n;
}

vec3 to_local(vec3 v, vec3 n) {
    vec3 t, b;
    make_basis(n, t, b);
    return vec3(dot(v, t), dot(v, b), dot(v, n));
}

// Concentric disk (Shirley & Chiu 1997): uniform on the unit disk.
vec2 sample_disk(vec2 u) {
    vec2 o = 2.0 * u - 1.0;
    if (o.x == 0.0 && o.y == 0.0) return vec2(0.0);
    float r, th;
    if (abs(o.x) > abs(o.y)) { r = o.x; th = (PI / 4.0) * (o.y / o.x); }
    else { r = o.y; th = PI / 2.0 - (PI / 4.0) * (o.x / o.y); }
    return r * vec2(cos(th), sin(th));
}

// Cosine-weighted hemisphere around +Z; pdf = cos / pi.
vec3 sample_cosine_hemisphere(vec2 u) {
    vec2 d = sample_disk(u);
    return vec3(d, sqrt(max(0.0, 1.0 - dot(d, d))));
}

vec3 sample_uniform_sphere(vec2 u) {
    float z = 1.0 - 2.0 * u.x;
    float r = sqrt(max(0.0, 1.0 - z * z));
    float phi = TWO_PI * u.y;
    return vec3(r * cos(phi), r * sin(phi), z);
}

// Uniform direction in the cone of half-angle acos(cos_max) around +Z; pdf = 1/(2 pi (1 - cos_max)).
vec3 sample_cone(vec2 u, float cos_max) {
    float c = mix(1.0, cos_max, u.x);
    float s = sqrt(max(0.0, 1.0 - c * c));
    float phi = TWO_PI * u.y;
    return vec3(s * cos(phi), s * sin(phi), c);
}

float cone_pdf(float cos_max) { return 1.0 / (TWO_PI * max(1.0 - cos_max, 1e-12)); }

// Uniform barycentrics on a triangle.
vec2 sample_triangle(vec2 u) {
    float su = sqrt(u.x);
    return vec2(1.0 - su, u.y * su);
}

// MIS power heuristic (beta = 2), Veach & Guibas 1995.
float power_heuristic(float pa, float pb) {
    float a = pa * pa, b = pb * pb;
    return a + b > 0.0 ? a / (a + b) : 0.0;
}

#endif
