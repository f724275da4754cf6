"""The scene on the GPU: vertex buffers, material/light/emitter buffers, textures.

Host side of the std430 structs declared in ``shaders/lib/common.glsl`` (keep in step).
Uploads are incremental: a mesh's vertex buffer is kept while its content hash is the
same (the hash is cached on the ``Mesh`` object, so an exporter that hands back the same
``Mesh`` for unchanged geometry costs no hashing), so moving an object or editing a light
re-uploads only small buffers, and ``update`` reports it as ``transforms`` / ``lights``.
"""
from __future__ import annotations

import hashlib
import logging
import time

import numpy as np

from .scene_data import AreaShape, LightType, SceneData, SceneError
from .shaders import bind_tables
from .world_map import WorldGPU

log = logging.getLogger(__name__)

# One source of truth for the layouts (floats per record); see common.glsl.
MATERIAL_FLOATS = 72  # 6 vec4 of values, one vec4 per texture map (MATERIAL_MAPS order), coat and sheen 3 vec4
LIGHT_FLOATS = 28
EMITTER_FLOATS = 16
LIGHT_MESH = 4
MAX_TEXTURE_SIZE = 2048
MAX_EMITTERS = 1 << 16
# Vertex layout: position 3, normal 3, uv 2, material id 1 (float, exact below 2^24),
# tangent 4 (xyz, bitangent sign; zero when the mesh has no normal-mapped material),
# colour 4 (the colour attribute a material reads; zero when none).
VERTEX_FORMAT = "3f 3f 2f 1f 4f 4f"
VERTEX_ATTRS = ("in_position", "in_normal", "in_uv", "in_material", "in_tangent", "in_color")
VERTEX_FLOATS = 17
_EXTENSIONS = {"REPEAT": 0, "EXTEND": 1, "CLIP": 2, "MIRROR": 3}
# A buffer bigger than this is refused with a clear message rather than crashing the driver.
MAX_VERTEX_BYTES = 2 << 30


def set_uniform(prog, name: str, value):
    """Set a uniform if the program uses it (inactive uniforms are optimised away)."""
    try:
        u = prog[name]
    except KeyError:
        return
    if isinstance(value, np.ndarray):
        if value.ndim == 2:  # numpy row-major -> GLSL column-major
            u.write(np.ascontiguousarray(value.T, dtype=np.float32).tobytes())
        else:
            u.value = tuple(float(x) for x in value)
    else:
        u.value = value


def _mesh_key(mesh, material_map) -> str:
    h = hashlib.blake2b(digest_size=16)
    for arr in (mesh.positions, mesh.normals, mesh.uvs, mesh.material_ids,
                mesh.tangents if mesh.tangents is not None else np.zeros(0, np.float32),
                mesh.colors if getattr(mesh, "colors", None) is not None else np.zeros(0, np.float32)):
        a = np.ascontiguousarray(arr)
        h.update(str(a.shape).encode())
        h.update(a.tobytes())
    if material_map is not None:
        h.update(np.ascontiguousarray(material_map, np.int32).tobytes())
    return h.hexdigest()


def layer_size(pixels: np.ndarray) -> tuple[int, int]:
    """(width, height) an image keeps in the texture array (resized only beyond the limit)."""
    return min(MAX_TEXTURE_SIZE, int(pixels.shape[1])), min(MAX_TEXTURE_SIZE, int(pixels.shape[0]))


def pack_map(scene: SceneData, ref) -> np.ndarray:
    """One texture map of a material record (common.glsl ``Material.maps``): layer (-1 none),
    width * 4096 + height of its image in the layer, flags (channel + 1 | Closest << 3 |
    extension << 4), scale."""
    from .scene_data import VERTEX_COLOR
    if ref is not None and ref.texture == VERTEX_COLOR:
        return np.array([VERTEX_COLOR, 0.0, ref.channel + 1, ref.scale], np.float32)
    if ref is None or not (0 <= ref.texture < len(scene.textures)):
        return np.array([-1.0, 0.0, 0.0, 1.0], np.float32)
    w, h = layer_size(scene.textures[ref.texture].pixels)
    flags = (ref.channel + 1) | ((1 if ref.interpolation == "Closest" else 0) << 3) | \
        (_EXTENSIONS.get(ref.extension, 0) << 4)
    return np.array([ref.texture, w * 4096 + h, flags, ref.scale], np.float32)


def _pack_record(scene: SceneData, m, out: np.ndarray, first_lobe: int = -1) -> None:
    from .scene_data import BSDF_KINDS, MATERIAL_MAPS, TexRef

    maps = dict(m.maps)
    if "base_color" not in maps and m.base_color_texture >= 0:
        maps["base_color"] = TexRef(m.base_color_texture)
    out[0:3] = m.base_color
    out[3] = maps["base_color"].texture if "base_color" in maps else -1
    out[4:8] = (m.metallic, m.roughness, m.ior, m.specular_ior_level)
    out[8:11] = m.emission
    out[11] = m.alpha
    out[12:15] = m.specular_tint
    out[15] = 1.0 if m.exact else 0.0
    out[16:20] = (BSDF_KINDS.index(m.bsdf), m.transmission, m.weight, 1.0 if m.transmits else 0.0)
    out[20:24] = (first_lobe, len(m.lobes) if first_lobe >= 0 else 0, m.bump_strength if "bump" in maps else 0.0,
                  1.0 if m.bump_correction else 0.0)
    for k, key in enumerate(MATERIAL_MAPS):
        out[24 + 4 * k:28 + 4 * k] = pack_map(scene, maps.get(key))
    c = 24 + 4 * len(MATERIAL_MAPS)
    out[c:c + 4] = (m.coat_weight, m.coat_roughness, m.coat_ior, 0.0)
    out[c + 4:c + 8] = (*m.coat_tint, m.sheen_weight)
    out[c + 8:c + 12] = (*m.sheen_tint, m.sheen_roughness)


def pack_materials(scene: SceneData) -> np.ndarray:
    """One record per material (common.glsl ``Material``), the default material at index
    len(materials), then the lobe records of the materials that have lobes."""
    from .scene_data import MATERIAL_MAPS, MAX_LOBES

    n = max(1, len(scene.materials))
    n_lobes = sum(min(len(m.lobes), MAX_LOBES) for m in scene.materials)
    out = np.zeros((n + 1 + n_lobes, MATERIAL_FLOATS), np.float32)
    nxt = n + 1
    for i, m in enumerate(scene.materials):
        lobes = m.lobes[:MAX_LOBES]
        _pack_record(scene, m, out[i], nxt if lobes else -1)
        for lobe in lobes:
            _pack_record(scene, lobe, out[nxt])
            nxt += 1
    # the default material at the end (for material id -1 and out-of-range ids)
    out[n, 0:4] = (0.8, 0.8, 0.8, -1)
    out[n, 4:8] = (0.0, 0.5, 1.5, 0.5)
    out[n, 11] = 1.0
    out[n, 12:16] = (1, 1, 1, 1)
    out[n, 16:24] = (0, 0, 1, 0, -1, 0, 0, 0)
    for k in range(len(MATERIAL_MAPS)):
        out[n, 24 + 4 * k:28 + 4 * k] = (-1.0, 0.0, 0.0, 1.0)
    return out


def has_alpha(scene: SceneData) -> bool:
    """Does any material cut holes (Alpha < 1 or an alpha texture)?"""
    return any(m.alpha < 1.0 or "alpha" in m.maps for m in scene.materials)


def spot_params(light) -> tuple[float, float]:
    """Cycles' spot cone: cos of the half angle and the smoothstep scale 1/((1-cos)*blend)."""
    cos_half = float(np.cos(0.5 * light.spot_size))
    denom = (1.0 - cos_half) * float(light.spot_blend)
    smooth = 1.0 / denom if denom > 1e-8 else 1e8
    return cos_half, smooth


def pack_lights(scene: SceneData, emitters: "EmitterSet") -> np.ndarray:
    """Lights, then one LIGHT_MESH record per emissive instance."""
    recs = []
    for idx, L in enumerate(scene.lights):
        r = np.zeros(LIGHT_FLOATS, np.float32)
        r[0:3] = L.position
        r[3] = int(L.type)
        r[4:7] = L.direction
        r[8:11] = L.color
        r[11] = L.power
        r[27] = 0.0
        if L.type in (LightType.POINT, LightType.SPOT):
            r[7] = L.radius
        if L.type == LightType.SUN:
            r[7] = 0.5 * L.angle
        if L.type == LightType.SPOT:
            m3 = np.asarray(L.matrix, np.float64)[:3, :3]
            try:
                inv = np.linalg.inv(m3)
            except np.linalg.LinAlgError:
                raise SceneError(f"Light '{L.name}' has a degenerate transform (zero scale)") from None
            cos_half, smooth = spot_params(L)
            r[12:15] = inv[0]
            r[15] = cos_half
            r[16:19] = inv[1]
            r[19] = smooth
            r[20:23] = inv[2]
        if L.type == LightType.AREA:
            u, v = L.area_axes()
            r[12:15] = u
            r[15] = int(L.shape)
            r[16:19] = v
            r[19] = L.area()
        r[23] = 1.0 if L.cast_shadow else 0.0
        r[26] = 1.0  # views per shadow origin (set by the shadow pass)
        recs.append(r)
    for g in emitters.groups:
        r = np.zeros(LIGHT_FLOATS, np.float32)
        r[0:3] = g["center"]
        r[3] = LIGHT_MESH
        r[8:11] = g["radiance_max"]
        r[11] = g["power"]
        r[20] = g["first"]
        r[21] = g["count"]
        r[23] = 1.0
        r[26] = 6.0
        r[27] = float(np.sum(g["areas"]))
        recs.append(r)
    if not recs:
        return np.zeros((1, LIGHT_FLOATS), np.float32)
    return np.stack(recs)


class EmitterSet:
    """Emissive triangles in world space, grouped per instance (one mesh light each)."""

    def __init__(self, scene: SceneData):
        emissive = np.array([m.is_emissive for m in scene.materials] + [False], bool)
        radiance = np.array([m.emission for m in scene.materials] + [np.zeros(3)], np.float32).reshape(-1, 3)
        rows, groups = [], []
        total = 0
        self.truncated = False
        for ii, inst in enumerate(scene.instances):
            mesh = scene.meshes[inst.mesh]
            mids = mesh.material_ids
            if inst.material_map is not None and mids.size:
                mids = np.asarray(inst.material_map)[np.clip(mids, 0, len(inst.material_map) - 1)]
            mids = np.where((mids < 0) | (mids >= len(scene.materials)), len(scene.materials), mids)
            sel = np.nonzero(emissive[mids])[0]
            if sel.size == 0:
                continue
            if total + sel.size > MAX_EMITTERS:
                self.truncated = True
                sel = sel[: max(0, MAX_EMITTERS - total)]
                if sel.size == 0:
                    break
            tri = mesh.positions.reshape(-1, 3, 3)[sel].astype(np.float64)
            M = inst.matrix.astype(np.float64)
            w = tri @ M[:3, :3].T + M[:3, 3]
            e1, e2 = w[:, 1] - w[:, 0], w[:, 2] - w[:, 0]
            area = 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1)
            rad = radiance[mids[sel]]
            power = area * rad.mean(axis=1) * np.pi
            cdf = np.cumsum(power)
            cdf = cdf / cdf[-1] if cdf[-1] > 0 else np.linspace(1.0 / len(cdf), 1.0, len(cdf))
            rec = np.zeros((sel.size, EMITTER_FLOATS), np.float32)
            rec[:, 0:3] = w[:, 0]
            rec[:, 3] = area
            rec[:, 4:7] = w[:, 1]
            rec[:, 7] = ii
            rec[:, 8:11] = w[:, 2]
            rec[:, 11] = cdf
            rec[:, 12:15] = rad
            rec[:, 15] = power
            groups.append({
                "instance": ii, "object": inst.object_name, "first": total, "count": int(sel.size),
                "center": w.reshape(-1, 3).mean(axis=0), "power": float(power.sum()),
                "radiance_max": rad.max(axis=0), "triangles": w, "areas": area,
            })
            rows.append(rec)
            total += sel.size
        self.groups = groups
        self.array = np.concatenate(rows) if rows else np.zeros((1, EMITTER_FLOATS), np.float32)
        self.count = total


def _resize(img: np.ndarray, w: int, h: int) -> np.ndarray:
    """Bilinear resize of (H, W, 4) float32 (numpy, separable)."""
    H, W = img.shape[:2]
    if (H, W) == (h, w):
        return img
    ys = (np.arange(h) + 0.5) * H / h - 0.5
    xs = (np.arange(w) + 0.5) * W / w - 0.5
    y0 = np.clip(np.floor(ys).astype(int), 0, H - 1)
    x0 = np.clip(np.floor(xs).astype(int), 0, W - 1)
    y1 = np.clip(y0 + 1, 0, H - 1)
    x1 = np.clip(x0 + 1, 0, W - 1)
    fy = np.clip(ys - y0, 0, 1)[:, None, None]
    fx = np.clip(xs - x0, 0, 1)[None, :, None]
    top = img[y0][:, x0] * (1 - fx) + img[y0][:, x1] * fx
    bot = img[y1][:, x0] * (1 - fx) + img[y1][:, x1] * fx
    return (top * (1 - fy) + bot * fy).astype(np.float32)


class GPUScene:
    """Scene buffers of one GL context. Call ``update(scene)`` each frame; cheap when unchanged."""

    def __init__(self, ctx):
        self.ctx = ctx
        self._vbos: dict[str, tuple] = {}  # key -> (vbo, vertex count)
        self._vaos: dict = {}
        self.draws: list[tuple] = []  # (key, model matrix, normal matrix, instance id)
        self.material_buf = None
        self.light_buf = None
        self.light_prev_buf = None  # last update's lights (see update)
        self._light_prev_stale = False
        self.light_array = None  # the packed lights of the last update
        self.emitter_buf = None
        self.textures = None
        self.world = WorldGPU(ctx)
        self.scene: SceneData | None = None
        self.emitters: EmitterSet | None = None
        self.light_count = 0
        self.emitter_count = 0
        self.prev_matrices: dict[str, np.ndarray] = {}  # instance id -> matrix at the last update
        self.matrices: dict[str, np.ndarray] = {}  # instance id -> current matrix
        self._motion_pending = False  # prev_matrices not yet drawn by a G-buffer frame
        self._fp = {}
        self.version = 0  # bumps on any change (history invalidation)
        # per kind of change (update()'s keys): bumps when that part changed, so a cache can
        # depend on only what it reads (VXGI's voxels: geometry, transforms, materials, textures)
        self.versions = {"geometry": 0, "transforms": 0, "materials": 0, "lights": 0, "light_set": 0, "textures": 0}
        self.setup_ms = 0.0  # one-time work (BVH builds, uploads) done for this scene so far, in ms

    # ------------------------------------------------------------------ upload
    def update(self, scene: SceneData) -> dict:
        """Bring the buffers up to ``scene`` (:meth:`_update`); the time of an update that
        uploaded something is one-time work (``setup_ms``), that of the check alone is not."""
        t0 = time.perf_counter()
        bvh0 = self.setup_ms
        changes = self._update(scene)
        if any(changes.values()):
            # BVH builds inside the update already added their own time
            self.setup_ms = bvh0 + max((time.perf_counter() - t0) * 1e3, self.setup_ms - bvh0)
        return changes

    def _update(self, scene: SceneData) -> dict:
        """Bring the buffers up to ``scene``; returns which parts changed (the frame graph's
        scene-edit events, ``framegraph.SCENE_EDITS``): ``geometry`` (a mesh was added,
        removed or its vertex data changed, or instances were added/removed), ``transforms``
        (only instance matrices changed: nothing is re-uploaded but the matrices),
        ``materials``, ``lights``, ``light_set`` (which lights there are; see
        ``framegraph.LIGHT_SET``), ``textures``.

        Motion: the previous matrices are kept per instance id (``SceneData.instance_ids``),
        so every instance of one object, moving on its own, gets its own motion vectors.
        An instance new since the last update has no previous transform (no motion)."""
        changes = {"geometry": False, "transforms": False, "materials": False, "lights": False,
                   "light_set": False, "textures": False}
        # geometry
        keys = []
        needed = set()
        total_bytes = 0
        for inst in scene.instances:
            mesh = scene.meshes[inst.mesh]
            key = getattr(mesh, "_gi_key", None)
            if key is None or inst.material_map is not None:
                key = _mesh_key(mesh, inst.material_map)
                if inst.material_map is None:
                    mesh._gi_key = key
            keys.append(key)
            if key not in needed:
                total_bytes += mesh.positions.shape[0] * 4 * VERTEX_FLOATS
            needed.add(key)
        if total_bytes > MAX_VERTEX_BYTES:
            raise SceneError(
                f"The scene needs {total_bytes / 2**30:.1f} GiB of vertex data, more than GI Preview "
                f"uploads at once ({MAX_VERTEX_BYTES / 2**30:.0f} GiB): reduce the triangle count "
                f"(e.g. lower Subdivision levels) or hide objects from rendering.")
        for inst, key in zip(scene.instances, keys):
            if key in self._vbos:
                continue
            mesh = scene.meshes[inst.mesh]
            mids = mesh.material_ids.astype(np.int64)
            if inst.material_map is not None and mids.size:
                mids = np.asarray(inst.material_map)[np.clip(mids, 0, len(inst.material_map) - 1)]
            mids = np.where((mids < 0) | (mids >= len(scene.materials)), len(scene.materials), mids)
            n = mesh.positions.shape[0]
            data = np.zeros((n, VERTEX_FLOATS), np.float32)
            data[:, 0:3] = mesh.positions
            data[:, 3:6] = mesh.normals
            data[:, 6:8] = mesh.uvs if mesh.uvs.shape[0] == n else 0.0
            data[:, 8] = np.repeat(mids, 3).astype(np.float32)
            if mesh.tangents is not None and mesh.tangents.shape[0] == n:
                data[:, 9:13] = mesh.tangents
            cols = getattr(mesh, "colors", None)
            if cols is not None and cols.shape[0] == n:
                data[:, 13:17] = cols
            try:
                vbo = self.ctx.buffer(data.tobytes()) if n else None
            except Exception as exc:
                raise SceneError(f"Mesh '{mesh.name}' ({mesh.triangle_count} triangles) does not fit in GPU "
                                 f"memory: {exc}") from None
            self._vbos[key] = (vbo, n)
            changes["geometry"] = True
        for key in list(self._vbos):
            if key not in needed:
                vbo, _ = self._vbos.pop(key)
                if vbo is not None:
                    vbo.release()
                for vk in [k for k in self._vaos if k[0] == key]:
                    self._vaos.pop(vk).release()
                changes["geometry"] = True
        draws = []
        mats = {}
        for inst, key, iid in zip(scene.instances, keys, scene.instance_ids()):
            M = inst.matrix.astype(np.float64)
            try:
                nm = np.linalg.inv(M[:3, :3]).T
            except np.linalg.LinAlgError:
                nm = np.eye(3)
            draws.append((key, M.astype(np.float32), nm.astype(np.float32), iid))
            mats[iid] = M.astype(np.float32)
        if [(d[0], d[3]) for d in draws] != [(d[0], d[3]) for d in self.draws]:
            changes["geometry"] = True  # instances added, removed, reordered or re-meshed
        elif any(a[1].tobytes() != b[1].tobytes() for a, b in zip(draws, self.draws)):
            changes["transforms"] = True
        # motion: previous = the matrices of the last update (per instance id)
        self.prev_matrices = self.matrices
        self.draws = draws
        self.matrices = mats
        self._motion_pending = True

        # materials and textures
        mat = pack_materials(scene)
        fp_m = hashlib.blake2b(mat.tobytes(), digest_size=16).hexdigest()
        if fp_m != self._fp.get("materials"):
            self._replace("material_buf", mat)
            self._fp["materials"] = fp_m
            changes["materials"] = True
        tex_fp = hashlib.blake2b(b"".join(np.ascontiguousarray(t.pixels[::7, ::7]).tobytes() + str(t.pixels.shape).encode()
                                          for t in scene.textures), digest_size=16).hexdigest()
        if tex_fp != self._fp.get("textures") or self.textures is None:
            self._upload_textures(scene)
            self._fp["textures"] = tex_fp
            changes["textures"] = True

        # lights and emitters (depend on instance transforms too)
        self.emitters = EmitterSet(scene)
        lights = pack_lights(scene, self.emitters)
        fp_l = hashlib.blake2b(lights.tobytes() + self.emitters.array.tobytes(), digest_size=16).hexdigest()
        # last frame's lights (light_prev_buf): what RESTIR_DI's reuse weights after a light edit
        # are evaluated with; written when the lights change and once more the update after
        prev = self.light_array
        if fp_l != self._fp.get("lights") or self._light_prev_stale or self.light_prev_buf is None:
            self._replace("light_prev_buf", lights if prev is None or prev.shape != lights.shape else prev)
            self._light_prev_stale = fp_l != self._fp.get("lights")
        if fp_l != self._fp.get("lights"):
            self._replace("light_buf", lights)
            self._replace("emitter_buf", self.emitters.array)
            self._fp["lights"] = fp_l
            changes["lights"] = True
        # which lights there are, by index: what light-relative samples (RESTIR_DI) refer to
        fp_set = hashlib.blake2b(repr(([(L.name, int(L.type), L.radius > 0.0, 0.5 * L.angle > 1e-6) for L in scene.lights],
                                       [(g["instance"], g["count"]) for g in self.emitters.groups])).encode(),
                                 digest_size=16).hexdigest()
        if fp_set != self._fp.get("light_set"):
            self._fp["light_set"] = fp_set
            changes["light_set"] = changes["lights"] = True
        if self.world.update(scene.world):
            changes["lights"] = changes["light_set"] = True  # the world is a light (its map and sampling tables)
        self.light_count = len(scene.lights) + len(self.emitters.groups)
        self.emitter_count = self.emitters.count
        self.light_array = lights
        self.scene = scene
        if any(changes.values()):
            self.version += 1
        for k, v in changes.items():
            self.versions[k] += int(bool(v))
        return changes

    def _replace(self, attr: str, array: np.ndarray):
        old = getattr(self, attr)
        data = np.ascontiguousarray(array, np.float32).tobytes()
        if old is not None and old.size == len(data):
            old.write(data)
            return
        if old is not None:
            old.release()
        setattr(self, attr, self.ctx.buffer(data))

    def _upload_textures(self, scene: SceneData):
        """One RGBA16F array layer per texture, as large as the largest image; each image sits
        unscaled at the layer's origin (its own size travels in the material record, and
        textures.glsl wraps and interpolates within it), so no image is resampled unless it
        exceeds MAX_TEXTURE_SIZE."""
        if self.textures is not None:
            self.textures.release()
        import moderngl

        if not scene.textures:
            # the same format and filter as a real array: a driver that specialises a program on
            # the texture formats bound (Mesa's llvmpipe) then compiles it once for both
            self.textures = self.ctx.texture_array((1, 1, 1), 4, np.ones(4, np.float16).tobytes(), dtype="f2")
            self.textures.filter = (moderngl.NEAREST, moderngl.NEAREST)
            return
        sizes = [layer_size(t.pixels) for t in scene.textures]
        w = max(s[0] for s in sizes)
        h = max(s[1] for s in sizes)
        data = np.zeros((len(sizes), h, w, 4), np.float16)
        for i, (t, (tw, th)) in enumerate(zip(scene.textures, sizes)):
            data[i, :th, :tw] = _resize(np.asarray(t.pixels, np.float32), tw, th)
        tex = self.ctx.texture_array((w, h, len(sizes)), 4, data.tobytes(), dtype="f2")
        tex.filter = (moderngl.NEAREST, moderngl.NEAREST)  # sampled with texelFetch only
        self.textures = tex

    # ------------------------------------------------------------------ use
    def bind(self, prog, texture_unit: int = 0):
        """Bind the scene buffers (bindings from common.glsl) and the texture array."""
        self.material_buf.bind_to_storage_buffer(0)
        self.light_buf.bind_to_storage_buffer(1)
        self.emitter_buf.bind_to_storage_buffer(2)
        self.textures.use(texture_unit)
        set_uniform(prog, "u_textures", texture_unit)
        set_uniform(prog, "u_light_count", self.light_count)
        set_uniform(prog, "u_emitter_count", self.emitter_count)
        set_uniform(prog, "u_material_count", len(self.scene.materials) if self.scene else 0)
        set_uniform(prog, "u_alpha_test", 1 if self.scene is not None and has_alpha(self.scene) else 0)
        if self.scene is not None:
            self.world.bind(prog, self.scene.world, self.scene.film_transparent)
        bind_tables(self.ctx, prog)  # the BRDF tables' unit, should anything have taken it

    def vao(self, key: str, prog):
        vk = (key, prog.glo)
        vao = self._vaos.get(vk)
        if vao is None:
            vbo, _ = self._vbos[key]
            attrs = [a for a in VERTEX_ATTRS if a in prog]
            fmt = " ".join(f if a in attrs else f"{f[0]}x4" for f, a in zip(VERTEX_FORMAT.split(), VERTEX_ATTRS))
            vao = self.ctx.vertex_array(prog, [(vbo, fmt, *attrs)])
            self._vaos[vk] = vao
        return vao

    def draw(self, prog, *, prev: bool = False):
        """Draw every instance with ``u_model``/``u_normal_matrix``; with ``prev`` (the
        G-buffer's motion vectors) also ``u_prev_model``, the instance's matrix at the last
        update (keyed by instance id; its current matrix when it is new).

        The motion of an update belongs to the first frame drawn after it: once a ``prev``
        draw has run, later frames of the same render (accumulation samples) see every
        instance at rest, as the camera's previous view is the last frame's."""
        for key, M, NM, iid in self.draws:
            vbo, n = self._vbos[key]
            if not n:
                continue
            set_uniform(prog, "u_model", M)
            set_uniform(prog, "u_normal_matrix", NM)
            if prev:
                set_uniform(prog, "u_prev_model", self.prev_matrices.get(iid, M) if self._motion_pending else M)
            self.vao(key, prog).render(vertices=n)
        if prev:
            self._motion_pending = False

    def rt(self):
        """The scene ray-tracing component (``rt_scene.SceneRT``) of this GPU scene, built on
        first use and brought up to date with the last ``update()``: every pass and graph of a
        session shares it (one BVH). Raises SceneError when the scene cannot be ray traced."""
        rt = getattr(self, "_rt", None)
        if rt is None:
            from .rt_scene import SceneRT

            rt = self._rt = SceneRT(self)
        from .framegraph import _graph_op

        # scene data built or uploaded on first use belongs to the scene, not to the pass
        # that happened to ask first (sync validation would see the next pass that traces
        # rays use buffers that pass "wrote")
        with _graph_op():
            return rt.update()

    def release(self):
        rt = getattr(self, "_rt", None)
        if rt is not None:
            rt.release()
            self._rt = None
        for vao in self._vaos.values():
            vao.release()
        for vbo, _ in self._vbos.values():
            if vbo is not None:
                vbo.release()
        for attr in ("material_buf", "light_buf", "light_prev_buf", "emitter_buf", "textures"):
            obj = getattr(self, attr)
            if obj is not None:
                obj.release()
                setattr(self, attr, None)
        self.world.release()
        self._vaos.clear()
        self._vbos.clear()
        self._fp.clear()
