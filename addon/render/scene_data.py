"""SceneData: the bpy-free description of one frame of a Blender scene.

Everything the renderer and the comparison need crosses the bpy boundary here, as numpy
arrays and plain Python values. ``addon/blender/export.py`` is the only producer; every
pass, technique and metric is a consumer. Units are Cycles' (see docs/ARCHITECTURE.md):

* positions in metres, world space is Blender's (Z up);
* point/spot ``intensity`` in W/sr (``P * color / (4 pi)``), sun ``irradiance`` in W/m^2,
  area ``radiance`` in W/(m^2 sr), emission ``radiance`` = colour * strength, world
  ``radiance`` = colour * strength;
* colours are linear scene-referred RGB (Blender's working space, Rec.709 primaries).

Meshes are triangle soups per corner (three corners per triangle, ``positions[3*t+k]``),
which is what Blender's loop triangles give and what both rasterisation and BVH building
want. Instances place meshes in the world, so a mesh used by many objects is stored once.
"""
from __future__ import annotations

import dataclasses
import enum
import hashlib
from dataclasses import dataclass, field

import numpy as np


class LightType(enum.IntEnum):
    POINT = 0
    SPOT = 1
    SUN = 2
    AREA = 3


class AreaShape(enum.IntEnum):
    SQUARE = 0
    RECTANGLE = 1
    DISK = 2
    ELLIPSE = 3


@dataclass
class Mesh:
    """One evaluated mesh, triangulated, in object space.

    positions, normals: (3*T, 3) float32, per triangle corner.
    uvs: (3*T, 2) float32 (zeros when the mesh has no UV map).
    tangents: (3*T, 4) float32 or None: MikkTSpace tangent xyz of the UV map and the
    bitangent sign (Blender's ``mesh.calc_tangents``), read when a material normal-maps it.
    colors: (3*T, 4) float32 or None: the colour attribute a material reads (Color Attribute
    node), per corner, linear; a material map with ``texture == VERTEX_COLOR`` reads it.
    material_slots: (T,) int32, index into ``SceneData.materials`` (already resolved
    through the object's material slots; -1 = default material).
    """

    name: str
    positions: np.ndarray
    normals: np.ndarray
    uvs: np.ndarray
    material_ids: np.ndarray
    tangents: np.ndarray | None = None
    colors: np.ndarray | None = None  # (3*T, 4) float32 linear RGBA of a colour attribute, per corner

    @property
    def triangle_count(self) -> int:
        return int(self.material_ids.shape[0])

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        if self.positions.shape[0] == 0:
            z = np.zeros(3, np.float32)
            return z, z
        return self.positions.min(axis=0), self.positions.max(axis=0)


@dataclass
class Instance:
    """A mesh placed in the world. ``matrix``: (4,4) float32 object-to-world.

    ``instance_id`` is stable across frames and edits and unique within the scene: the
    object's name for a real object, ``"<instancer>/<object>/<persistent id>"`` for an
    instance made by a collection instance, particles or geometry nodes (Blender's
    ``DepsgraphObjectInstance.persistent_id``). Motion vectors and any per-instance history
    are keyed by it (every instance of one object shares the object's name). Empty when
    the producer gave none: :meth:`SceneData.instance_ids` then numbers the instances of
    one object in order."""

    mesh: int
    matrix: np.ndarray
    object_name: str
    # Per-instance material override: maps a mesh's material id to another (object-linked
    # materials); None when the mesh's own ids apply.
    material_map: np.ndarray | None = None
    instance_id: str = ""


VERTEX_COLOR = -2  # TexRef.texture of a map that reads the mesh's colour attribute (Mesh.colors)

# The Principled inputs a texture can drive (Material.maps keys).
MATERIAL_MAPS = ("base_color", "roughness", "metallic", "alpha", "emission", "normal",
                 "specular_ior_level", "weight", "bump")

# BSDF kinds of a Material or of one of its lobes (common.glsl BSDF_* in this order).
BSDF_KINDS = ("principled", "glossy", "glass", "refraction", "translucent")
TRANSMITTING_KINDS = ("glass", "refraction", "translucent")
MAX_LOBES = 4  # common.glsl MATERIAL_MAX_LOBES


@dataclass
class TexRef:
    """One texture feeding one Principled input: ``texture`` indexes SceneData.textures,
    ``channel`` picks one channel (0-3) or -1 for RGB; sampled with Cycles' Linear or
    Closest interpolation and REPEAT / EXTEND / CLIP / MIRROR extension; the sample is
    multiplied by ``scale`` (Emission Strength, the Normal Map's strength for ``normal``)."""

    texture: int
    channel: int = -1
    interpolation: str = "Linear"
    extension: str = "REPEAT"
    scale: float = 1.0


@dataclass
class Material:
    """The Principled BSDF subset GI Preview renders (Blender 4.x/5.x inputs).

    Scalars hold the input's value, or its mean over the texture when ``maps`` has one for
    that input (consumers that ignore textures see the average). ``maps['emission']`` is the
    emitted radiance (Emission Color x Strength), ``maps['normal']`` a tangent-space normal
    map (RGB in [0, 1], strength in ``scale``) over the mesh's ``tangents``, ``maps['bump']``
    a Bump node's height (``scale`` = Distance, negated when inverted; ``bump_strength`` its
    Strength), applied after the normal map as Cycles' Bump node does.
    ``support`` is "exact", "approximated: <how>" or "unsupported: <node>" (what the
    exporter understood of the node tree).

    ``bsdf`` is the kind (BSDF_KINDS) and ``transmission`` the Principled Transmission
    Weight. ``lobes`` is empty for a material that is one lobe (the record itself). Otherwise
    (Mix / Add Shaders, Glass, Refraction, Translucent BSDFs, Principled transmission) the
    path tracer evaluates ``lobes``, each a Material of one kind whose ``weight`` (or
    ``maps['weight']``, a texture) is the product of the mix factors on its way to the
    output, while this record's own values are the blended approximation the G-buffer
    family (DIRECT, screen space, probes, voxels) shades: an opaque Principled BSDF.
    A Transparent BSDF is folded into ``alpha`` (Cycles' shadow rays pass through it as
    through alpha)."""

    name: str
    base_color: tuple[float, float, float] = (0.8, 0.8, 0.8)
    metallic: float = 0.0
    roughness: float = 0.5
    ior: float = 1.5
    specular_ior_level: float = 0.5
    specular_tint: tuple[float, float, float] = (1.0, 1.0, 1.0)
    alpha: float = 1.0
    emission_color: tuple[float, float, float] = (0.0, 0.0, 0.0)
    emission_strength: float = 0.0
    base_color_texture: int = -1  # index into SceneData.textures, -1 = none
    maps: dict = field(default_factory=dict)  # MATERIAL_MAPS key -> TexRef
    bsdf: str = "principled"
    transmission: float = 0.0
    weight: float = 1.0
    bump_strength: float = 0.0  # the Bump node's Strength (0: no bump, see maps['bump'])
    bump_correction: bool = True  # Cycles' Bump Map Correction (material settings)
    coat_weight: float = 0.0  # Principled coat (a GGX dielectric layer over the rest)
    coat_roughness: float = 0.03
    coat_ior: float = 1.5
    coat_tint: tuple[float, float, float] = (1.0, 1.0, 1.0)
    sheen_weight: float = 0.0  # Principled sheen (Cycles' microfiber sheen on top)
    sheen_roughness: float = 0.5
    sheen_tint: tuple[float, float, float] = (1.0, 1.0, 1.0)
    lobes: list = field(default_factory=list)  # [Material], see above
    support: str = "exact"
    # True when the material's node tree was fully understood; False = viewport-colour fallback.
    exact: bool = True
    warnings: list[str] = field(default_factory=list)

    @property
    def emission(self) -> np.ndarray:
        return np.asarray(self.emission_color, np.float32) * np.float32(self.emission_strength)

    @property
    def is_emissive(self) -> bool:
        return float(np.max(self.emission)) > 0.0

    @property
    def transmits(self) -> bool:
        """Does some lobe refract or transmit light (light below the surface reaches it)?"""
        return any(x.bsdf in TRANSMITTING_KINDS or (x.bsdf == "principled" and x.transmission > 0.0)
                   for x in (self.lobes or [self]))

    @property
    def is_glossy(self) -> bool:
        """Does the material show a visible specular lobe (mirror to moderately rough)?"""
        spec = self.metallic > 0.0 or self.specular_ior_level > 0.0
        return bool(spec and self.roughness < 0.6)


@dataclass
class Texture:
    """An image texture, linear float RGBA (H, W, 4), row 0 at the bottom (Blender's order)."""

    name: str
    pixels: np.ndarray


@dataclass
class Light:
    """One Blender light, in Cycles' units.

    ``matrix`` is the light object's world matrix (columns: X, Y, Z axes scaled, translation);
    lights emit along -Z. ``color`` is the per-type quantity described in the module
    docstring (intensity, irradiance or radiance), RGB, including colour, temperature and
    exposure.
    """

    name: str
    type: LightType
    matrix: np.ndarray
    color: np.ndarray  # RGB float32 in the type's unit
    radius: float = 0.0  # point/spot sphere radius (m)
    spot_size: float = 0.0  # full cone angle (rad)
    spot_blend: float = 0.0
    angle: float = 0.0  # sun: angular diameter (rad)
    shape: AreaShape = AreaShape.SQUARE
    size: tuple[float, float] = (1.0, 1.0)  # area: size along local X and Y (before object scale)
    spread: float = np.pi  # area: Cycles' spread angle (rad)
    cast_shadow: bool = True
    power: float = 0.0  # the light's power in W (sun: W/m^2), for light selection

    @property
    def position(self) -> np.ndarray:
        return np.asarray(self.matrix[:3, 3], np.float32)

    @property
    def direction(self) -> np.ndarray:
        """Unit vector along which the light shines (local -Z in world space)."""
        d = -np.asarray(self.matrix[:3, 2], np.float64)
        n = np.linalg.norm(d)
        return (d / n if n > 0 else np.array([0, 0, -1.0])).astype(np.float32)

    def area_axes(self) -> tuple[np.ndarray, np.ndarray]:
        """World-space half-extent vectors of an area light (X and Y half sizes)."""
        sx, sy = self.size
        if self.shape in (AreaShape.SQUARE, AreaShape.DISK):
            sy = sx
        u = np.asarray(self.matrix[:3, 0], np.float32) * np.float32(0.5 * sx)
        v = np.asarray(self.matrix[:3, 1], np.float32) * np.float32(0.5 * sy)
        return u, v

    def area(self) -> float:
        u, v = self.area_axes()
        full = float(np.linalg.norm(np.cross(u, v))) * 4.0
        if self.shape in (AreaShape.DISK, AreaShape.ELLIPSE):
            full *= np.pi / 4.0
        return full


@dataclass
class Camera:
    """The render camera. Matrices are OpenGL-style (clip = proj @ view @ world)."""

    name: str
    matrix_world: np.ndarray  # (4,4) camera-to-world
    projection: np.ndarray  # (4,4), from Camera.calc_matrix_camera
    type: str = "PERSP"  # PERSP | ORTHO
    clip_start: float = 0.1
    clip_end: float = 100.0

    @property
    def view(self) -> np.ndarray:
        return np.linalg.inv(self.matrix_world.astype(np.float64)).astype(np.float32)

    @property
    def position(self) -> np.ndarray:
        return np.asarray(self.matrix_world[:3, 3], np.float32)

    @property
    def forward(self) -> np.ndarray:
        d = -np.asarray(self.matrix_world[:3, 2], np.float64)
        return (d / np.linalg.norm(d)).astype(np.float32)


@dataclass
class World:
    """The world: background and light, radiance in W/(m^2 sr).

    ``map`` is None for a uniform world (radiance ``color``: a Background node's colour x
    strength). Otherwise it is the world's radiance over all directions as an
    equirectangular float image (H, W, 3), row 0 at the bottom, in the convention of
    Blender's Environment Texture (``render/world_map.py``), and ``color`` is its
    solid-angle mean (what passes that treat the world as uniform use). ``source`` says how
    it was obtained: ``"uniform"``, ``"environment"`` (an Environment Texture read
    directly) or ``"cycles"`` (any other node tree, evaluated by Cycles)."""

    color: np.ndarray = field(default_factory=lambda: np.zeros(3, np.float32))
    exact: bool = True
    warnings: list[str] = field(default_factory=list)
    map: np.ndarray | None = None
    source: str = "uniform"
    # The sun taken out of the map (world_map.extract_sun: a compact region carrying a large
    # share of the light), now the light named here in SceneData.lights; "" when none.
    sun_light: str = ""


@dataclass
class SceneData:
    """Everything one frame needs. Produced by the exporter, consumed by the renderer."""

    meshes: list[Mesh] = field(default_factory=list)
    instances: list[Instance] = field(default_factory=list)
    materials: list[Material] = field(default_factory=list)
    textures: list[Texture] = field(default_factory=list)
    lights: list[Light] = field(default_factory=list)
    camera: Camera | None = None
    world: World = field(default_factory=World)
    width: int = 256
    height: int = 256
    frame: int = 1
    name: str = "scene"
    # Render > Film > Transparent: the camera sees no world (RGB 0, alpha = coverage); the
    # world still lights the scene
    film_transparent: bool = False
    warnings: list[str] = field(default_factory=list)

    # ---------------------------------------------------------------- queries
    def instance_ids(self) -> list[str]:
        """One unique, stable id per instance (``Instance.instance_id``; for instances built
        without one, ``"<object>#<k>"``, k counting that object's instances in order)."""
        seen: dict[str, int] = {}
        out = []
        for inst in self.instances:
            base = inst.instance_id or f"{inst.object_name}#"
            k = seen.get(base, 0)
            seen[base] = k + 1
            out.append(base if (inst.instance_id and k == 0) else f"{base}{k}")
        return out

    @property
    def triangle_count(self) -> int:
        return sum(self.meshes[i.mesh].triangle_count for i in self.instances)

    def world_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned bounds of all instances in world space."""
        lo = np.full(3, np.inf, np.float64)
        hi = np.full(3, -np.inf, np.float64)
        for inst in self.instances:
            mlo, mhi = self.meshes[inst.mesh].bounds()
            corners = np.array([[x, y, z, 1.0] for x in (mlo[0], mhi[0]) for y in (mlo[1], mhi[1])
                                for z in (mlo[2], mhi[2])])
            w = corners @ inst.matrix.astype(np.float64).T
            lo = np.minimum(lo, w[:, :3].min(axis=0))
            hi = np.maximum(hi, w[:, :3].max(axis=0))
        if not np.all(np.isfinite(lo)):
            lo = np.zeros(3)
            hi = np.zeros(3)
        return lo.astype(np.float32), hi.astype(np.float32)

    def fingerprint(self) -> str:
        """A stable hash of everything that affects the rendered image."""
        h = hashlib.sha256()

        def add(x):
            if isinstance(x, np.ndarray):
                h.update(str(x.dtype).encode())
                h.update(str(x.shape).encode())
                h.update(np.ascontiguousarray(x).tobytes())
            elif dataclasses.is_dataclass(x):
                for f in dataclasses.fields(x):
                    if f.name in ("warnings", "instance_id", "support"):  # do not change the image
                        continue
                    v = getattr(x, f.name)
                    if f.name in _HASHED_WHEN_SET and (v is None or (isinstance(v, dict) and not v)
                                                        or (not isinstance(v, np.ndarray) and v is not None
                                                            and f.default is not dataclasses.MISSING
                                                            and v == f.default)):
                        continue  # unset: the fingerprint of a scene without it is unchanged
                    h.update(f.name.encode())
                    add(v)
            elif isinstance(x, dict):
                h.update(b"{")
                for k in sorted(x):
                    h.update(repr(k).encode())
                    add(x[k])
                h.update(b"}")
            elif isinstance(x, (list, tuple)):
                h.update(b"[")
                for y in x:
                    add(y)
                h.update(b"]")
            else:
                h.update(repr(x).encode())

        add(self)
        return h.hexdigest()


# Fields hashed only when set (not None, not empty), so scenes that do not use them keep their
# fingerprints (and the Cycles references cached under them).
_HASHED_WHEN_SET = ("maps", "tangents", "colors", "bump_strength", "bump_correction",
                    "coat_weight", "coat_roughness", "coat_ior", "coat_tint", "sheen_weight", "sheen_roughness",
                    "sheen_tint", "map", "source", "sun_light", "film_transparent")


class SceneError(ValueError):
    """A scene that cannot be rendered, with a message for the user."""
