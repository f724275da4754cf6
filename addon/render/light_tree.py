"""Light tree and light BVH (bpy-free numpy; the host side of shaders/lib/light_select.glsl).

Two binary trees over the scene's lights, both built by one builder (``build_tree``):

* the **light tree** over every light that has a position (point, spot, area, mesh lights):
  ``select_light(u, p, n, prob)`` walks it from the root, at each node choosing a child with
  probability proportional to its importance at the shading point (Conty Estevez and Kulla
  2018, "Importance Sampling of Many Lights with Adaptive Tree Splitting": power, distance,
  the emitters' orientation cone and, optionally, the receiver's normal); suns stay outside
  it as global lights chosen by their own power share, as the world is (``u_world_select``);
  a tenth of the samples (``POWER_MIX``) picks by power alone (a defensive mixture);
* the **light BVH** over the lights a BSDF ray can hit (area lights, point and spot lights
  with a radius): ``bsdf_hit_light_mis`` intersects it instead of testing every light.

Both are balanced trees: each node's lights are sorted along the longest axis of their
centres' bounds and split at the median (node ``[lo, hi)`` splits at ``(lo + hi) // 2``), so a
leaf's root-to-leaf path follows from its position in the final order alone: ``light_pdf`` retraces it and computes the same products
as the sampler did. Node layout (16 floats, ``NODE_FLOATS``):

    [0:3] bounds min, [3] energy (the selection weight: power, as rt_scene.light_selection)
    [4:7] bounds max, [7] cos theta_o (orientation cone half-angle around the axis; -1: all)
    [8:11] axis,      [11] cos theta_e (emission half-angle beyond theta_o)
    [12] left child, or -1 - light index for a leaf; [13] right child; [14] sin theta_o

The table (appended to scene_rt.glsl's RtLightSelect buffer; offsets relative to the table's
start are made absolute by ``light_select_table``) starts with a header of ``HEADER_FLOATS``:

    [0] tree nodes offset, [1] tree size (lights in it), [2] probability of the tree against
    the suns, [3] offset of the per-light leaf position (-1: a global light),
    [4] offset of the suns' [index..., cdf...], [5] sun count, [6] light-BVH nodes offset,
    [7] light-BVH size

``importance`` / ``select`` / ``pdf`` below are the float64 reference of the GLSL.
"""
from __future__ import annotations

import numpy as np

NODE_FLOATS = 16
# Share of the samples select_light(u, p, n) picks by power alone (light_select.glsl's
# LT_POWER_MIX): a defensive mixture bounding every light's probability below by 0.1 x its
# power share.
POWER_MIX = 0.1
HEADER_FLOATS = 8
LIGHT_POINT, LIGHT_SPOT, LIGHT_SUN, LIGHT_AREA, LIGHT_MESH = 0, 1, 2, 3, 4


def _cone_union(ax_a, to_a, te_a, ax_b, to_b, te_b):
    """Bounding cone of two orientation cones (Conty and Kulla 2018, Algorithm 1), vectorised."""
    swap = to_b > to_a
    ax1 = np.where(swap[:, None], ax_b, ax_a)
    ax2 = np.where(swap[:, None], ax_a, ax_b)
    t1 = np.where(swap, to_b, to_a)
    t2 = np.where(swap, to_a, to_b)
    te = np.maximum(te_a, te_b)
    cd = np.clip(np.sum(ax1 * ax2, axis=1), -1.0, 1.0)
    td = np.arccos(cd)
    contained = np.minimum(td + t2, np.pi) <= t1
    to = 0.5 * (t1 + td + t2)
    perp = ax2 - ax1 * cd[:, None]
    pl = np.linalg.norm(perp, axis=1)
    full = (to >= np.pi) | (pl < 1e-9)
    tr = to - t1
    perp = perp / np.maximum(pl, 1e-30)[:, None]
    ax = ax1 * np.cos(tr)[:, None] + perp * np.sin(tr)[:, None]
    ax /= np.maximum(np.linalg.norm(ax, axis=1), 1e-30)[:, None]
    ax = np.where(contained[:, None], ax1, np.where(full[:, None], ax1, ax))
    to = np.where(contained, t1, np.where(full, np.pi, to))
    return ax, to, te


def build_tree(ids, bmin, bmax, energy, axis, theta_o, theta_e):
    """Balanced binary tree over m items (median splits along the longest axis of each node's
    centres). Returns
    (nodes (2m - 1, NODE_FLOATS) float32, pos (m,) int: each item's leaf position)."""
    m = len(ids)
    if m == 0:
        return np.zeros((0, NODE_FLOATS), np.float32), np.zeros(0, np.int64)
    bmin, bmax = np.asarray(bmin, np.float64), np.asarray(bmax, np.float64)
    cen = 0.5 * (bmin + bmax)
    order = np.arange(m)  # item at each position; each level sorts its nodes' ranges
    total = 2 * m - 1
    lo = np.zeros(total, np.int64)
    hi = np.zeros(total, np.int64)
    left = np.full(total, -1, np.int64)
    right = np.full(total, -1, np.int64)
    hi[0] = m
    levels = [np.array([0])]
    nxt = 1
    while True:
        cur = levels[-1]
        inner = cur[hi[cur] - lo[cur] > 1]
        if inner.size == 0:
            break
        # sort each node's range along the longest axis of its centres' bounds (median split)
        inner = inner[np.argsort(lo[inner], kind="stable")]
        sizes = hi[inner] - lo[inner]
        offs = np.cumsum(sizes) - sizes
        rep = np.repeat(np.arange(inner.size), sizes)
        at = lo[inner][rep] + np.arange(int(sizes.sum())) - offs[rep]
        cc = cen[order[at]]
        ax = np.argmax(np.maximum.reduceat(cc, offs, axis=0) - np.minimum.reduceat(cc, offs, axis=0), axis=1)
        key = cc[np.arange(len(at)), ax[rep]]
        order[at] = order[at][np.lexsort((key, rep))]
        k = inner.size
        lc = nxt + 2 * np.arange(k)
        rc = lc + 1
        nxt += 2 * k
        mid = (lo[inner] + hi[inner]) // 2
        left[inner], right[inner] = lc, rc
        lo[lc], hi[lc] = lo[inner], mid
        lo[rc], hi[rc] = mid, hi[inner]
        levels.append(np.concatenate([lc, rc]))
    nb_min = np.zeros((total, 3))
    nb_max = np.zeros((total, 3))
    ne = np.zeros(total)
    nax = np.zeros((total, 3))
    nto = np.zeros(total)
    nte = np.zeros(total)
    leaf = left < 0
    item = order[lo[leaf]]
    nb_min[leaf], nb_max[leaf] = bmin[item], bmax[item]
    ne[leaf] = np.asarray(energy, np.float64)[item]
    nax[leaf] = np.asarray(axis, np.float64)[item]
    nto[leaf] = np.asarray(theta_o, np.float64)[item]
    nte[leaf] = np.asarray(theta_e, np.float64)[item]
    for lvl in reversed(levels):
        inner = lvl[left[lvl] >= 0]
        if inner.size == 0:
            continue
        a, b = left[inner], right[inner]
        nb_min[inner] = np.minimum(nb_min[a], nb_min[b])
        nb_max[inner] = np.maximum(nb_max[a], nb_max[b])
        ne[inner] = ne[a] + ne[b]
        # a child without energy is never chosen: its cone does not widen the parent's
        ea, eb = ne[a] > 0, ne[b] > 0
        ax, to, te = _cone_union(nax[a], nto[a], nte[a], nax[b], nto[b], nte[b])
        only_a, only_b = ea & ~eb, eb & ~ea
        nax[inner] = np.where(only_a[:, None], nax[a], np.where(only_b[:, None], nax[b], ax))
        nto[inner] = np.where(only_a, nto[a], np.where(only_b, nto[b], to))
        nte[inner] = np.where(only_a, nte[a], np.where(only_b, nte[b], te))
    pos = np.empty(m, np.int64)
    pos[order] = np.arange(m)
    nodes = np.zeros((total, NODE_FLOATS), np.float32)
    nodes[:, 0:3], nodes[:, 3] = nb_min, ne
    nodes[:, 4:7], nodes[:, 7] = nb_max, np.where(nto >= np.pi, -1.0, np.cos(nto))
    nodes[:, 8:11], nodes[:, 11] = nax, np.cos(nte)
    nodes[:, 14] = np.where(nto >= np.pi, 0.0, np.sin(nto))
    nodes[:, 12] = np.where(leaf, -1 - np.asarray(ids)[order[lo]], left)
    nodes[:, 13] = right
    return nodes, pos


def light_bounds(light_array: np.ndarray, count: int, emitter_groups) -> dict:
    """Per light (gpu_scene.pack_lights rows): bounds, orientation cone, and whether it is in
    the tree (not a sun) and hittable by a BSDF ray (area; point/spot with a radius)."""
    n = int(count)
    a = np.asarray(light_array, np.float64).reshape(-1, 28)[:n]
    typ = np.rint(a[:, 3]).astype(int)
    pos, d, r = a[:, 0:3], a[:, 4:7], np.maximum(a[:, 7], 0.0)
    bmin, bmax = pos.copy(), pos.copy()
    sph = (typ == LIGHT_POINT) | (typ == LIGHT_SPOT)
    bmin[sph] -= r[sph, None]
    bmax[sph] += r[sph, None]
    area = typ == LIGHT_AREA
    ext = np.abs(a[:, 12:15]) + np.abs(a[:, 16:19])
    bmin[area] -= ext[area]
    bmax[area] += ext[area]
    first_mesh = n - len(emitter_groups)
    for gi, g in enumerate(emitter_groups):
        w = np.asarray(g["triangles"], np.float64).reshape(-1, 3)
        bmin[first_mesh + gi], bmax[first_mesh + gi] = w.min(axis=0), w.max(axis=0)
    axis = np.zeros((n, 3))
    axis[:, 2] = 1.0
    theta_o = np.full(n, np.pi)
    theta_e = np.full(n, 0.5 * np.pi)
    dn = np.linalg.norm(d, axis=1)
    oriented = ((typ == LIGHT_SPOT) | area) & (dn > 1e-12)
    axis[oriented] = d[oriented] / dn[oriented, None]
    theta_o[oriented] = 0.0
    spot = (typ == LIGHT_SPOT) & oriented
    theta_e[spot] = np.arccos(np.clip(a[spot, 15], -1.0, 1.0))  # half cone (Cycles' smoothstep is 0 beyond)
    return {"type": typ, "bmin": bmin, "bmax": bmax, "axis": axis, "theta_o": theta_o, "theta_e": theta_e,
            "in_tree": typ != LIGHT_SUN, "hittable": area | (sph & (r > 0.0))}


def light_select_table(weights: np.ndarray, light_array: np.ndarray, count: int, emitter_groups,
                       offset: int) -> np.ndarray:
    """The header, the light tree, the leaf positions, the suns' CDF and the light BVH, with
    offsets made absolute for a table that starts at ``offset`` of RtLightSelect. ``weights``:
    rt_scene's selection weights (after its all-zero fallback)."""
    n = int(count)
    b = light_bounds(light_array, n, emitter_groups)
    w = np.asarray(weights, np.float64)
    tree_ids = np.nonzero(b["in_tree"])[0]
    sun_ids = np.nonzero(~b["in_tree"])[0]
    hit_ids = np.nonzero(b["hittable"])[0]
    nodes, pos = build_tree(tree_ids, b["bmin"][tree_ids], b["bmax"][tree_ids], w[tree_ids],
                            b["axis"][tree_ids], b["theta_o"][tree_ids], b["theta_e"][tree_ids])
    # the BVH's boxes padded a little: a flat area light's box has no thickness
    pad = (1e-5 * np.maximum(np.abs(b["bmin"]), np.abs(b["bmax"])).max(axis=1) + 1e-6)[:, None]
    hnodes, _ = build_tree(hit_ids, (b["bmin"] - pad)[hit_ids], (b["bmax"] + pad)[hit_ids], w[hit_ids],
                           b["axis"][hit_ids], b["theta_o"][hit_ids], b["theta_e"][hit_ids])
    leafpos = np.full(n, -1.0)
    leafpos[tree_ids] = pos
    wt, ws = float(w[tree_ids].sum()), float(w[sun_ids].sum())
    tree_prob = wt / (wt + ws) if wt + ws > 0 else (1.0 if tree_ids.size else 0.0)
    if tree_ids.size and wt <= 0.0:
        tree_prob = 0.0
    sun_cdf = np.cumsum(w[sun_ids]) / ws if ws > 0 else np.linspace(1.0, 1.0, sun_ids.size)
    if sun_cdf.size:
        sun_cdf[-1] = 1.0
    o_nodes = offset + HEADER_FLOATS
    o_pos = o_nodes + nodes.size
    o_suns = o_pos + n
    o_hit = o_suns + 2 * sun_ids.size
    header = np.array([o_nodes, tree_ids.size, tree_prob, o_pos, o_suns, sun_ids.size, o_hit, hit_ids.size],
                      np.float64)
    return np.concatenate([header, nodes.ravel(), leafpos, sun_ids.astype(np.float64), sun_cdf,
                           hnodes.ravel()]).astype(np.float32)


# ------------------------------------------------------------------ float64 reference (tests)
def importance(node: np.ndarray, p: np.ndarray, n: np.ndarray | None = None) -> float:
    """A node's importance at shading point p (normal n, or None: no receiver term); the
    float64 twin of light_select.glsl's lt_importance (the same cosine identities)."""
    node = np.asarray(node, np.float64)
    energy = node[3]
    if energy <= 0.0:
        return 0.0
    bmin, bmax = node[0:3], node[4:7]
    to = p - 0.5 * (bmin + bmax)
    d2 = float(to @ to)
    r2 = 0.25 * float((bmax - bmin) @ (bmax - bmin))
    if d2 > r2:
        sin_u = np.sqrt(r2 / d2)
        cos_u = np.sqrt(1.0 - r2 / d2)
    else:
        sin_u, cos_u = 0.0, -1.0
    w = to / np.sqrt(max(d2, 1e-30))
    orient = 1.0
    if node[7] > -1.0:
        ct = float(np.clip(node[8:11] @ w, -1.0, 1.0))
        st = np.sqrt(max(0.0, 1.0 - ct * ct))
        c1, s1 = (1.0, 0.0) if ct >= cos_u else (ct * cos_u + st * sin_u, st * cos_u - ct * sin_u)
        ctp = 1.0 if c1 >= node[7] else c1 * node[7] + s1 * node[14]
        if ctp <= node[11]:
            return 0.0
        orient = ctp
    recv = 1.0
    if n is not None and float(n @ n) > 0.0:
        ci = float(np.clip(-(n @ w), -1.0, 1.0))
        si = np.sqrt(max(0.0, 1.0 - ci * ci))
        recv = 1.0 if ci >= cos_u else ci * cos_u + si * sin_u
        if recv <= 0.0:
            return 0.0
    return energy * orient * recv / max(d2, r2, 1e-12)


def _left_prob(nodes, k, p, n):
    il = importance(nodes[int(nodes[k, 12])], p, n)
    ir = importance(nodes[int(nodes[k, 13])], p, n)
    return il / (il + ir) if il + ir > 0.0 else 0.5


def tree_pdf(nodes: np.ndarray, pos: int, size: int, p, n=None) -> float:
    """Probability that the tree walk at (p, n) ends at the leaf at position pos."""
    k, lo, hi, prob = 0, 0, size, 1.0
    while nodes[k, 12] >= 0:
        mid = (lo + hi) // 2
        pl = _left_prob(nodes, k, p, n)
        if pos < mid:
            prob *= pl
            k, hi = int(nodes[k, 12]), mid
        else:
            prob *= 1.0 - pl
            k, lo = int(nodes[k, 13]), mid
    return prob


def table_pdf(table: np.ndarray, offset: int, light: int, flat_prob: float, p, n=None) -> float:
    """light_pdf(i, p, n) from a table as built by light_select_table (offset: where it starts
    in RtLightSelect; table: that buffer)."""
    h = table[offset:offset + HEADER_FLOATS].astype(np.float64)
    o_nodes, size, tree_prob, o_pos = int(h[0]), int(h[1]), h[2], int(h[3])
    pos = int(table[o_pos + light])
    if pos < 0:
        return float(flat_prob)
    nodes = table[o_nodes:o_nodes + NODE_FLOATS * (2 * size - 1)].reshape(-1, NODE_FLOATS).astype(np.float64)
    return POWER_MIX * float(flat_prob) + (1.0 - POWER_MIX) * tree_prob * tree_pdf(
        nodes, pos, size, np.asarray(p, np.float64), None if n is None else np.asarray(n, np.float64))
