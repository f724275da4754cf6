"""Shadow atlas: one R32F atlas holding every shadow view of every light.

Views: one perspective view for a spot light whose cone is at most 120 degrees, six cube
faces for point, wider spot, area and mesh lights, and cascades (orthographic, fitted to slices of the camera frustum) for sun
lights, whose direction is sampled inside the sun's disk each frame. The shading side is
``shaders/lib/shadows.glsl``; the view record layout is ``ShadowView`` in common.glsl.
A light with size gets ``light_samples`` shadow origins per frame (points on the light, or
directions in the sun's disk; the first frame's first origin is the centre), each with its
own views; the shading side averages their visibilities weighted by each origin's geometry
term, so unoccluded points are exact from the first frame and penumbrae converge as frames
accumulate.

Each atlas tile remembers the view it holds: a view that is the same as last frame's in the
same tile (a light without size, a sun seen from a still camera) is not drawn again while the
scene is unchanged, so only the views that move (points on lights with size, the world's
directions) cost raster time each frame. Scenes whose materials cut holes redraw every view:
their shadows average a different stochastic alpha pattern each frame. Cube faces of a
one-sided area light that look only behind it are left empty (they read as unlit, which the
light's own cosine makes exact).

Of the lights within the budget, those with size whose moving views would cost more raster
time per frame than tracing their shadows (``ray_cost_texels``: a ray counted as that many map
texels; the readers' rays per pixel, times the image's pixels) get no views but rays of their
own (``ShadowSelection.traced``, ``Light.shadow.x`` = -1), provided every pass that reads the
maps traces shadows (``shadow_rays_per_pixel``; VXGI's injection does not).
"""
from __future__ import annotations

import math

import numpy as np

from ..framegraph import BUFFER, HOST, PREV, Effect, Param, Pass, Res
from ..gpu_scene import LIGHT_MESH, set_uniform
from ..scene_data import LightType
from ..world_map import halton, world_light_directions
from .light_cull import LIGHT_CULL, TILE_BOUNDS, scores_from_bounds

ATLAS, VIEWS, WORLD_RANGE = "shadow.atlas", "shadow.views", "shadow.world_range"
SCENE_LIGHTS = "scene.lights"  # the GPU scene's light buffer: the pass writes each light's view range
SHADOW_SELECTION = "shadow.selection"


class ShadowSelection:
    """Which lights got shadow maps this frame (a host resource): ``mapped`` and ``unmapped``
    light indices (shadow-casting point, spot, area and mesh lights; suns are always mapped),
    the ``budget`` and the ``frame`` (FrameState) it was made for."""

    def __init__(self, frame=None, mapped=(), unmapped=(), budget: int = 0, traced=()):
        self.frame, self.mapped, self.unmapped, self.budget = frame, list(mapped), list(unmapped), budget
        # of ``unmapped``: the lights with size left to ray tracing because their moving views
        # would cost more raster time than the rays (the rest of ``unmapped`` is over the budget)
        self.traced = list(traced)

    def release(self):
        pass


class WorldRange:
    """(first, count) of this frame's world-light views in the view table (a resource)."""

    def __init__(self, first: int = 0, count: int = 0):
        self.first, self.count = first, count


def world_light_range(rc) -> tuple[int, int]:
    """(first, count) of the world views DIRECT lights the world through this frame; (0, 0)
    when it does not (no world views, or a black world): then its aov.world_spec is 0."""
    wr = rc.resources.get(WORLD_RANGE)
    if wr is None or wr.count <= 0 or float(max(rc.scene.scene.world.color)) <= 0:
        return 0, 0
    return int(wr.first), int(wr.count)

    def release(self):
        pass
VIEW_FLOATS = 32
MAX_ATLAS = 8192


def _single_view(L) -> bool:
    """A spot light whose cone fits one perspective view (at most 120 degrees)."""
    return L.type == LightType.SPOT and L.spot_size <= math.radians(120.0)


def perspective(fov: float, near: float, far: float) -> np.ndarray:
    f = 1.0 / math.tan(fov / 2)
    return np.array([[f, 0, 0, 0], [0, f, 0, 0],
                     [0, 0, (far + near) / (near - far), 2 * far * near / (near - far)],
                     [0, 0, -1, 0]], np.float64)


def ortho(half: float, near: float, far: float) -> np.ndarray:
    return np.array([[1 / half, 0, 0, 0], [0, 1 / half, 0, 0],
                     [0, 0, -2 / (far - near), -(far + near) / (far - near)], [0, 0, 0, 1]], np.float64)


def look_at(eye, forward, up) -> np.ndarray:
    f = np.asarray(forward, np.float64)
    f = f / np.linalg.norm(f)
    up = np.asarray(up, np.float64)
    if abs(np.dot(f, up)) > 0.99:
        up = np.array([1.0, 0.0, 0.0]) if abs(f[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    s = np.cross(f, up)
    s /= np.linalg.norm(s)
    u = np.cross(s, f)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = s, u, -f
    m[:3, 3] = -m[:3, :3] @ np.asarray(eye, np.float64)
    return m


def world_view(center, radius: float, d) -> tuple[np.ndarray, np.ndarray]:
    """An orthographic view of the world light travelling along ``d`` over the scene's
    bounding sphere (``center``, ``radius``): (view-projection, eye). The world's shadow maps
    (DIRECT) and its reflective shadow maps (RSM) both look this way; the map's side is
    2 x 1.02 x radius."""
    eye = np.asarray(center, np.float64) - np.asarray(d, np.float64) * (2.0 * radius)
    return ortho(radius * 1.02, 0.0, 4.0 * radius) @ look_at(eye, d, (0, 0, 1)), eye


CUBE_DIRS = [((1, 0, 0), (0, 0, 1)), ((-1, 0, 0), (0, 0, 1)), ((0, 1, 0), (0, 0, 1)),
             ((0, -1, 0), (0, 0, 1)), ((0, 0, 1), (0, 1, 0)), ((0, 0, -1), (0, 1, 0))]


def _behind_area_light(scene, li, vp: np.ndarray, origin, normal) -> bool:
    """Does this perspective view of light ``li`` (an area light, one-sided along ``normal``)
    look only behind the light? Every direction of the view's frustum is a positive
    combination of its four corner rays, so checking the corners decides it."""
    if not isinstance(li, int) or li >= len(scene.lights) or scene.lights[li].type != LightType.AREA:
        return False
    n = np.asarray(normal, np.float64)
    if not np.any(n):
        return False
    inv = np.linalg.inv(np.asarray(vp, np.float64))
    o = np.asarray(origin, np.float64)
    for x in (-1.0, 1.0):
        for y in (-1.0, 1.0):
            w = inv @ np.array([x, y, 1.0, 1.0])
            if float(np.dot(w[:3] / w[3] - o, n)) > 0.0:
                return False
    return True


def first_frame_scores(gpu_scene, camera_position, indices, info: dict | None = None) -> np.ndarray:
    """The budget's ranking without tile bounds: peak intensity (W/sr; light_cull.light_ranges'
    ``intensity`` when known, else the light's colour) over the squared distance to the camera."""
    idx = np.asarray(list(indices), int)
    arr = gpu_scene.light_array
    cam = np.asarray(camera_position, np.float64)
    d2 = np.sum((arr[idx, 0:3].astype(np.float64) - cam) ** 2, axis=1)
    if info is not None and len(info["intensity"]) > int(idx.max(initial=-1)):
        inten = np.asarray(info["intensity"], np.float64)[idx]
    else:
        inten = np.max(arr[idx, 8:11], axis=1).astype(np.float64)
    return inten / np.maximum(d2, 1e-6)


class ShadowPass(Pass):
    """Renders the shadow atlas and the view table for every light that casts shadows."""

    name = "shadows"
    provides = frozenset({Effect.SHADOWS, Effect.ENVIRONMENT})
    kind = "raster"
    writes = (ATLAS, VIEWS, WORLD_RANGE, SHADOW_SELECTION, SCENE_LIGHTS)
    # the budget ranks lights by last frame's visible tiles (read back: no mid-frame stall)
    optional_reads = (LIGHT_CULL, TILE_BOUNDS + PREV)
    read_access = {TILE_BOUNDS + PREV: "readback"}
    # sizes depend on the lights: the pass allocates them (managed=False); the views are
    # written from the CPU, the world range is a Python object
    declared = (Res(ATLAS, components=1, dtype="f4", managed=False, check="none"),
                Res(VIEWS, kind=BUFFER, managed=False, check="none"),
                Res(WORLD_RANGE, kind=HOST, managed=False, check="none"),
                Res(SHADOW_SELECTION, kind=HOST, managed=False, check="none"),
                Res(SCENE_LIGHTS, kind=BUFFER, managed=False, check="none"))
    # a tile keeps its view while the scene is unchanged (see the module docstring)
    history_resets = frozenset({"geometry", "transforms", "lights", "param_change", "camera_cut"})
    params = (
        Param("shadow_resolution", 512, 64, 4096, "texels per side of one cube face / cascade"),
        Param("cascades", 3, 1, 4, "sun cascades"),
        Param("normal_offset", 2.0, 0.0, 8.0, "normal offset in texels"),
        Param("world_directions", 8, 0, 64, "world light: directions (orthographic maps) sampled per frame"),
        Param("light_samples", 2, 1, 16, "lights with size: points on the light (shadow origins) per frame"),
        Param("max_shadow_maps", 8, 0, 1024,
              "shadow-map budget: point, spot, area and mesh lights that get shadow maps (those that "
              "matter most in view); the others are shadowed by ray tracing in direct_light"),
        Param("ray_cost_texels", 8.0, 0.0, 1e6,
              "lights with size: ray-traced instead of shadow-mapped when their maps' texels per "
              "frame exceed pixels x shadow rays per pixel x this (a ray's cost in texels drawn); "
              "0: always shadow maps"),
    )
    quality_ladder = (
        {"shadow_resolution": 256, "cascades": 2, "world_directions": 4, "light_samples": 1, "max_shadow_maps": 4},
        {"shadow_resolution": 512, "cascades": 3, "world_directions": 8, "light_samples": 2, "max_shadow_maps": 8},
        {"shadow_resolution": 1024, "cascades": 3, "world_directions": 16, "light_samples": 4, "max_shadow_maps": 16},
        {"shadow_resolution": 2048, "cascades": 4, "world_directions": 24, "light_samples": 4, "max_shadow_maps": 32},
    )

    def __init__(self, quality=None, **props):
        super().__init__(quality, **props)
        self.atlas = self.depth = self.fbo = self.view_buf = None
        self._static_key = None
        self._tile_views = {}  # atlas tile rectangle -> the view drawn there (a bytes key)
        self._tile_scene = None  # what the tiles were drawn for (scene version, atlas, selection)
        self.tiles_drawn = 0  # views drawn in the last execute (the rest kept from earlier frames)
        self._mapped = set()
        self.selection = None
        self.ranked_by = None  # how the last budget ranked lights: "tiles" (last frame's) or "distance"

    def reset_history(self):
        super().reset_history()
        self._static_key = None
        self._tile_views = {}

    # ------------------------------------------------------------------ views
    def _sample_origin(self, light_rec, scene, k: int, rng: np.random.Generator):
        """A point on the light for frame k, and the light's normal there (zero if none).
        Frame 0 uses the light's centre (the best single-frame hard shadow)."""
        u = (halton(k, 2), halton(k, 3)) if k > 0 else (0.5, 0.5)
        if light_rec["type"] == LIGHT_MESH:
            g = light_rec["group"]
            areas = g["areas"]
            cdf = np.cumsum(areas) / max(areas.sum(), 1e-20)
            t = int(np.searchsorted(cdf, rng.random()))
            t = min(t, len(areas) - 1)
            a, b = rng.random(2)
            if a + b > 1:
                a, b = 1 - a, 1 - b
            tri = g["triangles"][t]
            n = np.cross(tri[1] - tri[0], tri[2] - tri[0])
            n = n / max(np.linalg.norm(n), 1e-20)
            return tri[0] + a * (tri[1] - tri[0]) + b * (tri[2] - tri[0]), n
        L = light_rec["light"]
        if L.type in (LightType.POINT, LightType.SPOT) and L.radius > 0 and k > 0:
            # uniform in the ball: its projection covers the visible disk of the sphere
            r = L.radius * u[0] ** (1 / 3)
            z = 1 - 2 * u[1]
            phi = 2 * math.pi * halton(k + 1, 5)
            s = math.sqrt(max(0.0, 1 - z * z))
            return L.position + r * np.array([s * math.cos(phi), s * math.sin(phi), z], np.float32), np.zeros(3)
        if L.type == LightType.AREA:
            uu, vv = L.area_axes()
            a, b = 2 * u[0] - 1, 2 * u[1] - 1
            if L.shape in (2, 3):
                rr, th = math.sqrt(u[0]), 2 * math.pi * u[1]
                a, b = rr * math.cos(th), rr * math.sin(th)
            return L.position + a * uu + b * vv, L.direction.astype(np.float64)
        return L.position, np.zeros(3)

    def _sun_dir(self, L, k: int) -> np.ndarray:
        d = L.direction.astype(np.float64)
        half = 0.5 * L.angle
        if half <= 1e-5 or k == 0:
            return d
        u1, u2 = halton(k + 1, 2), halton(k + 1, 3)
        c = 1 - u1 * (1 - math.cos(half))
        s = math.sqrt(max(0.0, 1 - c * c))
        phi = 2 * math.pi * u2
        t = np.cross(d, [0, 0, 1.0] if abs(d[2]) < 0.9 else [1.0, 0, 0])
        t /= np.linalg.norm(t)
        b = np.cross(d, t)
        out = c * d + s * (math.cos(phi) * t + math.sin(phi) * b)
        return out / np.linalg.norm(out)

    def _build_views(self, rc, frame, res: int):
        """Every view of this frame; ``res`` is the tile size the atlas will really use
        (texel sizes, hence biases, depend on it)."""
        scene = rc.scene.scene
        lo, hi = scene.world_bounds()
        center = 0.5 * (lo + hi)
        radius = max(float(np.linalg.norm(hi - lo)) * 0.5, 1e-3)
        rng = np.random.default_rng(frame.index * 7919 + 13)
        records = []
        mapped = self._mapped
        for li, L in enumerate(scene.lights):
            if L.cast_shadow and float(np.max(L.color)) > 0 and (L.type == LightType.SUN or li in mapped):
                records.append({"index": li, "type": int(L.type), "light": L})
        for gi, g in enumerate(rc.scene.emitters.groups):
            if len(scene.lights) + gi in mapped:
                records.append({"index": len(scene.lights) + gi, "type": LIGHT_MESH, "group": g})
        views = []  # (light index, view_proj, origin, ortho, dir, texel, far)
        self._per_group = {}  # light index -> views per shadow origin (6 cube faces, 1, cascades)
        cam = scene.camera
        J = int(self["light_samples"])
        for rec in records:
            n_origins = J if self._has_size(rec) else 1
            for j in range(n_origins):
                k = frame.index * n_origins + j  # k = 0: the light's centre / the sun's axis
                n_views = self._views_for(rec, k, scene, rng, rc, cam, center, radius, res, views)
                self._per_group[rec["index"]] = n_views

        # world light: orthographic maps along directions stratified on the sphere (a uniform
        # world) or importance-sampled from the world map by luminance (so the visibility
        # ratio DIRECT takes is weighted by where the light comes from), rotated every frame
        # (frame 0 included: a fixed, well-spread set)
        K = int(self["world_directions"]) if float(np.max(scene.world.color)) > 0 else 0
        if K:
            omegas, _, _ = world_light_directions(scene.world, K, frame.index)
            for k in range(K):
                omega = omegas[k]
                d = -omega  # the direction light travels
                vp, eye = world_view(center, radius, d)
                # world views use a quarter tile (half the resolution): sky visibility is
                # smooth, and this keeps many directions within the atlas
                views.append(("world", vp, eye, 1, d, 2.0 * radius * 1.02 / max(32, res // 2), 4.0 * radius))
        return views

    @staticmethod
    def _has_size(rec) -> bool:
        if rec["type"] == LIGHT_MESH:
            return True
        L = rec["light"]
        return (L.type == LightType.AREA or (L.type in (LightType.POINT, LightType.SPOT) and L.radius > 0)
                or (L.type == LightType.SUN and L.angle > 1e-5))

    def _views_for(self, rec, k, scene, rng, rc, cam, center, radius, res, views) -> int:
        """Append the views of one shadow origin (sample k of the light); returns how many."""
        if rec["type"] == int(LightType.SUN):
            d = self._sun_dir(rec["light"], k)
            cascades = self._cascades(rc, cam, d, center, radius, res)
            for (vp, origin, texel, far) in cascades:
                views.append((rec["index"], vp, origin, 1, d, texel, far))
            return len(cascades)
        origin, normal = self._sample_origin(rec, scene, k, rng)
        origin = np.asarray(origin, np.float64)
        far = float(np.linalg.norm(origin - center)) + radius * 1.01 + 1e-3
        near = max(far * 1e-5, min(1e-3, far * 1e-3))  # 1 mm, or a thousandth of a smaller scene
        L = rec.get("light")
        if L is not None and _single_view(L):
            # one perspective view around the cone (10% margin for the blend and scale)
            fov = min(math.radians(150.0), L.spot_size * 1.1 + math.radians(2.0))
            proj = perspective(fov, near, far)
            texel = 2 * math.tan(fov / 2) / res
            vp = proj @ look_at(origin, L.direction.astype(np.float64), (0, 0, 1))
            views.append((rec["index"], vp, origin, 0, normal, texel, far))
            return 1
        fov = math.radians(92.0)
        proj = perspective(fov, near, far)
        texel = 2 * math.tan(fov / 2) / res
        for fwd, up in CUBE_DIRS:
            vp = proj @ look_at(origin, fwd, up)
            views.append((rec["index"], vp, origin, 0, normal, texel, far))
        return len(CUBE_DIRS)

    def _cascades(self, rc, cam, d, center, radius, res):
        """Orthographic views along d, fitted to slices of the camera frustum (log splits)."""
        n = int(self["cascades"])
        view = cam.view.astype(np.float64)
        inv_vp = np.linalg.inv(cam.projection.astype(np.float64) @ view)
        # camera range limited to the scene
        cpos = cam.position.astype(np.float64)
        near = max(cam.clip_start, 1e-3)
        far = min(cam.clip_end, float(np.linalg.norm(cpos - center)) + radius)
        far = max(far, near * 1.01)
        splits = [near * (far / near) ** (i / n) for i in range(n + 1)]
        out = []
        for i in range(n):
            # frustum slice corners in world space via NDC at view depths
            corners = []
            for z_view in (splits[i], splits[i + 1]):
                p_view = np.array([0, 0, -z_view, 1.0])
                clip = cam.projection.astype(np.float64) @ p_view
                zndc = clip[2] / clip[3]
                for x in (-1, 1):
                    for y in (-1, 1):
                        w = inv_vp @ np.array([x, y, zndc, 1.0])
                        corners.append(w[:3] / w[3])
            corners = np.array(corners)
            c = corners.mean(axis=0)
            r = float(np.max(np.linalg.norm(corners - c, axis=1)))
            r = min(r, radius * 1.05) if i == n - 1 else r
            if i == n - 1 and r >= radius:
                c = center
            eye = c - d * (radius * 2 + r)
            depth = radius * 4 + 2 * r
            vp = ortho(r, 0.0, depth) @ look_at(eye, d, (0, 0, 1))
            texel = 2 * r / res
            out.append((vp, eye, texel, depth))
        return out

    # ------------------------------------------------------------------ run
    def _ensure_atlas(self, rc, n_views: int):
        res = int(self["shadow_resolution"])
        cols = max(1, math.ceil(math.sqrt(max(n_views, 1))))
        rows = max(1, math.ceil(max(n_views, 1) / cols))
        while cols * res > MAX_ATLAS or rows * res > MAX_ATLAS:
            res //= 2
        size = (cols * res, rows * res)
        if self.atlas is None or self.atlas.size != size:
            for o in (self.fbo, self.atlas, self.depth):
                if o is not None:
                    o.release()
            self.atlas = rc.ctx.texture(size, 1, dtype="f4")
            import moderngl

            self.atlas.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self.depth = rc.ctx.depth_texture(size)
            self.fbo = rc.ctx.framebuffer(color_attachments=[self.atlas], depth_attachment=self.depth)
            self._static_key = None
        rc.resources[ATLAS] = self.atlas
        return cols, res

    def _dynamic(self, scene) -> bool:
        """Does any view change from frame to frame (lights with size, the world light)?"""
        if int(self["world_directions"]) > 0 and float(np.max(scene.world.color)) > 0:
            return True
        mapped = getattr(self, "_mapped", set())
        for li, L in enumerate(scene.lights):
            if L.type == LightType.SUN and L.angle > 1e-5:
                return True
            if li not in mapped:  # over the budget: no shadow maps to move
                continue
            if L.type in (LightType.POINT, LightType.SPOT) and L.radius > 0:
                return True
            if L.type == LightType.AREA:
                return True
        return bool(getattr(self, "_has_mesh", False)) and any(i >= len(scene.lights) for i in mapped)

    def _select(self, rc, frame) -> ShadowSelection:
        """The shadow-map budget: every shadow-casting point, spot, area and mesh light when
        they fit in ``max_shadow_maps``; else the ones with the largest estimated contribution
        to the visible pixels (light_cull.scores_from_bounds over last frame's tile bounds of
        the G-buffer; on the first frame, or without culling: intensity / squared distance to
        the camera)."""
        scene = rc.scene.scene
        cands = [li for li, L in enumerate(scene.lights)
                 if L.cast_shadow and float(np.max(L.color)) > 0 and L.type != LightType.SUN]
        cands += [len(scene.lights) + gi for gi in range(len(rc.scene.emitters.groups))]
        budget = int(self["max_shadow_maps"])
        if len(cands) <= budget:
            traced = self._traced(rc, cands)
            return ShadowSelection(frame, sorted(set(cands) - set(traced)), traced, budget, traced)
        cull = rc.resources.get(LIGHT_CULL)
        score = None
        if cull is not None and cull.frame is frame and TILE_BOUNDS + PREV in rc.resources:
            nbytes = cull.n_tiles * 32
            data = rc.read_back(TILE_BOUNDS + PREV)
            if len(data) >= nbytes:
                tb = np.frombuffer(data[:nbytes], np.float32).reshape(-1, 2, 4)
                score = scores_from_bounds(tb, cull.info, cands)
        self.ranked_by = "tiles" if score is not None else "distance"
        if score is None:
            score = first_frame_scores(rc.scene, scene.camera.position, cands,
                                       cull.info if cull is not None and cull.frame is frame else None)
        order = np.argsort(-score, kind="stable")
        keep = sorted(int(cands[i]) for i in order[:budget])
        traced = self._traced(rc, keep)
        rest = sorted((set(cands) - set(keep)) | set(traced))
        return ShadowSelection(frame, sorted(set(keep) - set(traced)), rest, budget, traced)

    def _trace_rays(self, rc) -> int:
        """Shadow rays per pixel per frame that every reader of the shadow maps traces for a
        light without one (0 when any reader cannot: it would see the light unshadowed)."""
        rays = [int(c.shadow_rays_per_pixel()) if hasattr(c, "shadow_rays_per_pixel") else 0
                for c in self.consumers]
        if not rays or min(rays) <= 0:
            return 0
        from ..scene_data import SceneError
        try:
            rc.scene.rt()  # the session's shared ray tracer (built once)
        except SceneError:
            return 0
        return min(rays)

    def _traced(self, rc, keep) -> list:
        """Of the lights that get shadows of their own (``keep``), those with size to shadow by
        ray tracing rather than shadow maps. Their views move every frame (a new point on the
        light), so their maps are drawn every frame: a cost fixed by the maps' size, whatever
        the image's. Rays cost per pixel and see the exact visibility of points on the light.
        A light is traced when its maps' texels per frame exceed what its rays cost, counted
        in texels (``ray_cost_texels``): on a small image, or with many points per light, rays
        are the cheaper. Each traced light gets its own rays (``Light.shadow.x`` = -1), as a
        mapped light gets its own maps."""
        cost = float(self["ray_cost_texels"])
        if cost <= 0 or not keep:
            return []
        scene = rc.scene.scene
        n = len(scene.lights)
        per_face = float(self["shadow_resolution"]) ** 2 * int(self["light_samples"])
        moving = []
        for li in keep:
            L = scene.lights[li] if li < n else None
            rec = {"type": LIGHT_MESH} if L is None else {"type": int(L.type), "light": L}
            if self._has_size(rec):  # views per point on the light: one spot view or six faces
                moving.append((li, (1 if L is not None and _single_view(L) else 6) * per_face))
        if not moving:
            return []
        rays = self._trace_rays(rc)
        if rays <= 0:
            return []
        ray_texels = rc.width * rc.height * rays * cost
        return sorted(li for li, texels in moving if texels > ray_texels)

    def execute(self, rc, frame):
        import moderngl

        scene = rc.scene.scene
        self._has_mesh = bool(rc.scene.emitters.groups)
        selection = self._select(rc, frame)
        self._mapped = set(selection.mapped)
        rc.resources[SHADOW_SELECTION] = selection
        self.selection = selection
        key = (rc.scene.version, frame.view.tobytes() if any(L.type == LightType.SUN for L in scene.lights) else b"",
               frame.index if self._dynamic(scene) else 0, tuple(selection.mapped), tuple(selection.traced))
        if self._static_key == key and not self._dynamic(scene):
            return
        views = self._build_views(rc, frame, int(self["shadow_resolution"]))
        n_world = sum(1 for v in views if v[0] == "world")
        n_tiles = len(views) - n_world + (n_world + 3) // 4
        cols, res = self._ensure_atlas(rc, n_tiles)
        if res != int(self["shadow_resolution"]):  # the atlas had to shrink the tiles
            views = self._build_views(rc, frame, res)
        self._last_views = views  # for inspection (tests, debug views)
        atlas_w, atlas_h = self.atlas.size
        from ..gpu_scene import has_alpha

        tile_scene = (rc.scene.version, id(self.atlas), self.atlas.size, tuple(selection.mapped))
        if tile_scene != self._tile_scene or has_alpha(scene):
            self._tile_views = {}
        self._tile_scene = tile_scene
        self.tiles_drawn = 0
        table = np.zeros((max(1, len(views)), VIEW_FLOATS), np.float32)
        light_views = {}
        prog = rc.programs.program("raster/shadow.vert", "raster/shadow.frag")
        rc.scene.bind(prog)  # materials and textures: alpha holes let light through
        set_uniform(prog, "u_alpha_seed", int((frame.sample * 2654435761 + frame.seed * 40503 + 17) & 0x7FFFFFFF))
        self.fbo.use()
        # empty texels read as occluded: a PCF footprint reaching past the edge of a closed
        # room (zero-thickness walls) must not pick up "lit" from the void outside
        if not self._tile_views:
            self.fbo.clear(0.0, 0, 0, 0, depth=1.0)
        rc.ctx.enable(moderngl.DEPTH_TEST)
        rc.ctx.disable(moderngl.CULL_FACE)
        n_full = len(views) - n_world
        for vi, (li, vp, origin, is_ortho, d, texel, far) in enumerate(views):
            if li == "world":  # four per tile, after the full-size views
                k = vi - n_full
                tile, quad = n_full + k // 4, k % 4
                size = max(32, res // 2)
                x0 = (tile % cols) * res + (quad % 2) * size
                y0 = (tile // cols) * res + (quad // 2) * size
            else:
                size = res
                x0, y0 = (vi % cols) * res, (vi // cols) * res
            rect = (x0, y0, size, size)
            view_key = np.asarray(vp, np.float64).tobytes() + np.asarray(origin, np.float64).tobytes()
            if self._tile_views.get(rect) != view_key:
                if self._tile_views:
                    self.fbo.clear(0.0, 0, 0, 0, depth=1.0, viewport=rect)
                if not (is_ortho == 0 and _behind_area_light(scene, li, vp, origin, d)):
                    rc.ctx.viewport = rect
                    set_uniform(prog, "u_view_proj", vp.astype(np.float32))
                    set_uniform(prog, "u_origin", tuple(float(x) for x in origin))
                    set_uniform(prog, "u_dir", tuple(float(x) for x in d) if is_ortho else (0.0, 0.0, 0.0))
                    set_uniform(prog, "u_ortho", int(is_ortho))
                    rc.scene.draw(prog)
                    self.tiles_drawn += 1
                self._tile_views[rect] = view_key
            table[vi, 0:16] = vp.T.astype(np.float32).ravel()  # column-major mat4
            table[vi, 16:20] = (x0 / atlas_w, y0 / atlas_h, size / atlas_w, size / atlas_h)
            table[vi, 20:23] = origin
            table[vi, 23] = is_ortho
            table[vi, 24:27] = d
            table[vi, 27] = texel
            table[vi, 28] = far
            table[vi, 29] = self["normal_offset"]
            first, count = light_views.get(li, (vi, 0))
            light_views[li] = (first, count + 1)
        rc.ctx.disable(moderngl.DEPTH_TEST)
        data = table.tobytes()
        if self.view_buf is None or self.view_buf.size != len(data):
            if self.view_buf is not None:
                self.view_buf.release()
            self.view_buf = rc.ctx.buffer(data)
        else:
            self.view_buf.write(data)
        rc.resources[VIEWS] = self.view_buf
        # write each light's view range into the light buffer (Light.shadow)
        lights = rc.scene.light_array.copy()
        lights[:, 24:26] = 0
        for li, (first, count) in light_views.items():
            if li == "world":
                continue
            lights[li, 24] = first
            lights[li, 25] = count
            lights[li, 26] = self._per_group.get(li, count)
        for li in selection.traced:  # no views: shadows by rays of its own (direct.comp)
            lights[li, 24] = -1.0
        rc.register_external(SCENE_LIGHTS, rc.scene.light_buf, scene_wide=True)
        rc.scene.light_buf.write(lights.tobytes())
        first, count = light_views.pop("world", (0, 0))
        rc.resources[WORLD_RANGE] = WorldRange(first, count)
        self._static_key = key

    def release(self):
        self._tile_views = {}
        for o in (self.fbo, self.atlas, self.depth, self.view_buf):
            if o is not None:
                o.release()
        self.fbo = self.atlas = self.depth = self.view_buf = None
