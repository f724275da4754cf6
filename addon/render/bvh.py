"""Two-level bounding volume hierarchy for GPU ray tracing (bpy-free, numpy only).

* Bottom level (BLAS): one BVH per mesh, in object space, built once per mesh (``BLAS_CACHE``:
  shared by every session, rebuilt only for meshes whose positions change) by a binned
  surface-area-heuristic builder (Wald 2007, "On fast construction of SAH-based bounding
  volume hierarchies"). The build is *level-synchronous*: every node of one tree depth is
  binned and split in the same handful of vectorised numpy calls (``np.minimum.at`` over
  (node, bin) keys, prefix unions along the bins, a stable in-segment partition by
  cumulative sums). So Python runs O(depth) iterations, not O(nodes), and 4·10^6
  triangles build in seconds on two cores (see docs/results/rt_benchmark.md).
* Top level (TLAS): a BVH over instances (world AABBs of each BLAS root box transformed by
  the instance matrix), one instance per leaf. It is rebuilt every frame in well under a
  millisecond for hundreds of instances: moving an object touches only the TLAS.

GPU layout (std430, matches ``shaders/lib/bvh.glsl``)
------------------------------------------------------
``nodes``: float32 (N, 8) = two vec4 per node::

    vec4(min.xyz, intBitsToFloat(left_or_first))  vec4(max.xyz, intBitsToFloat(count))

``count > 0``: a leaf over primitives ``[first, first + count)`` (triangles in BVH order for a
BLAS, instance indices for the TLAS); ``count == 0``: an interior node whose children are
``left`` and ``left + 1``. All BLAS of a scene share one node array and one triangle array
(indices already offset), so a BLAS is just its root node index.

Per triangle (in BVH order, global over all meshes): ``verts`` vec4[3T] (object-space corner
positions), ``normals`` 2 x vec4[3T] (corner normal xyz, w = u; MikkTSpace tangent xyz,
w = bitangent sign, zero without one), ``uvs``... packed as the w of ``verts`` (v) so that
the shading attributes cost two buffers, ``tri_info`` ivec2[T]
(original triangle index within its mesh, mesh material id). ``instances``: per instance
``mat4 world_to_object, mat4 object_to_world, ivec4(blas_root, mesh, material_map_offset,
triangle_offset)``; ``material_map``: int[] per-instance material remaps.
"""
from __future__ import annotations

import hashlib
import time
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np

SAH_BINS = 16
MAX_LEAF = 4  # leaves hold at most this many triangles unless the tree hits MAX_DEPTH
MAX_DEPTH = 60  # traversal stacks in bvh.glsl hold 64 entries
COST_TRAVERSE = 1.0  # SAH cost of one node visit relative to one triangle test
COST_INTERSECT = 1.0


@dataclass
class BVH:
    """One flattened BVH. ``nodes`` (N, 8) float32 as described in the module docstring,
    ``prim_order`` (P,) int32: leaf slot -> original primitive index."""

    nodes: np.ndarray
    prim_order: np.ndarray
    depth: int = 0
    build_ms: float = 0.0

    @property
    def node_count(self) -> int:
        return int(self.nodes.shape[0])

    # decoded views (int32) of the packed node fields
    @property
    def left_or_first(self) -> np.ndarray:
        return self.nodes[:, 3].view(np.int32)

    @property
    def count(self) -> np.ndarray:
        return self.nodes[:, 7].view(np.int32)

    @property
    def bounds_min(self) -> np.ndarray:
        return self.nodes[:, 0:3]

    @property
    def bounds_max(self) -> np.ndarray:
        return self.nodes[:, 4:7]


def _pack_nodes(bmin, bmax, left_or_first, count) -> np.ndarray:
    n = bmin.shape[0]
    out = np.empty((n, 8), np.float32)
    out[:, 0:3] = bmin
    out[:, 4:7] = bmax
    out[:, 3] = np.asarray(left_or_first, np.int32).view(np.float32)
    out[:, 7] = np.asarray(count, np.int32).view(np.float32)
    return out


def _half_area(ext: np.ndarray) -> np.ndarray:
    ext = np.where(np.isfinite(ext), np.maximum(ext, 0.0), 0.0)
    return ext[..., 0] * ext[..., 1] + ext[..., 1] * ext[..., 2] + ext[..., 2] * ext[..., 0]


def _spread_bits(v: np.ndarray) -> np.ndarray:
    v = v.astype(np.uint64) & np.uint64(0x1FFFFF)
    v = (v | (v << np.uint64(32))) & np.uint64(0x1F00000000FFFF)
    v = (v | (v << np.uint64(16))) & np.uint64(0x1F0000FF0000FF)
    v = (v | (v << np.uint64(8))) & np.uint64(0x100F00F00F00F00F)
    v = (v | (v << np.uint64(4))) & np.uint64(0x10C30C30C30C30C3)
    v = (v | (v << np.uint64(2))) & np.uint64(0x1249249249249249)
    return v


def morton_codes(points: np.ndarray) -> np.ndarray:
    """63-bit Morton codes of points quantised to 2^21 cells per axis of their bounds."""
    lo = points.min(axis=0)
    ext = np.maximum(points.max(axis=0) - lo, 1e-30)
    q = np.clip(((points - lo) / ext * 2097151.0), 0, 2097151).astype(np.uint64)
    return (_spread_bits(q[:, 0]) << np.uint64(2)) | (_spread_bits(q[:, 1]) << np.uint64(1)) | _spread_bits(q[:, 2])


def _prefix_suffix(col: np.ndarray, op) -> tuple[np.ndarray, np.ndarray]:
    """For (B, m) bins: op-prefix over bins [0, s) and op-suffix over [s, B), s = 1..B-1."""
    B = col.shape[0]
    pre = np.empty((B - 1,) + col.shape[1:], col.dtype)
    suf = np.empty_like(pre)
    pre[0] = col[0]
    for i in range(1, B - 1):
        op(pre[i - 1], col[i], out=pre[i])
    suf[B - 2] = col[B - 1]
    for i in range(B - 3, -1, -1):
        op(suf[i + 1], col[i + 1], out=suf[i])
    return pre, suf


def _half_area3(ext: list) -> np.ndarray:
    x, y, z = (np.where(e > 0, e, 0.0) for e in ext)  # empty sides have -inf extents
    return x * y + y * z + z * x


def build_bvh(prim_min: np.ndarray, prim_max: np.ndarray, max_leaf: int = MAX_LEAF,
              bins: int = SAH_BINS, max_depth: int = MAX_DEPTH) -> BVH:
    """Binned-SAH BVH over primitives given by their AABBs ((P, 3) float32 each).

    Level-synchronous: all nodes of one depth are processed together. Nodes are numbered
    breadth first; siblings are adjacent (``left``, ``left + 1``).
    """
    t0 = time.perf_counter()
    pmin = np.ascontiguousarray(prim_min, np.float32)
    pmax = np.ascontiguousarray(prim_max, np.float32)
    n = pmin.shape[0]
    if n == 0:
        nodes = _pack_nodes(np.zeros((1, 3), np.float32), np.zeros((1, 3), np.float32), [0], [0])
        # an empty leaf that no ray can enter: min > max
        nodes[0, 0:3] = np.inf
        nodes[0, 4:7] = -np.inf
        nodes[0, 7] = np.int32(0).view(np.float32)
        return BVH(nodes, np.zeros(0, np.int32), 0, 0.0)
    # Sort primitives along a Morton curve first: the level loop gathers primitive data by
    # index, and spatially coherent indices make those gathers cache friendly (~2x faster).
    morton = None
    if n > 4096:
        morton = np.argsort(morton_codes((pmin + pmax) * np.float32(0.5)), kind="stable").astype(np.int32)
        pmin = pmin[morton]
        pmax = pmax[morton]
    cen = (pmin + pmax) * np.float32(0.5)
    pmin_c = [np.ascontiguousarray(pmin[:, a]) for a in range(3)]
    pmax_c = [np.ascontiguousarray(pmax[:, a]) for a in range(3)]
    cen_c = [np.ascontiguousarray(cen[:, a]) for a in range(3)]

    out_order = np.empty(n, np.int32)
    # Per level: the active primitives (grouped by node, nodes in id order) and their nodes.
    cur = np.arange(n, dtype=np.int32)  # primitive ids of active prims
    seg = np.zeros(n, dtype=np.int64)  # active-node slot of each active prim (non-decreasing)
    act_id = np.array([0], np.int64)  # node id of each active slot
    act_start = np.array([0], np.int64)  # first slot in out_order of each active node
    level_nodes = []  # (ids, bmin, bmax, left_or_first, count) per level
    next_id = 1
    depth = 0
    B = int(bins)
    while act_id.size:
        m = act_id.size
        cnt = np.bincount(seg, minlength=m).astype(np.int64)
        seg_first = np.concatenate([[0], np.cumsum(cnt)[:-1]])  # first position in `cur`
        # node bounds and centroid bounds
        nb_min = np.empty((m, 3), np.float32)
        nb_max = np.empty((m, 3), np.float32)
        cb_min = np.empty((m, 3), np.float32)
        cb_max = np.empty((m, 3), np.float32)
        for a in range(3):
            for arr, src, ufunc, init in ((nb_min, pmin_c, np.minimum, np.inf), (nb_max, pmax_c, np.maximum, -np.inf),
                                          (cb_min, cen_c, np.minimum, np.inf), (cb_max, cen_c, np.maximum, -np.inf)):
                col = np.full(m, init, np.float32)
                ufunc.at(col, seg, src[a][cur])
                arr[:, a] = col
        cext = cb_max - cb_min
        node_area = _half_area(nb_max - nb_min)

        # SAH over bins on every axis
        best_cost = np.full(m, np.inf, np.float64)
        best_axis = np.zeros(m, np.int64)
        best_split = np.zeros(m, np.int64)  # prims with bin < split go left
        # fewer bins when nodes are small (deep levels): the per-bin work is m * B
        Bl = int(min(B, max(4, 2 * int(np.ceil(cur.size / m)))))
        for a in range(3):
            ext = cext[:, a]
            scale = np.where(ext > 0, Bl / np.maximum(ext, 1e-30), 0.0).astype(np.float32)
            b = ((cen_c[a][cur] - cb_min[seg, a]) * scale[seg]).astype(np.int64)
            np.clip(b, 0, Bl - 1, out=b)
            key = b * m + seg  # (bin, node) layout: prefix sums run over contiguous rows of m
            bcnt = np.bincount(key, minlength=m * Bl).reshape(Bl, m)
            lcnt = np.cumsum(bcnt, axis=0)[:-1]
            rcnt = cnt[None, :] - lcnt
            lext, rext = [], []
            for k in range(3):
                col = np.full(m * Bl, np.inf, np.float32)
                np.minimum.at(col, key, pmin_c[k][cur])
                col = col.reshape(Bl, m)
                lo_l, lo_r = _prefix_suffix(col, np.minimum)
                col = np.full(m * Bl, -np.inf, np.float32)
                np.maximum.at(col, key, pmax_c[k][cur])
                col = col.reshape(Bl, m)
                hi_l, hi_r = _prefix_suffix(col, np.maximum)
                lext.append(hi_l - lo_l)
                rext.append(hi_r - lo_r)
            cost = _half_area3(lext) * lcnt + _half_area3(rext) * rcnt
            cost = np.where((lcnt > 0) & (rcnt > 0) & (ext[None, :] > 0), cost, np.inf)
            s_ = np.argmin(cost, axis=0)
            c = cost[s_, np.arange(m)]
            better = c < best_cost
            best_cost = np.where(better, c, best_cost)
            best_axis = np.where(better, a, best_axis)
            best_split = np.where(better, s_ + 1, best_split)

        # leaf or split?
        split_cost = COST_TRAVERSE + COST_INTERSECT * best_cost / np.maximum(node_area, 1e-30)
        leaf_cost = COST_INTERSECT * cnt
        has_sah = np.isfinite(best_cost)
        make_leaf = (cnt <= 1) | ((cnt <= max_leaf) & (~has_sah | (leaf_cost <= split_cost)))
        if depth >= max_depth:
            make_leaf[:] = True
        median = ~make_leaf & ~has_sah  # all centroids coincide: split by position in the list

        # record this level's nodes
        is_leaf = make_leaf
        n_split = int(np.count_nonzero(~is_leaf))
        left = np.zeros(m, np.int64)
        left[~is_leaf] = next_id + 2 * np.arange(n_split)
        lof = np.where(is_leaf, act_start, left).astype(np.int32)
        level_nodes.append((act_id, nb_min, nb_max, lof, np.where(is_leaf, cnt, 0).astype(np.int32)))
        next_id += 2 * n_split

        # write leaves' primitives to their final slots
        rank = np.arange(cur.size, dtype=np.int64) - seg_first[seg]
        leaf_prim = is_leaf[seg]
        out_order[(act_start[seg] + rank)[leaf_prim]] = cur[leaf_prim]
        if n_split == 0:
            break

        # partition the split nodes' primitives (stable, within each node's segment)
        keep = ~leaf_prim
        cur = cur[keep]
        seg_k = seg[keep]
        rank_k = rank[keep]
        ax = best_axis[seg_k]
        cvals = np.choose(ax, [cen_c[0][cur], cen_c[1][cur], cen_c[2][cur]])
        cmin_ax = cb_min[seg_k, ax]
        ext_ax = cext[seg_k, ax]
        scale = np.where(ext_ax > 0, Bl / np.maximum(ext_ax, 1e-30), 0.0).astype(np.float32)
        bk = np.clip(((cvals - cmin_ax) * scale).astype(np.int64), 0, Bl - 1)
        go_left = np.where(median[seg_k], rank_k < (cnt[seg_k] // 2), bk < best_split[seg_k])
        # new slot numbering: split nodes in order, children 2j (left) and 2j+1 (right)
        split_slot = np.cumsum(~is_leaf) - 1  # active slot -> index among split nodes
        j = split_slot[seg_k]
        # stable partition: order by (j, side) keeping relative order
        gl = go_left.astype(np.int64)
        cl = np.cumsum(gl)
        cr = np.cumsum(1 - gl)
        # per-segment starts in the compacted arrays
        kcnt = cnt[~is_leaf]
        kfirst = np.concatenate([[0], np.cumsum(kcnt)[:-1]])
        # counts of left/right before the segment start
        seg_begin = kfirst[j]
        cl_before = np.where(seg_begin > 0, cl[np.maximum(seg_begin - 1, 0)], 0)
        cr_before = np.where(seg_begin > 0, cr[np.maximum(seg_begin - 1, 0)], 0)
        nleft_seg = np.bincount(j, weights=gl, minlength=n_split).astype(np.int64)
        pos = np.where(go_left, seg_begin + (cl - cl_before) - 1,
                       seg_begin + nleft_seg[j] + (cr - cr_before) - 1)
        new_cur = np.empty_like(cur)
        new_cur[pos] = cur
        new_seg = np.empty_like(seg_k)
        new_seg[pos] = 2 * j + (1 - gl)
        split_start = act_start[~is_leaf]
        split_left = left[~is_leaf]
        act_id = np.empty(2 * n_split, np.int64)
        act_id[0::2] = split_left
        act_id[1::2] = split_left + 1
        act_start = np.empty(2 * n_split, np.int64)
        act_start[0::2] = split_start
        act_start[1::2] = split_start + nleft_seg
        cur, seg = new_cur, new_seg
        depth += 1

    total = next_id
    bmin = np.empty((total, 3), np.float32)
    bmax = np.empty((total, 3), np.float32)
    lof = np.empty(total, np.int32)
    cnts = np.empty(total, np.int32)
    for ids, a, b, l, c in level_nodes:
        bmin[ids] = a
        bmax[ids] = b
        lof[ids] = l
        cnts[ids] = c
    nodes = _pack_nodes(bmin, bmax, lof, cnts)
    if morton is not None:
        out_order = morton[out_order]
    return BVH(nodes, out_order, depth + 1, (time.perf_counter() - t0) * 1e3)


def triangle_bounds(positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """AABBs of a per-corner triangle soup ((3T, 3) -> two (T, 3))."""
    tri = np.asarray(positions, np.float32).reshape(-1, 3, 3)
    return tri.min(axis=1), tri.max(axis=1)


def build_blas(positions: np.ndarray, max_leaf: int = MAX_LEAF) -> BVH:
    lo, hi = triangle_bounds(positions)
    return build_bvh(lo, hi, max_leaf=max_leaf)


def positions_key(positions: np.ndarray, max_leaf: int = MAX_LEAF) -> str:
    """What a mesh's BLAS depends on: a hash of its corner positions (and the leaf size)."""
    a = np.ascontiguousarray(positions, np.float32)
    h = hashlib.blake2b(digest_size=16)
    h.update(f"{a.shape}:{max_leaf}".encode())
    h.update(a.tobytes())
    return h.hexdigest()


class BlasCache:
    """Process-wide least-recently-used store of per-mesh BLAS, keyed by ``positions_key``.
    Every session of a scene (F12, each viewport) shares a mesh's build, an edit of one mesh
    rebuilds that mesh only, and UV, normal or material edits rebuild none. A mesh's key is
    kept on the mesh object (``_gi_blas_key``), which the exporter hands back unchanged while
    its geometry is unchanged. Bounded by the triangles it holds (a BLAS costs about 70 bytes
    per triangle). GL thread only (not locked)."""

    def __init__(self, max_triangles: int = 4_000_000):
        self.max_triangles = int(max_triangles)
        self._items: OrderedDict = OrderedDict()  # key -> BVH
        self._triangles = 0
        self.hits = 0
        self.misses = 0

    def get(self, mesh, positions: np.ndarray, max_leaf: int = MAX_LEAF) -> BVH:
        key = getattr(mesh, "_gi_blas_key", None)
        if key is None or not key.endswith(f":{max_leaf}"):
            key = positions_key(positions, max_leaf) + f":{max_leaf}"
            try:
                mesh._gi_blas_key = key
            except AttributeError:  # a mesh type without attributes: hash every time
                pass
        bvh = self._items.get(key)
        if bvh is not None:
            self._items.move_to_end(key)
            self.hits += 1
            return bvh
        self.misses += 1
        bvh = build_blas(positions, max_leaf=max_leaf)
        n = len(bvh.prim_order)
        self._items[key] = bvh
        self._triangles += n
        while self._triangles > self.max_triangles and len(self._items) > 1:
            _, old = self._items.popitem(last=False)
            self._triangles -= len(old.prim_order)
        return bvh

    def clear(self) -> None:
        self._items.clear()
        self._triangles = 0


BLAS_CACHE = BlasCache()


def transform_aabb(lo: np.ndarray, hi: np.ndarray, matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World AABB of an object-space box under a 4x4 affine matrix (Arvo 1990)."""
    m = np.asarray(matrix, np.float64)
    c = (np.asarray(lo, np.float64) + hi) * 0.5
    e = (np.asarray(hi, np.float64) - lo) * 0.5
    wc = m[:3, :3] @ c + m[:3, 3]
    we = np.abs(m[:3, :3]) @ e
    return (wc - we).astype(np.float32), (wc + we).astype(np.float32)


# ------------------------------------------------------------------ the scene-level BVH
@dataclass
class SceneBVH:
    """Buffers for ``shaders/lib/bvh.glsl``: all BLAS concatenated, plus the TLAS.

    Build with :meth:`from_scene`; after instances move call :meth:`update_instances`
    (rebuilds only the TLAS and the instance records).
    """

    blas_nodes: np.ndarray  # (N, 8) float32
    verts: np.ndarray  # (3T, 4) float32: object-space position xyz, w = uv.y
    normals: np.ndarray  # (3T, 8) float32: corner normal xyz, uv.x, tangent xyz, bitangent sign
    colors: np.ndarray  # (3T, 4) float32: corner colour attribute (empty when no mesh has one)
    tri_info: np.ndarray  # (T, 2) int32: original triangle index in its mesh, material id
    mesh_root: np.ndarray  # (M,) int32 root node of each mesh's BLAS
    mesh_tri_offset: np.ndarray  # (M,) int32 first BVH-ordered triangle of each mesh
    mesh_bounds: list  # per mesh (lo, hi) object space
    tlas_nodes: np.ndarray = None  # (N, 8) float32
    instances: np.ndarray = None  # (I, 36) float32: w2o (16), o2w (16), ivec4 as bits
    material_map: np.ndarray = None  # int32
    blas_ms: float = 0.0
    tlas_ms: float = 0.0
    blas: list = field(default_factory=list)

    @classmethod
    def from_scene(cls, scene, max_leaf: int = MAX_LEAF) -> "SceneBVH":
        t0 = time.perf_counter()
        nodes, verts, normals, infos, roots, offs, bounds, blas_list = [], [], [], [], [], [], [], []
        colors = []
        any_colors = any(getattr(m, "colors", None) is not None for m in scene.meshes)
        node_base = 0
        tri_base = 0
        for mesh in scene.meshes:
            T = mesh.triangle_count
            pos = np.asarray(mesh.positions, np.float32).reshape(-1, 3)
            bvh = BLAS_CACHE.get(mesh, pos, max_leaf)
            blas_list.append(bvh)
            nd = bvh.nodes.copy()
            lof = nd[:, 3].view(np.int32)
            cnt = nd[:, 7].view(np.int32)
            lof += np.where(cnt > 0, tri_base, node_base).astype(np.int32)
            nodes.append(nd)
            roots.append(node_base)
            offs.append(tri_base)
            order = bvh.prim_order
            corner = (order[:, None] * 3 + np.arange(3)[None, :]).reshape(-1)
            v = np.zeros((3 * T, 4), np.float32)
            nrm = np.zeros((3 * T, 8), np.float32)
            if T:
                uv = np.asarray(mesh.uvs, np.float32).reshape(-1, 2)[corner]
                v[:, :3] = pos[corner]
                v[:, 3] = uv[:, 1]
                nrm[:, :3] = np.asarray(mesh.normals, np.float32).reshape(-1, 3)[corner]
                nrm[:, 3] = uv[:, 0]
                if getattr(mesh, "tangents", None) is not None:
                    nrm[:, 4:8] = np.asarray(mesh.tangents, np.float32).reshape(-1, 4)[corner]
            verts.append(v)
            normals.append(nrm)
            if any_colors:
                col = np.zeros((3 * T, 4), np.float32)
                if T and getattr(mesh, "colors", None) is not None:
                    col[:] = np.asarray(mesh.colors, np.float32).reshape(-1, 4)[corner]
                colors.append(col)
            info = np.zeros((T, 2), np.int32)
            info[:, 0] = order
            info[:, 1] = np.asarray(mesh.material_ids, np.int32)[order] if T else 0
            infos.append(info)
            bounds.append(mesh.bounds())
            node_base += nd.shape[0]
            tri_base += T
        cat = lambda xs, shape, dt: np.concatenate(xs) if xs else np.zeros(shape, dt)  # noqa: E731
        out = cls(
            blas_nodes=cat(nodes, (0, 8), np.float32),
            verts=cat(verts, (0, 4), np.float32),
            normals=cat(normals, (0, 8), np.float32),
            colors=cat(colors, (0, 4), np.float32),
            tri_info=cat(infos, (0, 2), np.int32),
            mesh_root=np.asarray(roots, np.int32),
            mesh_tri_offset=np.asarray(offs, np.int32),
            mesh_bounds=bounds,
            blas=blas_list,
        )
        out.blas_ms = (time.perf_counter() - t0) * 1e3
        out.update_instances(scene)
        return out

    def update_instances(self, scene) -> None:
        """Rebuild the TLAS and the instance records (cheap: O(instances))."""
        t0 = time.perf_counter()
        insts = [i for i in scene.instances if scene.meshes[i.mesh].triangle_count > 0]
        self._instance_ids = np.array([k for k, i in enumerate(scene.instances)
                                       if scene.meshes[i.mesh].triangle_count > 0], np.int32)
        n = len(scene.instances)
        rec = np.zeros((max(n, 1), 36), np.float32)
        mat_map = [np.zeros(1, np.int32)]
        map_base = 1
        lo = np.zeros((n, 3), np.float32)
        hi = np.zeros((n, 3), np.float32)
        for k, inst in enumerate(scene.instances):
            o2w = np.asarray(inst.matrix, np.float64)
            w2o = np.linalg.inv(o2w)
            # GLSL mat4 is column-major: store the transpose's rows = columns
            rec[k, 0:16] = w2o.T.reshape(-1)
            rec[k, 16:32] = o2w.T.reshape(-1)
            mo = -1
            if inst.material_map is not None and len(inst.material_map):
                mo = map_base
                mm = np.asarray(inst.material_map, np.int32)
                mat_map.append(mm)
                map_base += mm.size
            ints = np.array([self.mesh_root[inst.mesh], inst.mesh, mo, self.mesh_tri_offset[inst.mesh]], np.int32)
            rec[k, 32:36] = ints.view(np.float32)
            lo[k], hi[k] = transform_aabb(*self.mesh_bounds[inst.mesh], o2w)
        self.instances = rec
        self.material_map = np.concatenate(mat_map)
        valid = self._instance_ids
        if valid.size:
            t = build_bvh(lo[valid], hi[valid], max_leaf=1)
            nd = t.nodes.copy()
            cnt = nd[:, 7].view(np.int32)
            lof = nd[:, 3].view(np.int32)
            # leaves (one instance each): first -> the instance's index in scene.instances
            leaf = cnt > 0
            lof[leaf] = valid[t.prim_order[lof[leaf]]]
            self.tlas_nodes = nd
        else:
            nd = _pack_nodes(np.full((1, 3), np.inf, np.float32), np.full((1, 3), -np.inf, np.float32), [0], [0])
            self.tlas_nodes = nd
        self.tlas_ms = (time.perf_counter() - t0) * 1e3

    @property
    def triangle_count(self) -> int:
        return int(self.tri_info.shape[0])

    def buffers(self) -> dict[str, np.ndarray]:
        """name -> array for each SSBO of bvh.glsl (never empty: GL wants non-zero sizes)."""
        def nz(a, shape):
            return a if a.size else np.zeros(shape, a.dtype)

        return {
            "nodes": nz(self.blas_nodes, (1, 8)),
            "tlas": nz(self.tlas_nodes, (1, 8)),
            "verts": nz(self.verts, (1, 4)),
            "normals": nz(self.normals, (1, 8)),
            "colors": nz(self.colors, (1, 4)),
            "tri_info": nz(self.tri_info, (1, 2)),
            "instances": nz(self.instances, (1, 36)),
            "material_map": nz(self.material_map, (1,)),
        }


def check_invariants(bvh: BVH, prim_min: np.ndarray, prim_max: np.ndarray, tol: float = 0.0) -> None:
    """Raise AssertionError unless every primitive is in exactly one leaf and every child box
    lies inside its parent's box and every leaf box holds its primitives (tests use this)."""
    n = prim_min.shape[0]
    cnt = bvh.count
    lof = bvh.left_or_first
    leaf = cnt > 0
    covered = np.zeros(n, np.int64)
    for i in np.flatnonzero(leaf):
        s, c = lof[i], cnt[i]
        prims = bvh.prim_order[s:s + c]
        np.add.at(covered, prims, 1)
        assert np.all(prim_min[prims] >= bvh.bounds_min[i] - tol), f"leaf {i} does not bound its prims"
        assert np.all(prim_max[prims] <= bvh.bounds_max[i] + tol), f"leaf {i} does not bound its prims"
    assert np.all(covered == 1), "a primitive is in zero or several leaves"
    inner = np.flatnonzero(~leaf)
    for child in (lof[inner], lof[inner] + 1):
        assert np.all(child > inner), "child index must follow its parent"
        assert np.all(bvh.bounds_min[child] >= bvh.bounds_min[inner] - tol), "child box outside parent"
        assert np.all(bvh.bounds_max[child] <= bvh.bounds_max[inner] + tol), "child box outside parent"
    # every node reached exactly once from the root
    seen = np.zeros(bvh.node_count, np.int64)
    seen[0] += 1
    seen[lof[inner]] += 1
    seen[lof[inner] + 1] += 1
    assert np.all(seen == 1), "node graph is not a tree"
