// common.glsl — constants, scene structs and buffer bindings shared by every shader.
// The host side of these layouts is addon/render/gpu_scene.py (one source of truth for
// each std430 struct: keep the two in step).
#ifndef GI_COMMON_GLSL
#define GI_COMMON_GLSL

#define PI 3.14159265358979323846
#define TWO_PI 6.28318530717958647692
#define INV_PI 0.31830988618379067154
#define INV_FOUR_PI 0.07957747154594766788
#define FLT_MAX 3.402823466e+38
const float T_INF = 1e30;  // "no hit" ray length (e.g. towards the sun)

// Buffer binding points (a shader may override before including this file).
#ifndef BIND_MATERIALS
#define BIND_MATERIALS 0
#endif
#ifndef BIND_LIGHTS
#define BIND_LIGHTS 1
#endif
#ifndef BIND_EMITTERS
#define BIND_EMITTERS 2
#endif
#ifndef BIND_SHADOW_VIEWS
#define BIND_SHADOW_VIEWS 3
#endif

// Light types (scene_data.LightType, plus emissive meshes grouped per object).
#define LIGHT_POINT 0
#define LIGHT_SPOT 1
#define LIGHT_SUN 2
#define LIGHT_AREA 3
#define LIGHT_MESH 4

#define SHAPE_SQUARE 0
#define SHAPE_RECTANGLE 1
#define SHAPE_DISK 2
#define SHAPE_ELLIPSE 3

// Texture maps of a Material (scene_data.MATERIAL_MAPS order). Each map is a vec4:
// x = texture-array layer (-1 = none), y = width * 4096 + height of its image in the layer,
// z = flags (channel + 1, 0 = RGB | Closest << 3 | extension << 4: 0 repeat, 1 extend,
// 2 clip, 3 mirror), w = scale (emission strength, normal-map strength).
#define MAP_BASE_COLOR 0
#define MAP_ROUGHNESS 1
#define MAP_METALLIC 2
#define MAP_ALPHA 3
#define MAP_EMISSION 4
#define MAP_NORMAL 5
#define MAP_SPECULAR 6
#define MAP_WEIGHT 7       // a lobe's weight in its material's lobe list (Mix Shader factors)
#define MAP_BUMP 8         // a Bump node's height (scale = Distance, negative when inverted)
#define MATERIAL_MAP_COUNT 9

// BSDF kinds of a lobe (Material.bsdf.x; scene_data.BSDF_KINDS order). Adding a kind touches
// scene_data.BSDF_KINDS, the exporter's reading of its node and lib/brdf.glsl's
// eval_surface / sample_surface / pdf_surface.
#define BSDF_PRINCIPLED 0
#define BSDF_GLOSSY 1      // GGX with a constant Fresnel colour (Cycles' Glossy BSDF)
#define BSDF_GLASS 2       // dielectric GGX reflection + refraction, tinted both ways (Glass BSDF)
#define BSDF_REFRACTION 3  // GGX refraction only, no Fresnel (Refraction BSDF)
#define BSDF_TRANSLUCENT 4 // diffuse transmission (Translucent BSDF)
#define MATERIAL_MAX_LOBES 4

struct Material {
    vec4 base_color;   // rgb linear (the texture's mean when textured), w = base-colour layer (-1 = none)
    vec4 params;       // metallic, roughness, ior, specular_ior_level
    vec4 emission;     // rgb radiance (colour * strength), w = alpha
    vec4 spec_tint;    // rgb specular tint, w = 1 when the material was understood exactly
    vec4 bsdf;         // x = BSDF_* kind, y = Principled transmission weight, z = the lobe's weight
                       // (constant, or the mean of maps[MAP_WEIGHT]), w = 1 when some lobe transmits
    vec4 lobes;        // x = first lobe record, y = lobe count (0: this record is the one lobe),
                       // z = Bump strength (maps[MAP_BUMP]), w = 1: Bump Map Correction.
                       // A material with lobes is, in this record, the blended approximation the
                       // G-buffer family renders; the path tracer evaluates its lobe records.
    vec4 maps[MATERIAL_MAP_COUNT];  // textures feeding the values above (lib/textures.glsl)
    vec4 coat;         // Principled coat: weight, roughness, IOR, -
    vec4 coat_tint;    // rgb coat tint, w = sheen weight
    vec4 sheen;        // rgb sheen tint, w = sheen roughness
};

struct Light {
    vec4 pos_type;     // xyz position (area/sphere centre), w = LIGHT_*
    vec4 dir_radius;   // xyz unit direction the light shines along, w = sphere radius | sun half-angle
    vec4 color;        // rgb: point/spot intensity W/sr | sun irradiance W/m^2 | area/mesh radiance; w = power
    vec4 axis_u;       // area: half-extent vector u, w = shape | spot: row 0 of world->light 3x3, w = cos(half cone)
    vec4 axis_v;       // area: half-extent vector v, w = area (m^2) | spot: row 1, w = spot smoothness 1/((1-cos)*blend)
    vec4 axis_w;       // spot: row 2 of world->light 3x3 | mesh: x = first emitter, y = count; w = casts shadow
    vec4 shadow;       // x = first shadow view, y = view count, z = views per shadow origin, w = mesh light area
};

struct Emitter {       // one emissive triangle in world space
    vec4 p0;           // xyz, w = area
    vec4 p1;           // xyz, w = instance index
    vec4 p2;           // xyz, w = cdf within its mesh light
    vec4 radiance;     // rgb, w = power (radiance luminance * area * pi)
};

struct ShadowView {
    mat4 view_proj;    // world -> clip of this view
    vec4 rect;         // atlas uv offset xy, scale zw
    vec4 origin;       // xyz origin of the view (light sample point), w = 0 perspective (distance), 1 ortho (depth)
    vec4 dir;          // xyz: ortho light direction | light normal at the sampled origin (zero if none), w = world size of one texel at distance 1 (persp) | texel size (ortho)
    vec4 misc;         // x = far distance, y = normal-offset scale, zw unused
};

#ifdef USE_SCENE_BUFFERS
layout(std430, binding = BIND_MATERIALS) readonly buffer MaterialBuffer { Material materials[]; };
layout(std430, binding = BIND_LIGHTS) readonly buffer LightBuffer { Light lights[]; };
layout(std430, binding = BIND_EMITTERS) readonly buffer EmitterBuffer { Emitter emitters[]; };
uniform int u_light_count;
uniform int u_emitter_count;
#endif

float max3(vec3 v) { return max(v.x, max(v.y, v.z)); }
float luminance(vec3 c) { return dot(c, vec3(0.2126, 0.7152, 0.0722)); }
float sqr(float x) { return x * x; }
float saturate(float x) { return clamp(x, 0.0, 1.0); }

// A history value as it is read back: NaN/Inf (written by an earlier frame) reads as 0, so one
// bad frame does not stay in a volume, atlas or cache that blends its past forever.
vec4 finite_or_zero(vec4 v) {
    bvec4 bad = bvec4(isnan(v.x) || isinf(v.x), isnan(v.y) || isinf(v.y), isnan(v.z) || isinf(v.z),
                      isnan(v.w) || isinf(v.w));
    return mix(v, vec4(0.0), bad);
}

// Replace NaN/Inf by 0 and clamp to a finite range (every technique's final write goes through this).
vec3 sanitize(vec3 c) {
    bvec3 bad = bvec3(isnan(c.x) || isinf(c.x), isnan(c.y) || isinf(c.y), isnan(c.z) || isinf(c.z));
    return clamp(mix(c, vec3(0.0), bad), vec3(0.0), vec3(1e20));
}

#endif
