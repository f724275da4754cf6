"""Blender depsgraph -> SceneData: the only converter from bpy to the renderer's data.

``export_scene(depsgraph, *, width=None, height=None, camera=None) -> SceneData``

* Geometry: every visible mesh instance of ``depsgraph.object_instances`` (modifiers,
  collection instances, geometry-nodes instances), triangulated by Blender's loop triangles,
  read with ``foreach_get`` and numpy indexing only. Meshes are deduplicated by their
  evaluated data (and the materials their object's slots resolve to), so an instanced mesh
  is stored once. Curves, text, surfaces and metaballs come through ``to_mesh()`` when the
  depsgraph does not already give their mesh as an instance.
* Materials: the Principled BSDF (and Emission / Diffuse / Glossy / Metallic BSDFs) behind
  the Cycles output node. Each input is read through the node evaluator
  (``material_nodes.Capture`` -> ``render/node_eval.py``): a constant, an image used as is
  (or one of its channels), or a bake of the nodes over the UV square (see
  docs/ARCHITECTURE.md, "Materials and textures"); a Normal Map node gives a tangent-space
  map and the mesh's MikkTSpace tangents. A node that depends on more than the UV map falls
  back for its input only (``exact=False``, ``support``, a warning naming it). Mix and Add
  Shaders, Glass, Refraction, Translucent, Transparent and Glossy BSDFs and Principled
  transmission make a lobe list (``_LobeMaterial``: exact lobes for the path tracer, a
  blended record for the raster passes); another surface shader falls back to the
  material's viewport colour.
* Lights in Cycles' units (checked against Cycles renders, see blender_tests/test_export.py):
  point/spot intensity ``P*color/(4 pi)`` W/sr, sun irradiance ``E*color`` W/m^2, area
  radiance ``P*color/(pi*A)`` (``normalize``) or ``P*color/pi``; all times ``2**exposure``
  and the blackbody colour when ``use_temperature``.
* The world: a Background colour (times strength) is uniform; any other node tree is
  evaluated by Cycles into an equirectangular radiance map (``world_bake.bake_world``,
  cached), whose solid-angle mean is ``World.color``.
* Camera from ``calc_matrix_camera`` (sensor fit, shift, pixel aspect included).

Exporting never changes the scene: evaluated data is only read, ``to_mesh`` meshes are
freed with ``to_mesh_clear``.
"""
from __future__ import annotations

import math
import subprocess

import bpy
import numpy as np

from ..render import node_eval as NE
from ..render.node_eval import Unsupported
from ..render.scene_data import (VERTEX_COLOR, AreaShape, Camera, Instance, Light, LightType, Material,
                                 Mesh, SceneData, SceneError, TexRef, Texture, World)
from ..render.world_map import extract_sun, world_map_of
from .material_nodes import Capture, follow_link

__all__ = ["export_scene", "SceneExporter", "instance_id", "DEFAULT_MATERIAL_NAME"]

DEFAULT_MATERIAL_NAME = "GI Preview Default"
MISSING_IMAGE_RGBA = (1.0, 0.0, 1.0, 1.0)  # what Cycles shows for an image without pixels
_GEOMETRY_TYPES = {"MESH", "CURVE", "SURFACE", "FONT", "META"}
_TO_MESH_TYPES = {"CURVE", "SURFACE", "FONT", "META"}
_AREA_SHAPES = {"SQUARE": AreaShape.SQUARE, "RECTANGLE": AreaShape.RECTANGLE,
                "DISK": AreaShape.DISK, "ELLIPSE": AreaShape.ELLIPSE}
_LIGHT_TYPES = {"POINT": LightType.POINT, "SPOT": LightType.SPOT, "SUN": LightType.SUN,
                "AREA": LightType.AREA}


# ------------------------------------------------------------------------------ helpers
def _matrix(m) -> np.ndarray:
    return np.array(m, dtype=np.float32).reshape(4, 4)


def _rgb(v) -> tuple[float, float, float]:
    return (float(v[0]), float(v[1]), float(v[2]))


def _srgb_to_linear(c: np.ndarray) -> np.ndarray:
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4).astype(np.float32)


_follow = follow_link  # (node, output socket) linked into a socket, skipping reroutes


def _node_tree(idblock):
    """The shader node tree in use (``use_nodes`` is deprecated and always on in 5.0)."""
    if bpy.app.version < (5, 0, 0) and not getattr(idblock, "use_nodes", True):
        return None
    return idblock.node_tree


def _output_node(tree):
    if tree is None:
        return None
    node = tree.get_output_node("CYCLES")
    if node is None:
        node = tree.get_output_node("ALL")
    return node


# ------------------------------------------------------------------------------ materials
_PRINCIPLED_SCALARS = (("metallic", "Metallic", "metallic"), ("roughness", "Roughness", "roughness"),
                       ("alpha", "Alpha", "alpha"), ("specular_ior_level", "Specular IOR Level",
                                                     "specular_ior_level"))


class _MaterialReader:
    """Reads the inputs of one BSDF node into a Material: each input is a constant, a texture
    (an image used as is, or a bake of the node expression over the UV square: see
    render/node_eval.py), or, when a node upstream depends on more than the UV map, the
    input's own value with a warning naming the node (that input only)."""

    def __init__(self, ex: "_Exporter", mat, bsdf):
        self.ex = ex
        self.mat = mat
        self.bsdf = bsdf
        self.cap = Capture(ex.image_ref)
        self.unsupported: list[str] = []
        self.approx: list[str] = []
        self.tangent_uv: str | None = None
        self.color_attr: str | None = None  # the colour attribute a Color Attribute node reads ("" = default)
        self.uv_names: set = set()
        self.exprs: dict = {}  # Material attribute -> the expression read for it (colour inputs)
        self.uv_square: list[str] = []  # inputs baked from UV values: exact for UVs inside [0, 1]

    # ---------------------------------------------------------- expressions
    def expr(self, sock):
        try:
            e = self.cap.socket(sock)
        except Unsupported as exc:
            self.unsupported.append(f"{exc} (on '{sock.name}')")
            return None
        self.uv_names |= NE.uv_maps(e) - {""}
        return e

    def resolve(self, e, chans: int, label: str):
        """('const', value array) or ('tex', TexRef, mean array) for expression ``e``."""
        if NE.is_const(e):
            return "const", NE.evaluate(e, [[0.5, 0.5]])[0]
        ref = self._direct(e, chans)
        if ref is not None:
            px = self.ex.data.textures[ref.texture].pixels
            mean = px[..., :3].reshape(-1, 3).mean(0) if ref.channel < 0 else \
                np.array([px[..., ref.channel].mean()])
            return "tex", ref, mean * ref.scale
        w, h = NE.bake_size(e)
        closest = NE.closest_grid(e)
        if not (closest or NE.texel_linear(e)):  # thresholds, ramps: sample finer than the images
            w, h = min(2048, 2 * w), min(2048, 2 * h)
        key = f"{e!r}|{w}x{h}"

        def make():
            vals = NE.bake(e, w, h)
            out = np.zeros((h, w, 4), np.float32)
            out[..., :vals.shape[2]] = vals
            out[..., 3] = 1.0 if vals.shape[2] == 3 else out[..., 3]
            return out

        tex = self.ex.baked(f"{self.mat.name}: {label}", key, make)
        ext = "REPEAT"
        if NE.uv_maps_other(e):  # a function of UV: exact where the mesh's UVs stay in [0, 1]
            ext = "EXTEND"
            self.uv_square.append(label)
        elif not NE.periodic(e):
            ext = "EXTEND"
            self.approx.append(f"'{label}' is baked over the UV square [0, 1] (Extend outside it)")
        ref = TexRef(texture=tex, channel=-1 if chans == 3 else 0,
                     interpolation="Closest" if closest else "Linear", extension=ext)
        px = self.ex.data.textures[tex].pixels
        mean = px[..., :3].reshape(-1, 3).mean(0) if chans == 3 else np.array([px[..., 0].mean()])
        return "tex", ref, mean

    @staticmethod
    def _direct(e, chans):
        """A TexRef when ``e`` is one image (default UV map) or one channel of it."""
        img, ch = None, -1
        if isinstance(e, NE.Image):
            img, ch = e, (-1 if e.output == "Color" else 3)
        elif isinstance(e, NE.Op) and e.kind == "separate" and e.params[0] == "RGB" and \
                isinstance(e.args[0], NE.Image) and e.args[0].output == "Color":
            img, ch = e.args[0], e.params[1]
        if img is None or not isinstance(img.vector, NE.UV) or img.vector.name:
            return None
        if (chans == 3) != (ch < 0):
            return None
        return TexRef(texture=img.texture, channel=ch, interpolation=img.interpolation, extension=img.extension)

    # ---------------------------------------------------------- inputs
    def vertex_color(self, sock):
        """The colour attribute name when ``sock`` is fed straight by a Color Attribute node
        (or an Attribute node's Color output, Geometry type); None otherwise."""
        found = _follow(sock)
        if found is None:
            return None
        node, out = found
        if getattr(node, "mute", False):
            return None
        if node.bl_idname == "ShaderNodeVertexColor" and out.identifier == "Color":
            return node.layer_name or ""
        if node.bl_idname == "ShaderNodeAttribute" and node.attribute_type == "GEOMETRY" and \
                out.identifier == "Color":
            return node.attribute_name or ""
        return None

    def color(self, m: Material, key: str, sock) -> None:
        name = self.vertex_color(sock)
        if name is not None:
            m.maps[key] = TexRef(texture=VERTEX_COLOR, channel=-1)
            self.color_attr = name
            return
        e = self.expr(sock)
        if e is None:
            e = NE.Const(tuple(float(x) for x in sock.default_value[:3]))
        self.exprs[key] = e
        kind, val, *rest = self.resolve(e, 3, sock.name)
        if kind == "const":
            setattr(m, key, _rgb(val))
            return
        m.maps[key] = val
        setattr(m, key, _rgb(rest[0]))
        if key == "base_color":
            m.base_color_texture = val.texture

    def scalar(self, m: Material, attr: str, sock, map_key: str | None = None) -> None:
        e = self.expr(sock)
        if e is None:
            setattr(m, attr, float(sock.default_value))
            return
        kind, val, *rest = self.resolve(e, 1, sock.name)
        if kind == "const":
            setattr(m, attr, float(val[0]))
            return
        if map_key is None:
            self.approx.append(f"'{sock.name}' is textured; its mean {float(rest[0][0]):.4g} is used")
        else:
            m.maps[map_key] = val
        setattr(m, attr, float(rest[0][0]))

    def emission(self, m: Material, col_sock, str_sock) -> None:
        ce = self.expr(col_sock)
        se = self.expr(str_sock)
        if ce is None:
            ce = NE.Const(_rgb(col_sock.default_value))
        if se is None:
            se = NE.Const((float(str_sock.default_value),))
        if NE.is_const(ce) and NE.is_const(se):
            m.emission_color = _rgb(NE.evaluate(ce, [[0.5, 0.5]])[0])
            m.emission_strength = float(NE.evaluate(se, [[0.5, 0.5]])[0, 0])
            return
        strength = float(NE.evaluate(se, [[0.5, 0.5]])[0, 0]) if NE.is_const(se) else None
        if strength is not None:
            if strength == 0.0:
                m.emission_color, m.emission_strength = _rgb(NE.evaluate(ce, [[0.5, 0.5]])[0]), 0.0
                return
            _, ref, mean = self.resolve(ce, 3, col_sock.name)
            ref.scale = strength
        else:
            prod = NE.Op("vmath", ("SCALE",), (ce, NE.Const((0.0, 0.0, 0.0)), NE.Const((0.0, 0.0, 0.0)), se))
            _, ref, mean = self.resolve(prod, 3, "Emission")
        m.maps["emission"] = ref
        m.emission_color = _rgb(mean)
        m.emission_strength = 1.0

    def normal(self, m: Material, sock) -> None:
        found = _follow(sock)
        if found is None:
            return
        node, _ = found
        if node.bl_idname == "ShaderNodeBump":
            self.bump(m, node, sock)
            return
        if node.bl_idname != "ShaderNodeNormalMap":
            self.unsupported.append(f"node '{node.name}' ({node.bl_idname}) is not supported (on '{sock.name}')")
            return
        if node.space != "TANGENT":
            self.unsupported.append(f"node '{node.name}' (ShaderNodeNormalMap) in {node.space} space is not "
                                    f"supported (on '{sock.name}')")
            return
        se = self.expr(node.inputs["Strength"])
        if se is None:
            return
        if not NE.is_const(se):
            self.approx.append(f"the strength of normal map '{node.name}' is textured; its mean is used")
        strength = float(NE.evaluate(se, [[0.5, 0.5]])[0, 0]) if NE.is_const(se) else \
            float(NE.bake(se, 16, 16).mean())
        ce = self.expr(node.inputs["Color"])
        if ce is None:
            return
        if NE.is_const(ce):
            ce = NE.Op("to_color", (), (ce,)) if NE.channels(ce) == 1 else ce
            c = NE.evaluate(ce, [[0.5, 0.5]])[0]
            if np.allclose(c, (0.5, 0.5, 1.0), atol=1e-6):
                return  # the flat normal
        if NE.is_const(ce):  # a constant tilt: a 1 x 1 texture
            c = tuple(float(x) for x in NE.evaluate(ce, [[0.5, 0.5]])[0])
            ref = TexRef(texture=self.ex.baked(f"{self.mat.name}: normal", f"const-normal{c}",
                                              lambda: np.array([[[*c, 1.0]]], np.float32)))
        else:
            _, ref, _ = self.resolve(ce, 3, f"{node.name} Color")
        ref.scale = strength
        m.maps["normal"] = ref
        self.tangent_uv = node.uv_map or ""
        if node.uv_map:
            self.uv_names.add(node.uv_map)

    def bump(self, m: Material, node, sock) -> None:
        """A Bump node: its height (any UV graph, baked when not one image channel) in
        ``maps['bump']`` with Distance as the map's scale (negated when inverted) and Strength
        in ``bump_strength``; a Normal Map on its Normal input is read as the normal map."""
        nin = node.inputs.get("Normal")
        if nin is not None and _follow(nin) is not None:
            self.normal(m, nin)
        if "bump" in m.maps:
            self.unsupported.append(f"node '{node.name}' (ShaderNodeBump) after another Bump node is not "
                                    f"supported (on '{sock.name}')")
            return
        vals = {}
        for key in ("Strength", "Distance"):
            e = self.expr(node.inputs[key])
            if e is None:
                return
            if NE.is_const(e):
                vals[key] = float(NE.evaluate(e, [[0.5, 0.5]])[0, 0])
            else:
                vals[key] = float(NE.bake(e, 16, 16).mean())
                self.approx.append(f"the {key.lower()} of bump '{node.name}' is textured; its mean is used")
        strength = min(max(vals["Strength"], 0.0), 1.0)
        fw = node.inputs.get("Filter Width")
        if fw is not None and fw.is_linked:
            self.approx.append(f"the filter width of bump '{node.name}' is linked; the exact derivative is used")
        he = self.expr(node.inputs["Height"])
        if he is None or NE.is_const(he) or strength <= 0.0 or vals["Distance"] == 0.0:
            return  # a constant height leaves the normal as it is
        if NE.channels(he) != 1:
            he = NE.Op("to_float", ("RGBA",), (he,))
        _, ref, _ = self.resolve(he, 1, f"{node.name} Height")
        ref.scale = vals["Distance"] * (-1.0 if node.invert else 1.0)
        m.maps["bump"] = ref
        m.bump_strength = strength

    def const_or_mean(self, sock, chans: int):
        """(value, textured) of an input: its constant, or its mean over a bake when textured."""
        e = self.expr(sock)
        if e is None:
            v = sock.default_value
            return (float(v) if chans == 1 else _rgb(v)), False
        if NE.is_const(e):
            v = NE.evaluate(e, [[0.5, 0.5]])[0]
            return (float(v[0]) if chans == 1 else _rgb(v)), False
        if chans == 3 and NE.channels(e) == 1:
            e = NE.Op("to_color", (), (e,))
        if chans == 1 and NE.channels(e) != 1:
            e = NE.Op("to_float", ("RGBA",), (e,))
        w, h = NE.bake_size(e, 256)
        v = NE.bake(e, w, h).reshape(-1, NE.channels(e)).mean(0)
        return (float(v[0]) if chans == 1 else _rgb(v)), True

    def coat(self, m: Material, inp) -> None:
        """Principled coat: Weight, Roughness, IOR, Tint (constants; a textured one by its mean)."""
        ws = inp.get("Coat Weight")
        if ws is None or (not ws.is_linked and float(ws.default_value) <= 0.0):
            return
        for attr, name, chans in (("coat_weight", "Coat Weight", 1), ("coat_roughness", "Coat Roughness", 1),
                                  ("coat_ior", "Coat IOR", 1), ("coat_tint", "Coat Tint", 3)):
            v, textured = self.const_or_mean(inp[name], chans)
            setattr(m, attr, v)
            if textured:
                self.approx.append(f"'{name}' is textured; its mean is used")
        m.coat_weight = min(max(m.coat_weight, 0.0), 1.0)
        cn = inp.get("Coat Normal")
        if cn is not None and _follow(cn) is not None:
            self.approx.append("'Coat Normal' is linked; the coat uses the smooth normal")
        if m.coat_weight > 0.0:
            self.approx.append("in the raster passes the coat is in the BSDF lit by lights (its lobe and its "
                               "attenuation of the layers below), not in environment and indirect light")
            if m.transmission > 0.0:
                self.approx.append("the coat does not cover the transmission part (light sampling alone finds "
                                   "its reflection there)")

    def sheen(self, m: Material, inp) -> None:
        """Principled sheen: Weight, Roughness, Tint (constants; a textured one by its mean)."""
        ws = inp.get("Sheen Weight")
        if ws is None or (not ws.is_linked and float(ws.default_value) <= 0.0):
            return
        for attr, name, chans in (("sheen_weight", "Sheen Weight", 1), ("sheen_roughness", "Sheen Roughness", 1),
                                  ("sheen_tint", "Sheen Tint", 3)):
            v, textured = self.const_or_mean(inp[name], chans)
            setattr(m, attr, v)
            if textured:
                self.approx.append(f"'{name}' is textured; its mean is used")
        m.sheen_weight = max(m.sheen_weight, 0.0)
        if m.sheen_weight > 0.0:
            self.approx.append("the sheen's lobe shape is approximated (a Charlie distribution scaled to the "
                               "albedo of Cycles' microfiber sheen, which it takes off the layers below as Cycles "
                               "does); the raster passes shade it lit by lights only")

    def ignore_linked(self, names) -> None:
        for name in names:
            sock = self.bsdf.inputs.get(name)
            if sock is None:
                continue
            if name == "Normal":
                continue  # handled by normal() where the caller asks for it
            found = _follow(sock)
            if found is not None:
                self.unsupported.append(f"node '{found[0].name}' ({found[0].bl_idname}) is not supported "
                                        f"(on '{name}')")

    # ---------------------------------------------------------- Principled
    def principled(self) -> Material:
        inp = self.bsdf.inputs
        m = Material(name=self.mat.name)
        for attr, sock_name, key in _PRINCIPLED_SCALARS:
            self.scalar(m, attr, inp[sock_name], key)
        for attr, sock_name in (("ior", "IOR"),):
            self.scalar(m, attr, inp[sock_name])
        e = self.expr(inp["Specular Tint"])
        if e is not None and not NE.is_const(e):
            _, _, mean = self.resolve(e, 3, "Specular Tint")
            self.approx.append("'Specular Tint' is textured; its mean is used")
            m.specular_tint = _rgb(mean)
        else:
            m.specular_tint = _rgb(NE.evaluate(e, [[0.5, 0.5]])[0]) if e is not None else \
                _rgb(inp["Specular Tint"].default_value)
        self.emission(m, inp["Emission Color"], inp["Emission Strength"])
        self.color(m, "base_color", inp["Base Color"])
        self.normal(m, inp["Normal"])
        tw = inp.get("Transmission Weight")
        if tw is not None:
            self.scalar(m, "transmission", tw)
            m.transmission = min(max(m.transmission, 0.0), 1.0)
        self.coat(m, inp)
        self.sheen(m, inp)
        # Lobes GI Preview does not model: keep the Principled values, flag them.
        ignored = []
        for name in ("Subsurface Weight",):
            s = inp.get(name)
            if s is not None and (s.is_linked or float(s.default_value) > 0.0):
                ignored.append(name)
        if ignored:
            self.approx.append(f"Principled BSDF '{self.bsdf.name}' inputs "
                               f"{', '.join(repr(n) for n in ignored)} are ignored")
        return self.finish(m)

    def finish(self, m: Material) -> Material:
        self.approx.extend(self.cap.notes)
        name = self.mat.name
        for u in self.unsupported:
            m.warnings.append(f"Material '{name}': {u}; using the input's own value")
        for a in self.approx:
            m.warnings.append(f"Material '{name}': {a}")
        if self.unsupported:
            m.support = "unsupported: " + "; ".join(self.unsupported)
        elif self.approx:
            m.support = "approximated: " + "; ".join(self.approx)
        m.exact = not (self.unsupported or self.approx)
        m._tangent_uv = self.tangent_uv
        m._color_attr = self.color_attr
        m._uv_names = set(self.uv_names)
        m._uv_square = list(self.uv_square)
        return m


# ------------------------------------------------------------------------------ lobe lists
# Surface nodes that make a material a lobe list (Material.lobes) rather than one record.
_LOBE_GRAPH_NODES = {"ShaderNodeMixShader", "ShaderNodeAddShader", "ShaderNodeBsdfGlass",
                     "ShaderNodeBsdfRefraction", "ShaderNodeBsdfTranslucent", "ShaderNodeBsdfTransparent",
                     "ShaderNodeBsdfGlossy", "ShaderNodeBsdfAnisotropic"}
_LOBE_NODES = {"ShaderNodeBsdfPrincipled", "ShaderNodeBsdfDiffuse", "ShaderNodeBsdfGlossy",
               "ShaderNodeBsdfAnisotropic", "ShaderNodeBsdfMetallic", "ShaderNodeBsdfGlass",
               "ShaderNodeBsdfRefraction", "ShaderNodeBsdfTranslucent", "ShaderNodeEmission"}
# What the G-buffer family (DIRECT, screen space, probes, voxels) renders of each lobe kind:
# the record blended from the lobes' Principled-equivalent parameters (see _LobeMaterial).
_RASTER_APPROX = {
    "glass": "glass and refraction as their specular reflection alone (no refraction, no diffuse)",
    "refraction": "glass and refraction as their specular reflection alone (no refraction, no diffuse)",
    "translucent": "translucency as diffuse reflection",
    "glossy": "Glossy as a metal of its colour (Schlick Fresnel)",
    "transmission": "Principled transmission as its specular reflection, the diffuse scaled by 1 - transmission",
}
_MAX_SHADER_DEPTH = 16


def _transmits(node) -> bool:
    s = node.inputs.get("Transmission Weight")
    return s is not None and (_follow(s) is not None or float(s.default_value) > 0.0)


def _cmath(op, a, b, clamp=False):
    return NE.Op("math", (op, clamp), (a, b, NE.Const((0.0,))))


def _mul(a, b):
    if NE.is_const(a) and float(NE.evaluate(a, [[0.5, 0.5]])[0, 0]) == 1.0:
        return b
    if NE.is_const(b) and float(NE.evaluate(b, [[0.5, 0.5]])[0, 0]) == 1.0:
        return a
    return _cmath("MULTIPLY", a, b)


def _const(e) -> float | None:
    return float(NE.evaluate(e, [[0.5, 0.5]])[0, 0]) if NE.is_const(e) else None


class _LobeMaterial:
    """A material whose surface is a graph of Mix / Add Shaders over BSDF nodes, or one
    Glass / Refraction / Translucent / Transparent / Glossy BSDF, or a Principled BSDF with
    transmission. The graph is flattened into terms (weight expression, node): a Mix Shader
    multiplies its two inputs' weights by 1 - factor and factor (clamped, any UV-only
    expression of the node evaluator), an Add Shader passes its weight to both. Then

    * Transparent BSDFs become the material's alpha (1 - their summed weight times their
      colour's grey level), as Cycles' shadow rays see them, and every other term is
      divided by that alpha (the alpha test keeps the rest with probability alpha);
    * Emission terms sum into the material's emission;
    * every BSDF term becomes one lobe record (``Material.lobes``, at most MAX_LOBES) of
      its kind with its weight (constant, or a baked texture), which the path tracer
      evaluates exactly;
    * the material's own record is the approximation the G-buffer family shades: an opaque
      Principled BSDF of the lobes' parameters blended by their mean weights (base colour
      blended per texel when a weight or a colour is textured)."""

    def __init__(self, ex: "_Exporter", mat):
        self.ex = ex
        self.mat = mat
        self.cap = Capture(ex.image_ref)
        self.terms: list = []  # (weight expression, node)
        self.notes: list[str] = []

    def walk(self, sock, w, depth=0):
        found = _follow(sock)
        if found is None:
            return  # an unlinked shader socket is black
        node, _ = found
        k = node.bl_idname
        if getattr(node, "mute", False):
            raise Unsupported(f"shader node '{node.name}' ({k}) is muted")
        if depth > _MAX_SHADER_DEPTH:
            raise Unsupported(f"shader graph deeper than {_MAX_SHADER_DEPTH} nodes at '{node.name}'")
        if k == "ShaderNodeMixShader":
            f = self.cap.socket(node.inputs[0])  # raises Unsupported for position-dependent factors
            f = _cmath("MULTIPLY", f, NE.Const((1.0,)), clamp=True)
            one_minus = _cmath("SUBTRACT", NE.Const((1.0,)), f)
            if NE.is_const(f):
                fv = _const(f)
                f, one_minus = NE.Const((fv,)), NE.Const((1.0 - fv,))
            self.walk(node.inputs[1], _mul(w, one_minus), depth + 1)
            self.walk(node.inputs[2], _mul(w, f), depth + 1)
        elif k == "ShaderNodeAddShader":
            self.walk(node.inputs[0], w, depth + 1)
            self.walk(node.inputs[1], w, depth + 1)
        elif k in _LOBE_NODES or k == "ShaderNodeBsdfTransparent":
            self.terms.append((w, node))
        else:
            raise Unsupported(f"shader node '{node.name}' ({k}) is not supported")

    def lobe(self, node):
        """(Material of one lobe, its reader) for a BSDF or Emission node."""
        k = node.bl_idname
        r = _MaterialReader(self.ex, self.mat, node)
        inp = node.inputs
        if k == "ShaderNodeBsdfPrincipled":
            m = r.principled()
            return m, r
        if k == "ShaderNodeEmission":
            m = Material(name=self.mat.name, base_color=(0.0, 0.0, 0.0), roughness=1.0, specular_ior_level=0.0)
            r.emission(m, inp["Color"], inp["Strength"])
        elif k in ("ShaderNodeBsdfDiffuse", "ShaderNodeBsdfTranslucent"):
            m = Material(name=self.mat.name, roughness=1.0, specular_ior_level=0.0,
                         bsdf="translucent" if k == "ShaderNodeBsdfTranslucent" else "principled")
            if k == "ShaderNodeBsdfDiffuse":
                r.ignore_linked(("Roughness",))
                if float(inp["Roughness"].default_value) > 0.0:
                    r.approx.append("Diffuse BSDF roughness (Oren-Nayar) is read as 0 (Lambert)")
            r.normal(m, inp["Normal"])
            r.color(m, "base_color", inp["Color"])
        elif k in ("ShaderNodeBsdfGlossy", "ShaderNodeBsdfAnisotropic", "ShaderNodeBsdfMetallic"):
            col = inp.get("Color") or inp.get("Base Color")
            m = Material(name=self.mat.name, metallic=1.0, specular_ior_level=0.5,
                         bsdf="principled" if k == "ShaderNodeBsdfMetallic" else "glossy")
            r.scalar(m, "roughness", inp["Roughness"], "roughness")
            r.normal(m, inp["Normal"])
            r.color(m, "base_color", col)
            dist = getattr(node, "distribution", "MULTI_GGX")
            if m.bsdf == "glossy" and dist != "MULTI_GGX":
                r.approx.append(f"Glossy BSDF distribution {dist} is read as Multiscatter GGX")
            an = inp.get("Anisotropy")
            if an is not None and (an.is_linked or float(an.default_value) != 0.0):
                r.approx.append("anisotropy is ignored")
        else:  # Glass, Refraction
            m = Material(name=self.mat.name, metallic=0.0, specular_ior_level=0.5,
                         bsdf="glass" if k == "ShaderNodeBsdfGlass" else "refraction")
            r.scalar(m, "roughness", inp["Roughness"], "roughness")
            r.scalar(m, "ior", inp["IOR"])
            r.normal(m, inp["Normal"])
            r.color(m, "base_color", inp["Color"])
            dist = getattr(node, "distribution", "MULTI_GGX")
            want = "MULTI_GGX" if m.bsdf == "glass" else "GGX"
            if dist != want:
                r.approx.append(f"{node.bl_label} distribution {dist} is read as "
                                f"{'Multiscatter GGX' if want == 'MULTI_GGX' else 'GGX'}")
        return r.finish(m), r

    def read(self, surf) -> Material:
        self.walk(surf, NE.Const((1.0,)))
        top = Material(name=self.mat.name, roughness=0.5, specular_ior_level=0.5)
        # transparency -> alpha
        trans = NE.Const((0.0,))
        lobes, emitters = [], []
        for w, node in self.terms:
            if node.bl_idname == "ShaderNodeBsdfTransparent":
                ce = self.cap.socket(node.inputs["Color"])
                c = NE.evaluate(ce, [[0.5, 0.5]])[0] if NE.is_const(ce) else None
                if c is None or np.ptp(c) > 1e-6:
                    self.notes.append(f"Transparent BSDF '{node.name}': its colour is read as its grey level "
                                      "(shadow rays and camera rays pass through untinted)")
                grey = NE.Op("to_float", ("RGBA",), (ce,)) if c is None or np.ptp(c) > 1e-6 else NE.Const((float(c[0]),))
                trans = _cmath("ADD", trans, _mul(w, grey)) if _const(trans) != 0.0 else _mul(w, grey)
                continue
            m, r = self.lobe(node)
            if node.bl_idname == "ShaderNodeEmission":
                emitters.append((w, m, r))
                continue
            if m.alpha < 1.0 or "alpha" in m.maps:
                if "alpha" in m.maps:
                    self.notes.append(f"the textured Alpha of '{node.name}' inside a shader mix is ignored")
                    m.maps.pop("alpha")
                else:
                    trans = _cmath("ADD", trans, _mul(w, NE.Const((1.0 - m.alpha,))))
                    w = _mul(w, NE.Const((m.alpha,)))
                m.alpha = 1.0
            lobes.append((w, m, r))
        tv = _const(trans)
        keep = None  # 1 - transparency as an expression when textured
        if tv is not None:
            tv = min(max(tv, 0.0), 1.0)
            top.alpha = 1.0 - tv
            scale = NE.Const((1.0 / (1.0 - tv) if tv < 1.0 else 0.0,))
        else:
            keep = _cmath("SUBTRACT", NE.Const((1.0,)), trans, clamp=True)
            reader = _MaterialReader(self.ex, self.mat, None)
            kind, val, *rest = reader.resolve(keep, 1, "Alpha (Transparent BSDF)")
            top.maps["alpha"] = val
            top.alpha = float(rest[0][0])
            self.notes.extend(reader.approx)
            scale = None
        readers = [r for _, _, r in lobes + emitters]
        # weights: divided by alpha (the alpha test keeps the surface with probability alpha)
        out = []
        for w, m, r in lobes + emitters:
            if scale is not None:
                w = _mul(w, scale) if _const(scale) != 1.0 else w
            else:
                w = _cmath("DIVIDE", w, keep)
            out.append((w, m, r))
        lobes, emitters = out[:len(lobes)], out[len(lobes):]
        # emission: the weighted sum (means where a weight is textured)
        em = np.zeros(3)
        for w, m, r in emitters:
            wv = _const(w)
            if wv is None:
                wv = float(NE.bake(w, 16, 16).mean())
                self.notes.append("an Emission weighted by a textured factor emits its mean")
            if "emission" in m.maps and len(self.terms) > 1:
                self.notes.append("a textured Emission inside a shader mix emits its mean")
            em += wv * np.asarray(m.emission, np.float64)
        for _, m, _ in emitters:
            if len(self.terms) == 1 and tv == 0.0:
                top.maps["emission"] = m.maps.get("emission")
        if not top.maps.get("emission"):
            top.maps.pop("emission", None)
        top.emission_color, top.emission_strength = _rgb(em), 1.0
        # lobe weights: constant or baked; at most MAX_LOBES (the heaviest)
        rd = _MaterialReader(self.ex, self.mat, None)
        weighted = []
        for w, m, r in lobes:
            wv = _const(w)
            if wv is None:
                kind, val, *rest = rd.resolve(w, 1, f"lobe weight ({m.bsdf})")
                if kind == "tex":
                    m.maps["weight"] = val
                    wv = float(rest[0][0])
                else:
                    wv = float(val[0])
            m.weight = wv
            if wv > 0.0 or "weight" in m.maps:
                weighted.append((w, m, r))
        self.notes.extend(rd.approx)
        from ..render.scene_data import MAX_LOBES
        if len(weighted) > MAX_LOBES:
            weighted.sort(key=lambda t: -t[1].weight)
            dropped = weighted[MAX_LOBES:]
            weighted = weighted[:MAX_LOBES]
            self.notes.append(f"{len(dropped)} lobes beyond {MAX_LOBES} (the lightest) are dropped")
        top.lobes = [m for _, m, _ in weighted]
        self.blend(top, weighted)
        # support: what the raster passes approximate, and what each lobe's reader noted
        kinds = {m.bsdf for m in top.lobes} | ({"transmission"} if any(
            m.bsdf == "principled" and m.transmission > 0 for m in top.lobes) else set())
        raster = sorted({_RASTER_APPROX[k] for k in kinds if k in _RASTER_APPROX})
        if len(top.lobes) > 1:
            raster.append("the lobes as one Principled BSDF of their parameters blended by weight")
        approx = list(self.notes)
        unsupported = []
        for r in readers:
            approx.extend(a for a in r.approx if a not in approx)
            unsupported.extend(u for u in r.unsupported if u not in unsupported)
        if raster:
            approx.append("in the raster passes " + "; ".join(raster) + " (path tracing evaluates the lobes)")
        name = self.mat.name
        top.warnings = [f"Material '{name}': {u}; using the input's own value" for u in unsupported] + \
            [f"Material '{name}': {a}" for a in approx]
        if unsupported:
            top.support = "unsupported: " + "; ".join(unsupported)
        elif approx:
            top.support = "approximated: " + "; ".join(approx)
        top.exact = not (unsupported or approx)
        tangent = next((r.tangent_uv for _, _, r in weighted if r.tangent_uv is not None), None)
        top._tangent_uv = tangent
        top._color_attr = next((r.color_attr for _, _, r in weighted if r.color_attr is not None), None)
        top._uv_names = set().union(*[r.uv_names for r in readers]) if readers else set()
        top._uv_square = [x for r in readers for x in r.uv_square]
        for _, m, _ in weighted:
            m.maps.pop("normal", None)  # the lobes share the material's shading normal
            m.emission_color, m.emission_strength = (0.0, 0.0, 0.0), 0.0
            m.maps.pop("emission", None)
        return top

    @staticmethod
    def raster_diffuse(m: Material) -> float:
        """How much of a lobe's colour the raster record keeps as diffuse albedo: glass shows
        its specular reflection alone (what Cycles' direct light sees of it), Principled
        transmission removes that share of the diffuse."""
        if m.bsdf in ("glass", "refraction"):
            return 0.0
        if m.bsdf == "principled":
            return 1.0 - m.transmission
        return 1.0

    def blend(self, top: Material, weighted) -> None:
        """The G-buffer family's record: parameters blended by the lobes' mean weights."""
        tot = sum(m.weight for _, m, _ in weighted)
        if tot <= 0.0:
            top.base_color, top.specular_ior_level = (0.0, 0.0, 0.0), 0.0
            return
        for attr in ("metallic", "roughness", "ior", "specular_ior_level"):
            setattr(top, attr, float(sum(m.weight * getattr(m, attr) for _, m, _ in weighted) / tot))
        normals = [m.maps["normal"] for _, m, _ in weighted if "normal" in m.maps]
        if normals:
            top.maps["normal"] = normals[0]
            if len(normals) > 1:
                self.notes.append("the lobes share the first lobe's normal map")
        bumps = [m for _, m, _ in weighted if "bump" in m.maps]
        if bumps:
            top.maps["bump"], top.bump_strength = bumps[0].maps["bump"], bumps[0].bump_strength
            if len(bumps) > 1:
                self.notes.append("the lobes share the first lobe's bump")
        if len(weighted) == 1 and not weighted[0][1].maps.get("weight") and self.raster_diffuse(weighted[0][1]) > 0:
            m = weighted[0][1]
            k = m.weight * self.raster_diffuse(m)
            top.base_color = tuple(float(c) * k if k != 1.0 else float(c) for c in m.base_color)
            top.specular_tint = m.specular_tint
            for key in ("base_color", "roughness", "metallic", "specular_ior_level"):
                if key in m.maps and k == 1.0:
                    top.maps[key] = m.maps[key]
            if "base_color" in top.maps:
                top.base_color_texture = top.maps["base_color"].texture
            return
        expr = None
        for w, m, r in weighted:
            ce = r.exprs.get("base_color", NE.Const(tuple(float(c) for c in m.base_color)))
            k = self.raster_diffuse(m)
            if k != 1.0:
                w = _mul(w, NE.Const((k,)))
            term = NE.Op("vmath", ("SCALE",), (ce, NE.Const((0.0, 0.0, 0.0)), NE.Const((0.0, 0.0, 0.0)), w))
            expr = term if expr is None else NE.Op("vmath", ("ADD",), (expr, term, NE.Const((0.0, 0.0, 0.0)),
                                                                         NE.Const((1.0,))))
        rd = _MaterialReader(self.ex, self.mat, None)
        kind, val, *rest = rd.resolve(expr, 3, "blended Base Color")
        if kind == "const":
            top.base_color = _rgb(val)
        else:
            top.maps["base_color"] = val
            top.base_color = _rgb(rest[0])
            top.base_color_texture = val.texture
        self.notes.extend(rd.approx)


# ------------------------------------------------------------------------------ exporter
class _Exporter:
    def __init__(self, depsgraph, cache: "SceneExporter | None" = None):
        self.depsgraph = depsgraph
        self.data = SceneData()
        self._material_ids: dict[int, int] = {}
        self._texture_ids: dict[int, int] = {}
        self._bake_ids: dict[str, int] = {}
        self._tangent_maps: dict[int, str] = {}  # material index -> UV map its normal map uses
        self._uv_names: dict[int, set] = {}  # material index -> UV maps named by its nodes
        self._uv_square: dict[int, list] = {}
        self._color_maps: dict[int, str] = {}  # material index -> colour attribute its nodes read  # material index -> inputs baked from UV values
        self._mesh_ids: dict[tuple, int] = {}
        self._default_material: int | None = None
        self.cache = cache
        self.meshes_read = 0
        self.meshes_reused = 0

    # -------------------------------------------------------------- warnings
    def warn(self, msg: str) -> None:
        if msg not in self.data.warnings:
            self.data.warnings.append(msg)

    # -------------------------------------------------------------- materials
    def default_material(self) -> int:
        if self._default_material is None:
            self._default_material = len(self.data.materials)
            self.data.materials.append(Material(name=DEFAULT_MATERIAL_NAME,
                                                base_color=(0.8, 0.8, 0.8), roughness=0.5))
        return self._default_material

    def material(self, mat) -> int:
        if mat is None:
            return self.default_material()
        orig = getattr(mat, "original", None) or mat
        key = orig.as_pointer()
        if key in self._material_ids:
            return self._material_ids[key]
        m = self._convert_material(mat)
        m.bump_correction = bool(getattr(getattr(mat, "cycles", None), "use_bump_map_correction", True))
        for w in m.warnings:
            self.warn(w)
        idx = len(self.data.materials)
        self.data.materials.append(m)
        self._material_ids[key] = idx
        tu = getattr(m, "_tangent_uv", None)
        if tu is not None:
            self._tangent_maps[idx] = tu
        ca = getattr(m, "_color_attr", None)
        if ca is not None:
            self._color_maps[idx] = ca
        names = getattr(m, "_uv_names", None)
        if names:
            self._uv_names[idx] = names
        if getattr(m, "_uv_square", None):
            self._uv_square[idx] = m._uv_square
        return idx

    def _fallback(self, mat, reason: str) -> Material:
        msg = f"Material '{mat.name}': {reason}; using the viewport colour"
        return Material(name=mat.name, base_color=_rgb(mat.diffuse_color),
                        metallic=float(mat.metallic), roughness=float(mat.roughness),
                        alpha=float(mat.diffuse_color[3]), exact=False, warnings=[msg],
                        support=f"unsupported: {reason}; the viewport colour stands in")

    def _convert_material(self, mat) -> Material:
        tree = _node_tree(mat)
        if tree is None:
            return self._fallback(mat, "has no shader node tree")
        out = _output_node(tree)
        if out is None:
            return self._fallback(mat, "has no Material Output node")
        surf = out.inputs.get("Surface")
        found = _follow(surf) if surf is not None else None
        if found is None:
            # Cycles renders an unconnected surface black.
            return Material(name=mat.name, base_color=(0.0, 0.0, 0.0), roughness=1.0,
                            specular_ior_level=0.0)
        node, _ = found
        kind = node.bl_idname
        if kind in _LOBE_GRAPH_NODES or (kind == "ShaderNodeBsdfPrincipled" and _transmits(node)):
            try:
                return _LobeMaterial(self, mat).read(surf)
            except Unsupported as exc:
                return self._fallback(mat, str(exc))
        if kind == "ShaderNodeBsdfPrincipled":
            return _MaterialReader(self, mat, node).principled()
        if kind == "ShaderNodeEmission":
            r = _MaterialReader(self, mat, node)
            m = Material(name=mat.name, base_color=(0.0, 0.0, 0.0), roughness=1.0, specular_ior_level=0.0)
            r.emission(m, node.inputs["Color"], node.inputs["Strength"])
            return r.finish(m)
        if kind == "ShaderNodeBsdfDiffuse":
            r = _MaterialReader(self, mat, node)
            m = Material(name=mat.name, roughness=1.0, specular_ior_level=0.0)
            r.ignore_linked(("Roughness",))
            r.normal(m, node.inputs["Normal"])
            r.color(m, "base_color", node.inputs["Color"])
            return r.finish(m)
        if kind in ("ShaderNodeBsdfGlossy", "ShaderNodeBsdfAnisotropic", "ShaderNodeBsdfMetallic"):
            r = _MaterialReader(self, mat, node)
            col = node.inputs.get("Color") or node.inputs.get("Base Color")
            m = Material(name=mat.name, metallic=1.0, specular_ior_level=0.5)
            r.scalar(m, "roughness", node.inputs["Roughness"], "roughness")
            r.normal(m, node.inputs["Normal"])
            r.color(m, "base_color", col)
            return r.finish(m)
        return self._fallback(mat, f"shader node '{node.name}' ({kind}) on 'Surface' is not supported")

    # -------------------------------------------------------------- textures for materials
    def image_ref(self, image):
        """(texture index, content key, pixels) of an image for the node evaluator."""
        tex = self.texture(image)
        if tex < 0:
            return None
        orig = getattr(image, "original", None) or image
        px = self.data.textures[tex].pixels
        return tex, f"{orig.as_pointer()}:{px.shape[1]}x{px.shape[0]}", px

    def baked(self, name: str, key: str, make) -> int:
        """Index of a baked texture (made by ``make()`` -> (H, W, 4) float32), cached by ``key``."""
        idx = self._bake_ids.get(key)
        if idx is not None:
            return idx
        tex = self.cache._bakes.get(key) if self.cache is not None else None
        if tex is None:
            tex = Texture(name=name, pixels=np.ascontiguousarray(make(), np.float32))
            if self.cache is not None:
                self.cache._bakes[key] = tex
        idx = len(self.data.textures)
        self.data.textures.append(tex)
        self._bake_ids[key] = idx
        return idx

    def texture(self, image) -> int:
        orig = getattr(image, "original", None) or image
        key = orig.as_pointer()
        if key in self._texture_ids:
            return self._texture_ids[key]
        w, h = (int(image.size[0]), int(image.size[1]))
        idx = -1
        cached = self.cache._textures.get((key, w, h)) if self.cache is not None else None
        if cached is not None:
            tex, warn = cached
            if warn:
                self.warn(warn)
            idx = len(self.data.textures)
            self.data.textures.append(tex)
        elif w == 0 or h == 0:
            # a missing or unreadable file: Cycles shows such an image as magenta, so do we
            warn = (f"Image '{image.name}': no pixels (file '{image.filepath}' missing or unreadable); "
                    "rendered magenta, as Cycles does")
            self.warn(warn)
            idx = len(self.data.textures)
            tex = Texture(name=image.name, pixels=np.array([[MISSING_IMAGE_RGBA]], np.float32))
            self.data.textures.append(tex)
            if self.cache is not None:
                self.cache._textures[(key, w, h)] = (tex, warn)
        else:
            px = np.empty(w * h * 4, np.float32)
            image.pixels.foreach_get(px)
            px = px.reshape(h, w, 4)
            cs = image.colorspace_settings.name
            warn = None
            if not image.is_float and "srgb" in cs.lower() and "linear" not in cs.lower():
                px[..., :3] = _srgb_to_linear(px[..., :3])
            elif cs.lower() not in ("non-color", "linear rec.709", "linear", "raw") and \
                    "linear" not in cs.lower() and not image.is_float:
                warn = f"Image '{image.name}': colour space '{cs}' is treated as linear"
                self.warn(warn)
            idx = len(self.data.textures)
            tex = Texture(name=image.name, pixels=np.ascontiguousarray(px))
            self.data.textures.append(tex)
            if self.cache is not None:
                self.cache._textures[(key, w, h)] = (tex, warn)
        self._texture_ids[key] = idx
        return idx

    # -------------------------------------------------------------- geometry
    def slot_materials(self, ob, mesh) -> tuple[int, ...]:
        slots = ob.material_slots
        if len(slots):
            return tuple(self.material(s.material) for s in slots)
        mats = getattr(mesh, "materials", None)
        if mats is not None and len(mats):
            return tuple(self.material(m) for m in mats)
        return (self.default_material(),)

    def add_mesh(self, key, mesh, lut: tuple[int, ...], name: str, deps: tuple = ()) -> int:
        """Index of the evaluated ``mesh`` in ``data.meshes`` (read once per export; with a
        :class:`SceneExporter`, reused from the last export unless one of ``deps``, the
        names of the objects and data it comes from, had a geometry update)."""
        full_key = (key, lut)
        idx = self._mesh_ids.get(full_key)
        if idx is None:
            tangent_uv = next((self._tangent_maps[i] for i in lut if i in self._tangent_maps), None)
            color_attr = next((self._color_maps[i] for i in lut if i in self._color_maps), None)
            self._check_uv_names(mesh, lut)
            self._check_uv_square(mesh, lut)
            m = None
            ckey = None
            if self.cache is not None:
                ckey = (key, lut, len(mesh.vertices), len(mesh.polygons), name, tangent_uv, color_attr)
                hit = self.cache._meshes.get(ckey)
                if hit is not None:
                    m = hit[0]
                    hit[1].update(deps)
                    self.meshes_reused += 1
            if m is None:
                m = _read_mesh(mesh, np.asarray(lut, np.int32), name, tangent_uv, self.warn, color_attr)
                self.meshes_read += 1
                if ckey is not None:
                    self.cache._meshes[ckey] = (m, set(deps))
            if ckey is not None:
                self.cache._used.add(ckey)
            idx = len(self.data.meshes)
            self.data.meshes.append(m)
            self._mesh_ids[full_key] = idx
        return idx

    def _check_uv_square(self, mesh, lut) -> None:
        """A material input baked from a function of the UV values (not an image) is exact
        where the UVs stay inside [0, 1]: say so when this mesh's go outside (Extend there)."""
        mats = [i for i in set(lut) if i in self._uv_square]
        if not mats:
            return
        layers = mesh.uv_layers
        active = getattr(layers, "active_render", None) or layers.active
        inside = True
        if active is not None and len(mesh.loops):
            uv = np.empty(2 * len(mesh.loops), np.float32)
            active.data.foreach_get("uv", uv)
            inside = bool(uv.min() >= -1e-4 and uv.max() <= 1.0 + 1e-4)
        if inside:
            return
        for i in mats:
            m = self.data.materials[i]
            msg = (f"Material '{m.name}': {', '.join(repr(x) for x in self._uv_square[i])} baked over the UV "
                   f"square [0, 1] (Extend outside it, where mesh '{mesh.name}' has UVs)")
            self._approximate(m, msg)

    def _approximate(self, m, msg: str) -> None:
        """Mark material ``m`` not exact for ``msg`` ("Material 'x': why"), once."""
        if msg not in m.warnings:
            m.warnings.append(msg)
            m.exact = False
            if m.support == "exact":
                m.support = "approximated: " + msg.split(": ", 1)[1]
            self.warn(msg)

    def _check_uv_names(self, mesh, lut) -> None:
        """A material whose nodes name a UV map other than the mesh's render UV map is read
        with the render UV map: say so (not exact)."""
        layers = mesh.uv_layers
        active = getattr(layers, "active_render", None) or layers.active
        active_name = active.name if active is not None else ""
        for i in set(lut):
            for n in self._uv_names.get(i, ()):
                if n == active_name or n not in layers:
                    continue
                m = self.data.materials[i]
                msg = (f"Material '{m.name}': UV map '{n}' on mesh '{mesh.name}' is read as the render UV "
                       f"map '{active_name}'")
                self._approximate(m, msg)

    def add_instance(self, mesh_idx: int, matrix, object_name: str, instance_id: str = "") -> None:
        if self.data.meshes[mesh_idx].triangle_count == 0:
            return
        self.data.instances.append(Instance(mesh=mesh_idx, matrix=_matrix(matrix),
                                            object_name=object_name, instance_id=instance_id))

    def run_geometry_and_lights(self) -> None:
        dg = self.depsgraph
        render_mode = dg.mode == "RENDER"
        deferred = []  # curve/text/metaball objects whose mesh may come as an instance
        mesh_parents = set()
        for inst in dg.object_instances:
            ob = inst.object
            orig = ob.original
            if not render_mode and orig.hide_render:
                continue
            if inst.is_instance:
                par = inst.parent
                if par is not None and par.original.hide_render and not render_mode:
                    continue
            elif not inst.show_self:
                continue
            typ = ob.type
            if typ == "LIGHT":
                self.light(ob, inst.matrix_world)
            elif typ == "MESH":
                mesh = ob.data
                if mesh is None or len(mesh.polygons) == 0:
                    continue
                if inst.is_instance and inst.parent is not None and \
                        inst.parent.original.type in _TO_MESH_TYPES:
                    mesh_parents.add(inst.parent.original.as_pointer())
                lut = self.slot_materials(ob, mesh)
                deps = (orig.name_full, _data_name(orig))
                if inst.is_instance and inst.parent is not None:
                    deps += (inst.parent.original.name_full,)
                idx = self.add_mesh(("data", mesh.as_pointer()), mesh, lut,
                                    mesh.name if not inst.is_instance else f"{orig.name}:{mesh.name}", deps)
                self.add_instance(idx, inst.matrix_world, orig.name, instance_id(inst))
            elif typ in _TO_MESH_TYPES and not inst.is_instance:
                deferred.append((orig, _matrix(inst.matrix_world)))
        for orig, matrix in deferred:
            if orig.as_pointer() in mesh_parents:
                continue
            ob = orig.evaluated_get(dg)
            try:
                mesh = ob.to_mesh()
            except RuntimeError:
                mesh = None
            try:
                if mesh is not None and len(mesh.polygons):
                    lut = self.slot_materials(ob, mesh)
                    idx = self.add_mesh(("to_mesh", orig.as_pointer()), mesh, lut, orig.name,
                                        (orig.name_full, _data_name(orig)))
                    self.add_instance(idx, matrix, orig.name, orig.name_full)
            finally:
                ob.to_mesh_clear()

    # -------------------------------------------------------------- lights
    def light(self, ob, matrix_world) -> None:
        ld = ob.data
        typ = _LIGHT_TYPES.get(ld.type)
        if typ is None:
            self.warn(f"Light '{ob.name}': type {ld.type} is not supported; skipped")
            return
        energy = float(ld.energy)
        color = np.array(_rgb(ld.color), np.float64)
        if getattr(ld, "use_temperature", False):
            color *= np.array(_rgb(ld.temperature_color), np.float64)
        color *= 2.0 ** float(getattr(ld, "exposure", 0.0))
        m = _matrix(matrix_world)
        light = Light(name=ob.original.name, type=typ, matrix=m, color=np.zeros(3, np.float32),
                      cast_shadow=bool(getattr(ld, "use_shadow", True)), power=energy)
        if typ in (LightType.POINT, LightType.SPOT):
            value = energy * color / (4.0 * math.pi)
            light.radius = float(ld.shadow_soft_size)
            if typ == LightType.SPOT:
                light.spot_size = float(ld.spot_size)
                light.spot_blend = float(ld.spot_blend)
        elif typ == LightType.SUN:
            value = energy * color
            light.angle = float(ld.angle)
        else:
            light.shape = _AREA_SHAPES.get(ld.shape, AreaShape.SQUARE)
            sy = float(ld.size_y) if light.shape in (AreaShape.RECTANGLE, AreaShape.ELLIPSE) \
                else float(ld.size)
            light.size = (float(ld.size), sy)
            light.spread = float(getattr(ld, "spread", math.pi))
            if getattr(ld, "normalize", True):
                area = light.area()
                if area <= 0.0:
                    self.warn(f"Light '{ob.name}': area light of zero area; skipped")
                    return
                value = energy * color / (math.pi * area)
            else:
                value = energy * color / math.pi
        if getattr(ld, "use_nodes", False) and getattr(ld, "node_tree", None) is not None:
            self.warn(f"Light '{ob.name}': light shader nodes are ignored")
        light.color = np.asarray(value, np.float32)
        self.data.lights.append(light)

    # -------------------------------------------------------------- world
    def world(self, scene) -> None:
        wo = scene.world
        if wo is None:
            self.data.world = World()
            return
        tree = _node_tree(wo)
        fallback_color = np.array(_rgb(wo.color), np.float32)
        if tree is None:
            self.data.world = World(color=fallback_color)
            return
        out = _output_node(tree)
        found = _follow(out.inputs["Surface"]) if out is not None and "Surface" in out.inputs \
            else None
        if out is None or found is None:
            self.data.world = World()  # no surface: Cycles renders black
            return
        node = found[0]
        if node.bl_idname == "ShaderNodeBackground" and all(
                _follow(node.inputs[n]) is None for n in ("Color", "Strength")):
            col = np.array(_rgb(node.inputs["Color"].default_value), np.float32)
            self.data.world = World(color=col * np.float32(node.inputs["Strength"].default_value))
            return
        # anything else: Cycles evaluates the tree into an equirectangular map, once
        from . import world_bake

        warnings = []
        try:
            # the viewport (an exporter with a cache) never waits for Cycles
            px = world_bake.bake_world(wo, wait=self.cache is None)
        except (RuntimeError, OSError, subprocess.SubprocessError) as exc:
            msg = f"World '{wo.name}': {exc}; using the viewport colour"
            self.warn(msg)
            self.data.world = World(color=fallback_color, exact=False, warnings=[msg])
            return
        if px is None:
            msg = f"World '{wo.name}': being evaluated by Cycles; the viewport colour until it is ready"
            self.warn(msg)
            self.data.world = World(color=fallback_color, exact=False, warnings=[msg])
            return
        if world_bake.uses_light_path(wo):
            warnings.append(f"World '{wo.name}': the Light Path node is evaluated as camera rays see it; "
                            "light from the world may differ from Cycles")
            for w in warnings:
                self.warn(w)
        sun, px = _world_sun(px)
        sun_name = ""
        if sun is not None:
            sun_name = f"{wo.name} sun"
            self.data.lights.append(_sun_light(sun_name, sun))
        mean = world_map_of_pixels(px)
        self.data.world = World(color=mean, exact=not warnings, warnings=warnings, map=px, source="cycles",
                                sun_light=sun_name)

    # -------------------------------------------------------------- camera
    def camera(self, scene, cam_ob, width: int, height: int) -> None:
        if cam_ob is None:
            raise SceneError(f"Scene '{scene.name}' has no camera: add a camera and set it as "
                             "the scene camera (Scene Properties > Camera)")
        if cam_ob.type != "CAMERA":
            raise SceneError(f"Scene '{scene.name}': object '{cam_ob.name}' used as camera is "
                             f"a {cam_ob.type}, not a camera")
        ev = cam_ob.evaluated_get(self.depsgraph)
        cd = ev.data
        if cd.type not in ("PERSP", "ORTHO"):
            raise SceneError(f"Scene '{scene.name}': camera '{cam_ob.name}' is panoramic "
                             f"({cd.type}); GI Preview renders perspective and orthographic "
                             "cameras only")
        r = scene.render
        proj = ev.calc_matrix_camera(self.depsgraph, x=width, y=height,
                                     scale_x=r.pixel_aspect_x, scale_y=r.pixel_aspect_y)
        self.data.camera = Camera(name=cam_ob.name, matrix_world=_matrix(ev.matrix_world),
                                  projection=_matrix(proj), type=cd.type,
                                  clip_start=float(cd.clip_start), clip_end=float(cd.clip_end))


_SUNS: dict[int, tuple] = {}  # id(baked map) -> (map, sun, residual): one split per map


def _world_sun(px: np.ndarray):
    """(sun or None, the map without it) for a baked map, cached per map array."""
    hit = _SUNS.get(id(px))
    if hit is not None and hit[0] is px:
        return hit[1], hit[2]
    sun, residual = extract_sun(px)
    while len(_SUNS) >= 4:
        _SUNS.pop(next(iter(_SUNS)))
    _SUNS[id(px)] = (px, sun, residual)
    return sun, residual


def _sun_light(name: str, sun: dict) -> Light:
    """A sun light along the extracted sun's direction, of its irradiance and size."""
    z = np.asarray(sun["direction"], np.float64)  # lights shine along -Z: +Z points at the sun
    helper = np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    m = np.eye(4, dtype=np.float32)
    m[:3, 0], m[:3, 1], m[:3, 2] = x, y, z
    e = np.asarray(sun["irradiance"], np.float32)
    return Light(name=name, type=LightType.SUN, matrix=m, color=e, angle=float(sun["angle"]),
                 cast_shadow=True, power=float(e.mean()))


def world_map_of_pixels(px: np.ndarray) -> np.ndarray:
    """The solid-angle mean radiance of an equirectangular map (the world's uniform colour)."""
    return np.asarray(world_map_of(World(map=px)).mean, np.float32)


_NO_ID = 2147483647  # unused slots of DepsgraphObjectInstance.persistent_id


def _data_name(ob) -> str:
    data = getattr(ob, "data", None)
    return f"data:{data.name_full}" if data is not None else ""


def instance_id(inst) -> str:
    """A stable id of one ``DepsgraphObjectInstance``: the object's name for a real object,
    ``"<instancer>/<object>/<persistent id>"`` for an instance (collection instances,
    particles, geometry nodes). The persistent id is relative to the instancer, so the
    instancer's name makes it unique; it stays the same from frame to frame."""
    orig = inst.object.original
    if not inst.is_instance:
        return orig.name_full
    par = inst.parent
    pid = [int(x) for x in inst.persistent_id]
    while pid and pid[-1] == _NO_ID:
        pid.pop()
    return f"{par.original.name_full if par is not None else ''}/{orig.name_full}/{'.'.join(map(str, pid))}"


def _read_tangents(mesh, uv_name: str, corners: np.ndarray, warn) -> np.ndarray | None:
    """Per-corner MikkTSpace tangents of a UV map (xyz, bitangent sign), as Cycles reads them."""
    layers = mesh.uv_layers
    layer = layers.get(uv_name) if uv_name else (getattr(layers, "active_render", None) or layers.active)
    if layer is None:
        warn(f"Mesh '{mesh.name}': no UV map '{uv_name}' for its normal map's tangents")
        return None
    nl = len(mesh.loops)
    try:
        mesh.calc_tangents(uvmap=layer.name)
    except RuntimeError as exc:
        warn(f"Mesh '{mesh.name}': tangents of UV map '{layer.name}' failed ({exc})")
        return None
    try:
        t = np.empty(3 * nl, np.float32)
        mesh.loops.foreach_get("tangent", t)
        sign = np.empty(nl, np.float32)
        mesh.loops.foreach_get("bitangent_sign", sign)
    finally:
        mesh.free_tangents()
    out = np.empty((nl, 4), np.float32)
    out[:, :3] = t.reshape(nl, 3)
    out[:, 3] = sign
    return np.ascontiguousarray(out[corners])


def _read_colors(mesh, name: str, corners: np.ndarray, corner_vert: np.ndarray, warn) -> np.ndarray | None:
    """Per-corner linear RGBA of the colour attribute ``name`` ("" = the render colour
    attribute), point or corner domain; None (black in Cycles) when the mesh has none."""
    ca = mesh.color_attributes
    attr = ca.get(name) if name else None
    if attr is None and not name:
        idx = getattr(ca, "render_color_index", -1)
        attr = ca[idx] if 0 <= idx < len(ca) else (ca.active_color if hasattr(ca, "active_color") else None)
    if attr is None:
        attr = mesh.attributes.get(name) if name else None
        if attr is None or attr.data_type not in ("FLOAT_COLOR", "BYTE_COLOR"):
            warn(f"Mesh '{mesh.name}' has no colour attribute '{name}'; it reads as black (as in Cycles)")
            return None
    n = len(attr.data)
    buf = np.empty(4 * n, np.float32)
    attr.data.foreach_get("color", buf)
    buf = buf.reshape(n, 4)
    if attr.domain == "POINT":
        return np.ascontiguousarray(buf[corner_vert[corners]])
    if attr.domain == "CORNER":
        return np.ascontiguousarray(buf[corners])
    warn(f"Mesh '{mesh.name}': colour attribute '{attr.name}' on the {attr.domain} domain is not read")
    return None


def _read_mesh(mesh, lut: np.ndarray, name: str, tangent_uv: str | None = None, warn=None,
               color_attr: str | None = None) -> Mesh:
    """Triangle-soup arrays of an evaluated mesh (no per-element Python loops)."""
    mesh.calc_loop_triangles()
    tris = mesh.loop_triangles
    nt = len(tris)
    corners = np.empty(3 * nt, np.int32)
    tris.foreach_get("loops", corners)
    nv = len(mesh.vertices)
    pos = np.empty(3 * nv, np.float32)
    mesh.attributes["position"].data.foreach_get("vector", pos)
    pos = pos.reshape(nv, 3)
    nl = len(mesh.loops)
    cv_attr = mesh.attributes.get(".corner_vert")
    corner_vert = np.empty(nl, np.int32)
    if cv_attr is not None and cv_attr.domain == "CORNER" and cv_attr.data_type == "INT":
        cv_attr.data.foreach_get("value", corner_vert)
    else:
        mesh.loops.foreach_get("vertex_index", corner_vert)
    positions = pos[corner_vert[corners]]
    nrm = np.empty(3 * nl, np.float32)
    mesh.corner_normals.foreach_get("vector", nrm)
    normals = nrm.reshape(nl, 3)[corners]
    uv_layer = mesh.uv_layers.active_render if hasattr(mesh.uv_layers, "active_render") else None
    if uv_layer is None:
        uv_layer = mesh.uv_layers.active
    if uv_layer is not None:
        uv = np.empty(2 * nl, np.float32)
        uv_layer.uv.foreach_get("vector", uv)
        uvs = uv.reshape(nl, 2)[corners]
    else:
        uvs = np.zeros((3 * nt, 2), np.float32)
    mat_attr = mesh.attributes.get("material_index")
    if mat_attr is not None and mat_attr.domain == "FACE" and len(lut) > 1:
        poly_mat = np.empty(len(mesh.polygons), np.int32)
        mat_attr.data.foreach_get("value", poly_mat)
        tri_poly = np.empty(nt, np.int32)
        mesh.loop_triangle_polygons.foreach_get("value", tri_poly)
        tri_mat = np.clip(poly_mat[tri_poly], 0, len(lut) - 1)
        material_ids = lut[tri_mat]
    else:
        material_ids = np.full(nt, lut[0] if len(lut) else -1, np.int32)
    tangents = None
    if tangent_uv is not None and nt:
        tangents = _read_tangents(mesh, tangent_uv, corners, warn or (lambda msg: None))
    colors = None
    if color_attr is not None and nt:
        colors = _read_colors(mesh, color_attr, corners, corner_vert, warn or (lambda msg: None))
    return Mesh(name=name, positions=np.ascontiguousarray(positions),
                normals=np.ascontiguousarray(normals), uvs=np.ascontiguousarray(uvs),
                material_ids=np.ascontiguousarray(material_ids, dtype=np.int32), tangents=tangents,
                colors=colors)


def export_scene(depsgraph, *, width: int | None = None, height: int | None = None,
                 camera=None, view_camera: Camera | None = None,
                 cache: "SceneExporter | None" = None) -> SceneData:
    """Convert an evaluated depsgraph into a :class:`SceneData`.

    ``width``/``height`` default to the scene's render resolution times its percentage;
    ``camera`` (a camera object) defaults to ``scene.camera``; ``view_camera`` (a ready
    :class:`Camera`, e.g. the 3D viewport's view) replaces the camera object entirely. Raises
    :class:`SceneError` for a missing or panoramic camera and for a resolution below 4 pixels.
    """
    scene = depsgraph.scene_eval
    r = scene.render
    if width is None:
        width = int(r.resolution_x * r.resolution_percentage / 100)
    if height is None:
        height = int(r.resolution_y * r.resolution_percentage / 100)
    width, height = int(width), int(height)
    if width < 4 or height < 4:
        raise SceneError(f"Scene '{scene.name}': the render resolution {width}x{height} is too "
                         "small; GI Preview needs at least 4x4 pixels")
    ex = _Exporter(depsgraph, cache)
    if view_camera is not None:
        ex.data.camera = view_camera
    else:
        ex.camera(scene, camera if camera is not None else scene.camera, width, height)
    ex.run_geometry_and_lights()
    ex.world(scene)
    data = ex.data
    data.width, data.height = width, height
    data.frame = int(scene.frame_current)
    data.film_transparent = bool(r.film_transparent)
    data.name = scene.name
    if cache is not None:
        cache.last_stats = {"meshes_read": ex.meshes_read, "meshes_reused": ex.meshes_reused}
    return data


class SceneExporter:
    """Exports one depsgraph again and again, reading only what changed (the viewport).

    ``export(depsgraph, updates=None, ...)`` returns a new :class:`SceneData` each time, but
    hands back the *same* ``Mesh`` objects (numpy arrays) for geometry that did not change,
    so nothing is re-read from Blender and the GPU scene neither re-hashes nor re-uploads
    them: moving an object costs one walk over ``depsgraph.object_instances`` (matrices,
    lights, materials). ``updates`` is ``depsgraph.updates`` of the view update: every ID
    with ``is_updated_geometry`` (an object, or its mesh/curve data) drops the meshes read
    from it; an updated image drops the cached texture pixels. ``updates=None`` forgets
    everything (a full export). A new SceneData rather than an edit in place, because the
    GL thread may still be rendering the previous one.

    ``last_stats``: ``meshes_read`` / ``meshes_reused`` of the last export."""

    def __init__(self):
        self._meshes: dict = {}  # key -> (Mesh, set of dependency names)
        self._textures: dict = {}  # (image pointer, w, h) -> (Texture, warning)
        self._bakes: dict = {}  # node-expression key -> baked Texture
        self._used: set = set()
        self.last_stats: dict = {}

    def invalidate(self, updates) -> None:
        dirty = set()
        images = False
        for u in updates:
            idb = u.id
            if isinstance(idb, bpy.types.Image):
                images = True
                continue
            if not u.is_updated_geometry:
                continue
            orig = getattr(idb, "original", None) or idb
            name = orig.name_full
            if isinstance(idb, bpy.types.Object):
                dirty.add(name)
            else:
                dirty.add(f"data:{name}")
        if images:
            self._textures.clear()
            self._bakes.clear()
        if dirty:
            for k in [k for k, (_, deps) in self._meshes.items() if deps & dirty]:
                del self._meshes[k]

    def export(self, depsgraph, updates=None, **kwargs) -> SceneData:
        if updates is None:
            self._meshes.clear()
            self._textures.clear()
            self._bakes.clear()
        else:
            self.invalidate(updates)
        self._used = set()
        data = export_scene(depsgraph, cache=self, **kwargs)
        for k in [k for k in self._meshes if k not in self._used]:  # objects gone
            del self._meshes[k]
        return data
