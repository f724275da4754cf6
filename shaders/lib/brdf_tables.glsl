// brdf_tables.glsl — Cycles' GGX albedo tables (addon/render/brdf_tables.py, made by
// scripts/gen_brdf_tables.py), read from one R32F texture that ProgramCache binds to every
// program declaring u_brdf_lut (render/shaders.py: brdf_lut): row 0 GGX_E[rough*32 + mu],
// row 1 GGX_EAVG[rough], rows 2-5 GGX_SCHLICK_S[(z*16 + mu)*16 + rough], rows 6-9 and
// 10-13 GGX_GLASS_E / GGX_GLASS_INV_E[(z*16 + mu)*16 + rough] (entering / leaving glass),
// row 14 SHEEN_E[rough*32 + mu] (the sheen approximation's albedo), row 15
// SHEEN_ALBEDO[rough*32 + mu] (Cycles' sheen albedo, render/sheen_table.py), 1024 texels a row.
// A texture rather than GLSL constant arrays: NVIDIA's compiler did not finish compiling a
// shader holding the 5,152 constants (direct.comp and pt.comp, over 100 s each).
#ifndef GI_BRDF_TABLES_GLSL
#define GI_BRDF_TABLES_GLSL

uniform sampler2D u_brdf_lut;

float GGX_E_at(int i) { return texelFetch(u_brdf_lut, ivec2(i, 0), 0).r; }
float GGX_EAVG_at(int i) { return texelFetch(u_brdf_lut, ivec2(i, 1), 0).r; }
float GGX_SCHLICK_S_at(int i) { return texelFetch(u_brdf_lut, ivec2(i & 1023, 2 + (i >> 10)), 0).r; }
#define GGX_GLASS_TABLES
float GGX_GLASS_E_at(int i) { return texelFetch(u_brdf_lut, ivec2(i & 1023, 6 + (i >> 10)), 0).r; }
float GGX_GLASS_INV_E_at(int i) { return texelFetch(u_brdf_lut, ivec2(i & 1023, 10 + (i >> 10)), 0).r; }
float SHEEN_E_at(int i) { return texelFetch(u_brdf_lut, ivec2(i, 14), 0).r; }
float SHEEN_ALBEDO_at(int i) { return texelFetch(u_brdf_lut, ivec2(i, 15), 0).r; }

#endif
