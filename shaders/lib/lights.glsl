// lights.glsl — the one light model, in Cycles' units, shared by every technique. A light
// type is defined here and nowhere else: techniques ask these functions, never the type.
// Requires common.glsl (Light, Emitter; USE_SCENE_BUFFERS for mesh lights) and sampling.glsl.
//
// Light types (common.glsl LIGHT_*): point and spot (intensity I, W/sr; a radius makes a
// sphere of radiance I / (pi r^2)), sun (irradiance E at normal incidence; an angle makes a
// disk of radiance E / (pi sin^2 a)), area (radiance Le, one-sided rectangle/disk/ellipse)
// and mesh (emissive triangles, two-sided, picked by power).
//
//   light_is_delta(L)                 point/spot without radius, sun without angle
//   light_has_shape(L)                a BSDF ray can hit it analytically (area, sphere, sun disk)
//   light_intensity(L, w)             point/spot/area seen from afar: intensity towards w (RSM)
//   light_irradiance(L, p, n, K, rng) unshadowed irradiance on a surface facing n: exact for
//                                     point/spot/sun (cosine law; exact above the horizon for
//                                     spheres), area (polygon) and meshes of <= K triangles;
//                                     8 power samples of triangles for larger meshes
//   sample_light(L, p, u2, u3)        one direction towards L, with its solid-angle pdf and the
//                                     point it lands on (LightSample.y, .ny, .Le)
//   light_sample_pdf(L, p, y, ny)     sample_light's pdf of the direction towards y
//   light_eval_point(L, p, y, ny, ..) a known point y of L seen from p: direction, distance,
//                                     geometry factor G and the spot falloff (ReSTIR's reuse)
//   light_shape_point(L, y, ny, Le)   normal and radiance at a point y of an area/sphere shape
//   light_ray_distance(L, o, d)       where a ray meets an area/sphere light (-1: never)
//   light_ray_hit(L, o, d, ..)        radiance and pdf a BSDF ray sees (MIS)
//   pick_emitter / emitter_probability   a mesh light's triangle by power
//   LIGHT_CDF_SEARCH(CDF, N, U, OUT)  the binary search over a power table, used by the
//                                     selection of lib/light_select.glsl, by pick_emitter and
//                                     by VXGI's per-voxel selection
// Many-light selection (which light, with what probability) is lib/light_select.glsl.
#ifndef GI_LIGHTS_GLSL
#define GI_LIGHTS_GLSL

// Cycles: attenuation = smoothstep((cos - cos_half) * smooth), ray in light space.
float spot_attenuation(Light L, vec3 ray_from_light) {
    vec3 local = normalize(vec3(dot(L.axis_u.xyz, ray_from_light), dot(L.axis_v.xyz, ray_from_light),
                                dot(L.axis_w.xyz, ray_from_light)));
    float c = -local.z;  // lights shine along local -Z
    float t = clamp((c - L.axis_u.w) * L.axis_v.w, 0.0, 1.0);
    return t * t * (3.0 - 2.0 * t);
}

bool light_is_sphere(Light L) {
    int type = int(L.pos_type.w + 0.5);
    return (type == LIGHT_POINT || type == LIGHT_SPOT) && L.dir_radius.w > 0.0;
}

// Delta lights (a point without radius, a sun without angle) light from one direction: no
// shape to hit, no pdf to weigh against (sample_light's pdf is 1).
bool light_is_delta(Light L) {
    int type = int(L.pos_type.w + 0.5);
    if (type == LIGHT_POINT || type == LIGHT_SPOT) return L.dir_radius.w <= 0.0;
    return type == LIGHT_SUN && L.dir_radius.w <= 1e-6;
}

// Can a ray hit the light (light_ray_hit: area lights, spheres, sun disks)? Mesh lights are
// surfaces, found by tracing the scene; delta lights are never hit.
bool light_has_shape(Light L) {
    return !light_is_delta(L) && int(L.pos_type.w + 0.5) != LIGHT_MESH;
}

// Radiant intensity (W/sr) of a point, spot or area light towards the unit direction w from
// its centre: I (spots: times the cone), an area light L_e A max(0, cos) (its far field).
vec3 light_intensity(Light L, vec3 w) {
    int type = int(L.pos_type.w + 0.5);
    if (type == LIGHT_AREA) return L.color.rgb * L.axis_v.w * max(dot(w, L.dir_radius.xyz), 0.0);
    vec3 I = L.color.rgb;
    if (type == LIGHT_SPOT) I *= spot_attenuation(L, w);
    return I;
}

// Point on the area light's shape for u in [0,1)^2 (world space).
vec3 area_light_point(Light L, vec2 u) {
    int shape = int(L.axis_u.w + 0.5);
    vec2 q = (shape == SHAPE_DISK || shape == SHAPE_ELLIPSE) ? sample_disk(u) : 2.0 * u - 1.0;
    return L.pos_type.xyz + q.x * L.axis_u.xyz + q.y * L.axis_v.xyz;
}

// Does the ray hit the area light's front (emitting) face? Returns distance or -1.
float intersect_area_light(Light L, vec3 o, vec3 d) {
    vec3 n = L.dir_radius.xyz;  // emission direction
    float dn = dot(d, n);
    if (dn >= 0.0) return -1.0;  // must travel against the emission direction to see the front
    float t = dot(L.pos_type.xyz - o, n) / dn;
    if (t <= 0.0) return -1.0;
    vec3 q = o + t * d - L.pos_type.xyz;
    vec3 u = L.axis_u.xyz, v = L.axis_v.xyz;
    float a = dot(q, u) / dot(u, u);
    float b = dot(q, v) / dot(v, v);
    int shape = int(L.axis_u.w + 0.5);
    bool inside = (shape == SHAPE_DISK || shape == SHAPE_ELLIPSE) ? (a * a + b * b <= 1.0)
                                                                 : (abs(a) <= 1.0 && abs(b) <= 1.0);
    return inside ? t : -1.0;
}

// Ray-sphere: distance to the first hit or -1.
float intersect_sphere(vec3 c, float r, vec3 o, vec3 d) {
    vec3 oc = o - c;
    float b = dot(oc, d);
    float cc = dot(oc, oc) - r * r;
    float disc = b * b - cc;
    if (disc < 0.0) return -1.0;
    float s = sqrt(disc);
    float t = -b - s;
    if (t > 0.0) return t;
    t = -b + s;
    return t > 0.0 ? t : -1.0;
}

// ---- Polygon irradiance (Lambert 1760; Arvo 1995): E = L/2 * sum theta_i (n . gamma_i).
// Vertices are relative to the shading point. The polygon is clipped to the upper
// hemisphere of n. Returns the (signed) form-factor integral sum / 2, i.e. E / L.
#define MAX_POLY 20
float polygon_irradiance_factor(vec3 verts[MAX_POLY], int count, vec3 n) {
    // Sutherland-Hodgman clip against the plane dot(n, x) >= 0.
    vec3 clipped[MAX_POLY];
    int m = 0;
    for (int i = 0; i < count; ++i) {
        vec3 a = verts[i];
        vec3 b = verts[(i + 1) % count];
        float da = dot(n, a), db = dot(n, b);
        if (da >= 0.0 && m < MAX_POLY) clipped[m++] = a;
        if ((da >= 0.0) != (db >= 0.0) && m < MAX_POLY) {
            float t = da / (da - db);
            clipped[m++] = a + t * (b - a);
        }
    }
    if (m < 3) return 0.0;
    float sum = 0.0;
    for (int i = 0; i < m; ++i) {
        vec3 a = normalize(clipped[i]);
        vec3 b = normalize(clipped[(i + 1) % m]);
        float c = clamp(dot(a, b), -1.0, 1.0);
        vec3 cr = cross(a, b);
        float len = length(cr);
        if (len < 1e-9) continue;
        float theta = acos(c);
        sum += theta * dot(n, cr) / len;
    }
    return 0.5 * sum;
}

// Irradiance factor (E / Le) of an area light at p with normal n; 0 behind the light.
float area_light_irradiance_factor(Light L, vec3 p, vec3 n) {
    vec3 c = L.pos_type.xyz - p;
    if (dot(-c, L.dir_radius.xyz) <= 0.0) return 0.0;  // p is behind the emitting face
    vec3 u = L.axis_u.xyz, v = L.axis_v.xyz;
    int shape = int(L.axis_u.w + 0.5);
    vec3 verts[MAX_POLY];
    int count;
    if (shape == SHAPE_DISK || shape == SHAPE_ELLIPSE) {
        // a 16-gon with the ellipse's area (circumradius scaled so the areas match)
        const int N = 16;
        float k = sqrt(PI / (0.5 * float(N) * sin(TWO_PI / float(N))));
        for (int i = 0; i < N; ++i) {
            float a = TWO_PI * float(i) / float(N);
            verts[i] = c + k * (cos(a) * u + sin(a) * v);
        }
        count = N;
    } else {
        verts[0] = c - u - v; verts[1] = c + u - v; verts[2] = c + u + v; verts[3] = c - u + v;
        count = 4;
    }
    return abs(polygon_irradiance_factor(verts, count, n));
}

// Irradiance factor of one emissive triangle (two-sided emitter). A point in the triangle's
// own plane (a point of the emitting surface itself, or of a coplanar neighbour) sees it
// edge-on: 0. Without this test the clipped polygon lies in the horizon plane and the formula
// returns the in-plane angle it subtends (the whole hemisphere, pi, for a point inside it):
// an emissive wall lit itself with its own full radiance.
float triangle_irradiance_factor(vec3 a, vec3 b, vec3 c, vec3 p, vec3 n) {
    vec3 ng = cross(b - a, c - a);
    float area2 = length(ng);
    if (abs(dot(p - a, ng)) <= 1e-4 * area2 * sqrt(area2) + 1e-12) return 0.0;
    vec3 verts[MAX_POLY];
    verts[0] = a - p; verts[1] = b - p; verts[2] = c - p;
    return abs(polygon_irradiance_factor(verts, 3, n));
}

// Solid-angle pdf of sampling point q uniformly on an area A seen from p with light normal ln.
float area_to_solid_angle_pdf(vec3 p, vec3 q, vec3 ln, float area) {
    vec3 d = q - p;
    float dist2 = dot(d, d);
    float cosl = abs(dot(ln, d)) * inversesqrt(max(dist2, 1e-20));
    return cosl > 1e-8 ? dist2 / (cosl * area) : 0.0;
}

// Where a ray leaving o along d meets an area light's front face or a sphere light seen from
// outside (the nearest hit), else -1.
float light_ray_distance(Light L, vec3 o, vec3 d) {
    int type = int(L.pos_type.w + 0.5);
    if (type == LIGHT_AREA) return intersect_area_light(L, o, d);
    if (!light_is_sphere(L)) return -1.0;
    vec3 toc = L.pos_type.xyz - o;
    float r = L.dir_radius.w;
    return dot(toc, toc) > r * r ? intersect_sphere(L.pos_type.xyz, r, o, d) : -1.0;
}

// Normal ny and radiance Le (without a spot's cone) at a point y of an area or sphere light.
void light_shape_point(Light L, vec3 y, out vec3 ny, out vec3 Le) {
    if (int(L.pos_type.w + 0.5) == LIGHT_AREA) {
        ny = L.dir_radius.xyz;
        Le = L.color.rgb;
        return;
    }
    float r = L.dir_radius.w;
    ny = normalize(y - L.pos_type.xyz);
    Le = L.color.rgb / (PI * r * r);  // sphere radiance = I / (pi r^2)
}

// A sample on light L in the light's own frame (light_to_local) and back in world space
// (light_from_local, with the light's normal and radiance there as they are now): what a
// sample keeps from frame to frame so that it follows the light when the light moves, turns,
// scales or changes colour. Delta points and suns without size keep nothing (their one point
// or direction); sphere lights keep the unit offset from the centre; area lights the point's
// coordinates along the two half-extent axes; sun disks the direction in the sun's frame.
// Mesh lights are not handled here: their points live on the instance's triangles.
vec3 light_to_local(Light L, vec3 y) {
    int type = int(L.pos_type.w + 0.5);
    if (light_is_delta(L)) return vec3(0.0);
    if (type == LIGHT_SUN) return to_local(y, -L.dir_radius.xyz);
    if (type == LIGHT_AREA) {
        vec3 d = y - L.pos_type.xyz;
        return vec3(dot(d, L.axis_u.xyz) / max(dot(L.axis_u.xyz, L.axis_u.xyz), 1e-30),
                    dot(d, L.axis_v.xyz) / max(dot(L.axis_v.xyz, L.axis_v.xyz), 1e-30), 0.0);
    }
    return (y - L.pos_type.xyz) / max(L.dir_radius.w, 1e-30);  // sphere
}

void light_from_local(Light L, vec3 local, out vec3 y, out vec3 ny, out vec3 Le) {
    int type = int(L.pos_type.w + 0.5);
    ny = vec3(0.0, 0.0, 1.0);
    if (type == LIGHT_SUN) {
        float a = L.dir_radius.w;
        bool delta = a <= 1e-6;
        y = delta ? -L.dir_radius.xyz : normalize(to_world(local, -L.dir_radius.xyz));
        Le = delta ? L.color.rgb : L.color.rgb / (PI * sin(a) * sin(a));
        return;
    }
    if (light_is_delta(L)) {  // point, spot without size: the intensity, as sample_light gives it
        y = L.pos_type.xyz;
        Le = L.color.rgb;
        return;
    }
    if (type == LIGHT_AREA) y = L.pos_type.xyz + local.x * L.axis_u.xyz + local.y * L.axis_v.xyz;
    else y = L.pos_type.xyz + L.dir_radius.w * normalize(local);
    light_shape_point(L, y, ny, Le);
}

// |d y_now / d y_then| for one light-relative sample: how the light's measure changed between two
// states of the light (area: area; sphere: r^2; sun disk: the disk's solid angle; else 1). A
// contribution weight made for the light as it was is multiplied by it to serve the light as
// it is.
float light_local_jacobian(Light now, Light then) {
    int type = int(now.pos_type.w + 0.5);
    if (type != int(then.pos_type.w + 0.5) || light_is_delta(now) || light_is_delta(then)) return 1.0;
    if (type == LIGHT_AREA) return now.axis_v.w / max(then.axis_v.w, 1e-30);
    if (type == LIGHT_SUN) return (1.0 - cos(now.dir_radius.w)) / max(1.0 - cos(then.dir_radius.w), 1e-30);
    if (type == LIGHT_MESH) return 1.0;
    return (now.dir_radius.w * now.dir_radius.w) / max(then.dir_radius.w * then.dir_radius.w, 1e-30);
}

// Solid-angle pdf with which sample_light(L, p, ...) produces the direction towards y, a point
// of the light with normal ny (suns: y is the direction). Delta lights: 1. Mesh lights: 0 here;
// theirs is emitter_probability x area_to_solid_angle_pdf of y's triangle, which the caller
// knows.
float light_sample_pdf(Light L, vec3 p, vec3 y, vec3 ny) {
    if (light_is_delta(L)) return 1.0;
    int type = int(L.pos_type.w + 0.5);
    if (type == LIGHT_SUN) return cone_pdf(cos(L.dir_radius.w));
    if (type == LIGHT_POINT || type == LIGHT_SPOT) {
        float r = L.dir_radius.w;
        vec3 toc = L.pos_type.xyz - p;
        float d2 = dot(toc, toc);
        return d2 > r * r ? cone_pdf(sqrt(max(0.0, 1.0 - r * r / d2))) : 0.0;
    }
    if (type == LIGHT_AREA) return area_to_solid_angle_pdf(p, y, ny, max(L.axis_v.w, 1e-12));
    return 0.0;
}

// A known point y of light L seen from p (a point on its shape with normal ny, a delta point
// light's centre, or for suns the unit direction towards it): the direction dir and distance
// dist of the segment towards it (T_INF for suns) and the geometry factor G that turns the
// radiance stored for y into its contribution in y's own measure: |cos_y| / d^2 on surfaces
// (one-sided for spheres and area lights, two-sided for emissive triangles), 1 / d^2 for delta
// points (the stored radiance is the intensity), 1 for directions. Returns the factor on that
// radiance: the spot cone, 0 where y does not light p (the back of an area light or a sphere).
float light_eval_point(Light L, vec3 p, vec3 y, vec3 ny, out vec3 dir, out float dist, out float G) {
    G = 1.0;
    int type = int(L.pos_type.w + 0.5);
    if (type == LIGHT_SUN) {
        dir = y;
        dist = T_INF;
        return 1.0;
    }
    vec3 d = y - p;
    dist = length(d);
    dir = vec3(0.0, 0.0, 1.0);
    if (dist <= 1e-9) return 0.0;
    dir = d / dist;
    float inv_d2 = 1.0 / (dist * dist);
    if (type == LIGHT_MESH) {
        G = abs(dot(ny, dir)) * inv_d2;
        return 1.0;
    }
    float atten = type == LIGHT_SPOT ? spot_attenuation(L, normalize(p - L.pos_type.xyz)) : 1.0;
    if (light_is_delta(L)) {
        G = inv_d2;
        return atten;
    }
    float cy = dot(ny, -dir);
    if (cy <= 0.0) return 0.0;
    G = cy * inv_d2;
    return atten;
}

// ---- The BSDF half of MIS: does a ray leaving o along d see light L? (one copy, used by
// PT's bsdf_hit_light_mis in lib/scene_rt.glsl and by DIRECT's glossy MIS.)
// Area lights (front face) and sphere lights (point/spot with radius) are hit when their
// distance lies in (tmin, tmax); sun disks only by rays that escape (tmax >= T_INF) inside the
// disk. Lights are transparent (Cycles): nothing else is tested. On a hit returns true with
// the radiance Le arriving along d and the solid-angle pdf with which sample_light() would
// have produced this direction (the light's own pdf, without its selection probability).
// Point and sun lights without size and mesh lights are never hit (mesh lights are surfaces:
// the caller finds them with the BVH).
bool light_ray_hit(Light L, vec3 o, vec3 d, float tmin, float tmax, out vec3 Le, out float pdf) {
    Le = vec3(0.0);
    pdf = 0.0;
    int type = int(L.pos_type.w + 0.5);
    if (type == LIGHT_SUN) {
        if (light_is_delta(L) || tmax < T_INF || dot(d, -L.dir_radius.xyz) < cos(L.dir_radius.w)) return false;
        float sin_a = sin(L.dir_radius.w);
        Le = L.color.rgb / (PI * sin_a * sin_a);
        pdf = light_sample_pdf(L, o, d, vec3(0.0));
        return pdf > 0.0;
    }
    float t = light_ray_distance(L, o, d);
    if (!(t > tmin && t < tmax)) return false;
    vec3 y = o + t * d, ny;
    light_shape_point(L, y, ny, Le);
    if (type == LIGHT_SPOT) Le *= spot_attenuation(L, normalize(o - L.pos_type.xyz));
    pdf = light_sample_pdf(L, o, y, ny);
    return pdf > 0.0;
}

// Binary search of a cumulative power table: OUT = the first index i in [0, N) with
// CDF(i) > U (CDF(N - 1) = 1). CDF is a macro or function of the index.
#define LIGHT_CDF_SEARCH(CDF, N, U, OUT) {                                                      \
    int lo_ = 0, hi_ = (N) - 1;                                                                 \
    while (lo_ < hi_) {                                                                         \
        int mid_ = (lo_ + hi_) / 2;                                                             \
        if (CDF(mid_) <= (U)) lo_ = mid_ + 1; else hi_ = mid_;                                  \
    }                                                                                           \
    OUT = lo_;                                                                                  \
}

#ifdef USE_SCENE_BUFFERS
#include "lib/rng.glsl"

// Choose an emitter triangle of mesh light L by its power CDF; returns index, p = probability.
#define LIGHT_EMITTER_CDF(k) emitters[first + (k)].p2.w
int pick_emitter(Light L, float u, out float prob) {
    int first = int(L.axis_w.x + 0.5);
    int count = int(L.axis_w.y + 0.5);
    int lo;
    LIGHT_CDF_SEARCH(LIGHT_EMITTER_CDF, count, u, lo)
    float prev = lo > 0 ? emitters[first + lo - 1].p2.w : 0.0;
    prob = max(emitters[first + lo].p2.w - prev, 1e-12);
    return first + lo;
}
#undef LIGHT_EMITTER_CDF

float emitter_probability(Light L, int index) {
    int first = int(L.axis_w.x + 0.5);
    float prev = index > first ? emitters[index - 1].p2.w : 0.0;
    return max(emitters[index].p2.w - prev, 1e-12);
}

// One direction towards light L from p, in Cycles' units: sphere lights by uniform cone
// sampling (radiance I / (pi r^2)), suns inside their disk (radiance E / (pi sin^2 a)),
// area lights uniformly on their shape, mesh lights by a triangle chosen by power (u3) and
// a uniform point on it; point and sun lights without size are delta (Li is then the
// irradiance at normal incidence). Shared by every technique that samples lights (PT's
// next-event estimation, DIRECT's glossy MIS, ReSTIR DI's light candidates).
struct LightSample {
    vec3 dir;      // unit, from the shading point towards the light
    float dist;    // shadow ray length (T_INF for the sun)
    vec3 Li;       // radiance (or irradiance for delta lights) arriving along dir
    float pdf;     // solid-angle pdf of this direction given the light (0 = failed)
    bool delta;    // point / sun without size: no MIS
    vec3 y;        // the point on the light (suns: dir; delta points: the centre)
    vec3 ny;       // the light's normal there (surfaces)
    vec3 Le;       // radiance at y without a spot's cone (delta points: the intensity), as
                   // light_eval_point takes it back
};

LightSample sample_light(Light L, vec3 p, vec2 u2, float u3) {
    LightSample s;
    s.delta = false;
    s.pdf = 0.0;
    s.Li = vec3(0.0);
    s.dir = vec3(0.0, 0.0, 1.0);
    s.dist = 0.0;
    s.y = vec3(0.0);
    s.ny = vec3(0.0, 0.0, 1.0);
    s.Le = vec3(0.0);
    int type = int(L.pos_type.w + 0.5);
    if (type == LIGHT_POINT || type == LIGHT_SPOT) {
        vec3 c = L.pos_type.xyz;
        float r = L.dir_radius.w;
        vec3 toc = c - p;
        float d2 = dot(toc, toc);
        float d = sqrt(d2);
        vec3 w = toc / d;
        float atten = type == LIGHT_SPOT ? spot_attenuation(L, -w) : 1.0;
        if (r <= 0.0) {
            s.delta = true;
            s.dir = w;
            s.dist = d;
            s.Li = L.color.rgb * atten / d2;  // intensity / d^2 (irradiance at normal incidence)
            s.pdf = 1.0;
            s.y = c;
            s.Le = L.color.rgb;
            return s;
        }
        if (d <= r) return s;  // inside the sphere
        float sin2 = r * r / d2;
        float cos_max = sqrt(max(0.0, 1.0 - sin2));
        vec3 lw = sample_cone(u2, cos_max);
        vec3 dir = to_world(lw, w);
        float t = intersect_sphere(c, r, p, dir);
        if (t <= 0.0) t = d - r;
        s.dir = dir;
        s.dist = t;
        s.Li = L.color.rgb * atten / (PI * r * r);  // sphere radiance = I / (pi r^2)
        s.pdf = cone_pdf(cos_max);
        s.y = p + dir * t;
        light_shape_point(L, s.y, s.ny, s.Le);
        return s;
    }
    if (type == LIGHT_SUN) {
        float half_angle = L.dir_radius.w;
        vec3 w = -L.dir_radius.xyz;
        s.dist = T_INF;
        if (half_angle <= 1e-6) {
            s.delta = true;
            s.dir = w;
            s.Li = L.color.rgb;
            s.pdf = 1.0;
            s.y = w;
            s.Le = s.Li;
            return s;
        }
        float cos_max = cos(half_angle);
        s.dir = to_world(sample_cone(u2, cos_max), w);
        float sin_a = sin(half_angle);
        s.Li = L.color.rgb / (PI * sin_a * sin_a);
        s.pdf = cone_pdf(cos_max);
        s.y = s.dir;
        s.Le = s.Li;
        return s;
    }
    if (type == LIGHT_AREA) {
        vec3 q = area_light_point(L, u2);
        vec3 n = L.dir_radius.xyz;
        vec3 d = q - p;
        float dist = length(d);
        if (dist <= 0.0) return s;
        s.dir = d / dist;
        if (dot(s.dir, n) >= 0.0) return s;  // p behind the emitting face
        s.dist = dist;
        s.Li = L.color.rgb;
        s.pdf = area_to_solid_angle_pdf(p, q, n, L.axis_v.w);
        s.y = q;
        s.ny = n;
        s.Le = s.Li;
        return s;
    }
    // LIGHT_MESH: a triangle by power, then a uniform point on it (two-sided emission)
    float tri_prob;
    int e = pick_emitter(L, u3, tri_prob);
    Emitter em = emitters[e];
    vec2 b = sample_triangle(u2);
    vec3 q = (1.0 - b.x - b.y) * em.p0.xyz + b.x * em.p1.xyz + b.y * em.p2.xyz;
    vec3 n = normalize(cross(em.p1.xyz - em.p0.xyz, em.p2.xyz - em.p0.xyz));
    vec3 d = q - p;
    float dist = length(d);
    if (dist <= 0.0) return s;
    s.dir = d / dist;
    s.dist = dist;
    s.Li = em.radiance.rgb;
    s.pdf = tri_prob * area_to_solid_angle_pdf(p, q, n, em.p0.w);
    s.y = q;
    s.ny = n;
    s.Le = s.Li;
    return s;
}

// Unshadowed irradiance at p on a surface facing n (light arriving from the side n points to).
// Point/spot: I cos / d^2 (for spheres exact while the sphere lies above the horizon); sun:
// E cos; area lights: the polygon's exact irradiance; mesh lights: the exact sum over their
// triangles up to mesh_exact_max triangles, else the mean of 8 triangles picked by power
// (rng). Techniques call it for each side of a two-sided surface (VXGI) or for the shading
// normal (DIRECT's diffuse: times the diffuse BRDF).
vec3 light_irradiance(Light L, vec3 p, vec3 n, int mesh_exact_max, inout Rng rng) {
    int type = int(L.pos_type.w + 0.5);
    if (type == LIGHT_POINT || type == LIGHT_SPOT) {
        vec3 d = L.pos_type.xyz - p;
        float dist2 = max(dot(d, d), 1e-12);
        vec3 wi = d / sqrt(dist2);
        return light_intensity(L, -wi) * max(dot(n, wi), 0.0) / dist2;
    }
    if (type == LIGHT_SUN) return L.color.rgb * max(dot(n, -L.dir_radius.xyz), 0.0);
    if (type == LIGHT_AREA) return L.color.rgb * area_light_irradiance_factor(L, p, n);
    int first = int(L.axis_w.x + 0.5);
    int count = int(L.axis_w.y + 0.5);
    vec3 E = vec3(0.0);
    if (count <= mesh_exact_max) {
        for (int i = first; i < first + count; ++i) {
            Emitter e = emitters[i];
            E += e.radiance.rgb * triangle_irradiance_factor(e.p0.xyz, e.p1.xyz, e.p2.xyz, p, n);
        }
        return E;
    }
    const int K = 8;
    for (int k = 0; k < K; ++k) {
        float prob;
        Emitter e = emitters[pick_emitter(L, rng_next(rng), prob)];
        E += e.radiance.rgb * triangle_irradiance_factor(e.p0.xyz, e.p1.xyz, e.p2.xyz, p, n) / (prob * float(K));
    }
    return E;
}
#endif

#endif
