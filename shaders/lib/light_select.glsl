// light_select.glsl — many-light selection for every technique: a light tree walked by
// importance at the shading point, a power-only table for callers without one, and a BVH over
// the lights a BSDF ray can hit. Host side: addon/render/light_tree.py (layout, float64 twin of
// every function here) and rt_scene.light_table (the RtLightSelect buffer these read).
// Included by lib/scene_rt.glsl after its RtLightSelect buffer; needs lib/bvh.glsl (rt_box) and
// lib/lights.glsl (LIGHT_CDF_SEARCH, the one binary search over power tables).
//
//   int i = select_light(u, p, n, prob);   // light tree (suns: by power, outside the tree)
//   float pr = light_pdf(i, p, n);         // the same probability, for MIS
//   int i = select_light(u, prob);         // by power only (no shading point)
//   float pr = light_pdf(i);
// n = vec3(0.0) leaves out the receiver's horizon term (the next-event pair shade_direct /
// bsdf_hit_light_mis passes no normal: a BSDF ray's MIS weight is computed where the
// origin's normal is no longer known). Cost: O(log lights) per call.
//   light_bvh_first(o, d, tmin, tmax) / light_bvh_next(...): the area and sphere lights a ray
//   segment may cross, by the light BVH (see lights_crossed in scene_rt.glsl).
#ifndef GI_LIGHT_SELECT_GLSL
#define GI_LIGHT_SELECT_GLSL

// Offset of the light tree's header in rt_light_select (light_tree.py: HEADER_FLOATS), -1: none.
uniform int u_light_tree;
#define LT_NODE_FLOATS 16
#define LT_STACK 32

vec3 lt_vec3(int i) { return vec3(rt_light_select[i], rt_light_select[i + 1], rt_light_select[i + 2]); }

// Power-only selection: the table's cdf over every light (suns: irradiance x the scene's
// cross-section).
#define LT_TABLE_CDF(k) rt_light_select[k]
int select_light(float u, out float prob) {
    int lo;
    LIGHT_CDF_SEARCH(LT_TABLE_CDF, u_light_count, u, lo)
    prob = rt_light_select[u_light_count + lo];
    return lo;
}
#undef LT_TABLE_CDF

float light_pdf(int i) { return rt_light_select[u_light_count + i]; }

// Importance of the tree node at offset b at p with normal n (0: none): energy x the bound
// of the emitters' orientation cosine x the receiver's cosine bound / distance^2 (Conty
// Estevez and Kulla 2018; distance clamped to the bounds' half diagonal). Angles are
// subtracted through their cosines and sines (no acos: exact enough at grazing angles).
float lt_importance(int b, vec3 p, vec3 n) {
    float energy = rt_light_select[b + 3];
    if (energy <= 0.0) return 0.0;
    vec3 bmin = lt_vec3(b), bmax = lt_vec3(b + 4);
    vec3 to = p - 0.5 * (bmin + bmax);
    float d2 = dot(to, to);
    vec3 e = bmax - bmin;
    float r2 = 0.25 * dot(e, e);
    float sin_u = 0.0, cos_u = -1.0;  // the bounds' half-angle seen from p (inside: pi)
    if (d2 > r2) { sin_u = sqrt(r2 / d2); cos_u = sqrt(1.0 - r2 / d2); }
    vec3 w = to * inversesqrt(max(d2, 1e-30));
    float orient = 1.0;
    float cos_o = rt_light_select[b + 7];
    if (cos_o > -1.0) {
        float ct = clamp(dot(lt_vec3(b + 8), w), -1.0, 1.0);
        float st = sqrt(max(0.0, 1.0 - ct * ct));
        float c1 = 1.0, s1 = 0.0;  // theta - theta_u
        if (ct < cos_u) { c1 = ct * cos_u + st * sin_u; s1 = st * cos_u - ct * sin_u; }
        float ctp = c1 >= cos_o ? 1.0 : c1 * cos_o + s1 * rt_light_select[b + 14];  // - theta_o
        if (ctp <= rt_light_select[b + 11]) return 0.0;
        orient = ctp;
    }
    float recv = 1.0;
    if (dot(n, n) > 0.0) {
        float ci = clamp(-dot(n, w), -1.0, 1.0);
        float si = sqrt(max(0.0, 1.0 - ci * ci));
        recv = ci >= cos_u ? 1.0 : ci * cos_u + si * sin_u;
        if (recv <= 0.0) return 0.0;
    }
    return energy * orient * recv / max(max(d2, r2), 1e-12);
}

// Probability of descending into the left child of internal node at offset b.
float lt_left_prob(int nodes, int b, vec3 p, vec3 n) {
    float il = lt_importance(nodes + LT_NODE_FLOATS * int(rt_light_select[b + 12]), p, n);
    float ir = lt_importance(nodes + LT_NODE_FLOATS * int(rt_light_select[b + 13]), p, n);
    return il + ir > 0.0 ? il / (il + ir) : 0.5;
}

// Defensive mixture: this share of the samples picks a light by power alone, so no light's
// probability falls below LT_POWER_MIX x its power share where the tree's importance bound
// underrates it (a light near p inside a large cluster): the tail of rare bright samples stays
// bounded by the power-only estimator's (light_tree.POWER_MIX).
#define LT_POWER_MIX 0.1

float light_pdf(int i, vec3 p, vec3 n);

// One light by importance at (p, n): with the tree's share of the power a walk down the tree
// (u rescaled at every node), else a sun by its power; LT_POWER_MIX of the samples by power
// alone. prob = the probability of that light (= light_pdf(i, p, n)).
int select_light(float u, vec3 p, vec3 n, out float prob) {
    if (u_light_tree < 0) { prob = 0.0; return 0; }
    if (u < LT_POWER_MIX) {
        float pp;
        int i = select_light(u / LT_POWER_MIX, pp);
        prob = light_pdf(i, p, n);
        return i;
    }
    u = (u - LT_POWER_MIX) / (1.0 - LT_POWER_MIX);
    int h = u_light_tree;
    int size = int(rt_light_select[h + 1]);
    float tree_prob = rt_light_select[h + 2];
    if (u < tree_prob || int(rt_light_select[h + 5]) == 0) {
        int nodes = int(rt_light_select[h]);
        u = clamp(u / tree_prob, 0.0, 0.99999994);
        prob = tree_prob;
        int b = nodes;
        for (int depth = 0; depth < 64; ++depth) {
            float left = rt_light_select[b + 12];
            if (left < 0.0) {
                int i = int(-1.0 - left + 0.5);
                prob = LT_POWER_MIX * light_pdf(i) + (1.0 - LT_POWER_MIX) * prob;
                return i;
            }
            float pl = lt_left_prob(nodes, b, p, n);
            if (u < pl) {
                u = clamp(u / pl, 0.0, 0.99999994);
                prob *= pl;
                b = nodes + LT_NODE_FLOATS * int(left);
            } else {
                u = clamp((u - pl) / (1.0 - pl), 0.0, 0.99999994);
                prob *= 1.0 - pl;
                b = nodes + LT_NODE_FLOATS * int(rt_light_select[b + 13]);
            }
        }
        prob = 0.0;
        return 0;
    }
    // a sun: its cdf among the suns; its probability is its power share (the flat table's)
    int suns = int(rt_light_select[h + 4]);
    int ns = int(rt_light_select[h + 5]);
    u = (u - tree_prob) / max(1.0 - tree_prob, 1e-30);
#define LT_SUN_CDF(k) rt_light_select[suns + ns + (k)]
    int lo;
    LIGHT_CDF_SEARCH(LT_SUN_CDF, ns, u, lo)
#undef LT_SUN_CDF
    int i = int(rt_light_select[suns + lo] + 0.5);
    prob = light_pdf(i);
    return i;
}

// The probability with which select_light(u, p, n, .) picks light i: the same walk, guided
// by the leaf's position (node [lo, hi) splits at (lo + hi) / 2), the same products.
float light_pdf(int i, vec3 p, vec3 n) {
    if (u_light_tree < 0) return 0.0;
    int h = u_light_tree;
    int pos = int(rt_light_select[int(rt_light_select[h + 3]) + i]);
    if (pos < 0) return light_pdf(i);  // a sun: its power share either way
    int nodes = int(rt_light_select[h]);
    int lo = 0, hi = int(rt_light_select[h + 1]);
    float prob = rt_light_select[h + 2];
    int b = nodes;
    for (int depth = 0; depth < 64; ++depth) {
        float left = rt_light_select[b + 12];
        if (left < 0.0) return LT_POWER_MIX * light_pdf(i) + (1.0 - LT_POWER_MIX) * prob;
        float pl = lt_left_prob(nodes, b, p, n);
        int mid = (lo + hi) / 2;
        if (pos < mid) {
            prob *= pl;
            hi = mid;
            b = nodes + LT_NODE_FLOATS * int(left);
        } else {
            prob *= 1.0 - pl;
            lo = mid;
            b = nodes + LT_NODE_FLOATS * int(rt_light_select[b + 13]);
        }
    }
    return 0.0;
}

// ---- the light BVH: area lights and sphere lights (point/spot with a radius)
// Calls LIGHT_BVH_VISIT(i) for every light whose bounds the segment (tmin, tmax) of the ray
// crosses. Usage: #define a visitor, then LIGHT_BVH_TRAVERSE(o, d, tmin, tmax, VISITOR).
#define LIGHT_BVH_TRAVERSE(O, D, TMIN, TMAX, VISIT) {                                          \
    int lb_nodes_ = u_light_tree >= 0 ? int(rt_light_select[u_light_tree + 6]) : 0;             \
    int lb_size_ = u_light_tree >= 0 ? int(rt_light_select[u_light_tree + 7]) : 0;              \
    if (lb_size_ > 0) {                                                                         \
        RtRay lb_ray_;                                                                          \
        lb_ray_.o = (O);                                                                        \
        lb_ray_.inv_d = 1.0 / rt_safe_dir(D);                                                   \
        int lb_stack_[LT_STACK];                                                                \
        int lb_sp_ = 0;                                                                         \
        int lb_k_ = 0;                                                                          \
        for (int lb_it_ = 0; lb_it_ < 4 * 65536; ++lb_it_) {                                   \
            int lb_b_ = lb_nodes_ + LT_NODE_FLOATS * lb_k_;                                     \
            bool lb_pop_ = true;                                                                \
            if (rt_box(lb_ray_, lt_vec3(lb_b_), lt_vec3(lb_b_ + 4), (TMIN), (TMAX)) < 1e38) {    \
                float lb_left_ = rt_light_select[lb_b_ + 12];                                   \
                if (lb_left_ < 0.0) {                                                           \
                    int lb_i_ = int(-1.0 - lb_left_ + 0.5);                                     \
                    VISIT(lb_i_);                                                               \
                } else if (lb_sp_ < LT_STACK) {                                                 \
                    lb_stack_[lb_sp_++] = int(rt_light_select[lb_b_ + 13]);                     \
                    lb_k_ = int(lb_left_);                                                      \
                    lb_pop_ = false;                                                            \
                }                                                                               \
            }                                                                                   \
            if (lb_pop_) {                                                                      \
                if (lb_sp_ == 0) break;                                                         \
                lb_k_ = lb_stack_[--lb_sp_];                                                    \
            }                                                                                   \
        }                                                                                       \
    }                                                                                           \
}

#endif
