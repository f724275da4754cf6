"""Shader nodes -> ``render.node_eval`` expressions (the bpy half of the node evaluator).

``capture(socket, image_ref)`` follows the links into one input socket and returns an
expression tree of the nodes upstream, or raises :class:`node_eval.Unsupported` naming the
first node it cannot express (procedural textures, Geometry / Object / Generated
coordinates, node groups: anything that depends on more than the UV map). ``image_ref``
turns a ``bpy.types.Image`` into ``(texture index, content key, pixels)`` (the exporter's
texture table) or None when the image has no pixels.

Supported: Image Texture (Flat projection; Linear, Closest, Cubic/Smart read as Linear;
Repeat/Extend/Clip/Mirror; Color and Alpha), UV Map, Texture Coordinate's UV, Mapping,
Math, Vector Math (component-wise subset), Mix (float, vector, colour with every blend mode
but Hue/Saturation/Value/Color), legacy MixRGB, Invert, Color Ramp (RGB, Linear /
Constant / Ease), RGB, Value, Separate/Combine Color (RGB, HSV) and the legacy
Separate/Combine RGB, Gamma, Bright/Contrast, Hue/Saturation/Value, reroutes; implicit
conversions as Blender makes them (colour -> float by luminance, vector -> float by the
mean of the components, float -> colour/vector by copy).
"""
from __future__ import annotations

from ..render.node_eval import Const, Image, Op, Unsupported, UV

_PASS_THROUGH = {"NodeReroute"}
_CUBIC = ("Cubic", "Smart")


def follow_link(socket):
    """(from_node, from_socket) feeding ``socket`` through reroutes; None when unlinked.
    The one walk over links that the exporter and the node reader share."""
    seen = 0
    while socket is not None and socket.is_linked and seen < 64:
        link = next((lk for lk in socket.links if lk.is_valid and not lk.is_muted), None)
        if link is None:
            return None
        node = link.from_node
        if node.bl_idname in _PASS_THROUGH:
            socket = node.inputs[0] if node.inputs else None
            seen += 1
            continue
        return node, link.from_socket
    return None


def _link_into(socket):
    """follow_link, refusing a muted node (the reader cannot express what it passes on)."""
    found = follow_link(socket)
    if found is not None and getattr(found[0], "mute", False):
        node = found[0]
        raise Unsupported(f"node '{node.name}' ({node.bl_idname}) is muted")
    return found


def _socket_channels(sock) -> int:
    return 1 if sock.type in ("VALUE", "INT", "BOOLEAN") else 3


def _default(sock) -> Const:
    v = sock.default_value
    if sock.type in ("VALUE", "INT", "BOOLEAN"):
        return Const((float(v),))
    return Const((float(v[0]), float(v[1]), float(v[2])))


def _convert(expr, from_sock, to_sock):
    fc = 1 if from_sock.type in ("VALUE", "INT", "BOOLEAN") else 3
    tc = _socket_channels(to_sock)
    if fc == tc:
        return expr
    if tc == 1:
        return Op("to_float", ("VECTOR" if from_sock.type == "VECTOR" else "RGBA",), (expr,))
    return Op("to_color", (), (expr,))


class Capture:
    """Builds expressions for the inputs of one material; ``notes`` collects approximations."""

    def __init__(self, image_ref):
        self.image_ref = image_ref
        self.notes: list[str] = []
        self._memo: dict = {}

    def socket(self, sock):
        """The value arriving at input ``sock`` (its default when unlinked)."""
        found = _link_into(sock)
        if found is None:
            return _default(sock)
        node, out = found
        expr = self.output(node, out)
        return _convert(expr, out, sock)

    def output(self, node, out):
        key = (node.as_pointer(), out.identifier)
        if key in self._memo:
            return self._memo[key]
        expr = self._output(node, out)
        self._memo[key] = expr
        return expr

    def _in(self, node, name):
        return self.socket(node.inputs[name])

    def _in_id(self, node, identifier):
        sock = next(s for s in node.inputs if s.identifier == identifier)
        return self.socket(sock)

    def _const_values(self, node, name):
        from ..render.node_eval import is_const
        e = self._in(node, name)
        if not is_const(e):
            raise Unsupported(f"node '{node.name}' ({node.bl_idname}) input '{name}' is not constant")
        from ..render.node_eval import evaluate
        return tuple(float(x) for x in evaluate(e, [[0.5, 0.5]])[0])

    def _output(self, node, out):
        k = node.bl_idname
        name = f"node '{node.name}' ({k})"
        if k == "ShaderNodeTexImage":
            if node.image is None:
                raise Unsupported(f"{name} has no image")
            if node.projection != "FLAT":
                raise Unsupported(f"{name} uses {node.projection} projection")
            ref = self.image_ref(node.image)
            if ref is None:
                raise Unsupported(f"{name}: image '{node.image.name}' has no pixels")
            tex, key, pixels = ref
            vec_sock = node.inputs.get("Vector")
            vector = self.socket(vec_sock) if vec_sock is not None and _link_into(vec_sock) is not None else UV("")
            interp = node.interpolation
            if interp in _CUBIC:
                self.notes.append(f"{name}: {interp} interpolation read as Linear")
                interp = "Linear"
            return Image(texture=tex, key=key, interpolation=interp, extension=node.extension, vector=vector,
                         output="Alpha" if out.identifier == "Alpha" else "Color", pixels=pixels)
        if k == "ShaderNodeUVMap":
            return UV(node.uv_map or "")
        if k == "ShaderNodeTexCoord":
            if out.identifier == "UV":
                return UV("")
            raise Unsupported(f"{name} output '{out.name}' depends on position")
        if k == "ShaderNodeMapping":
            vtype = node.vector_type
            loc = self._const_values(node, "Location") if "Location" in node.inputs and vtype in ("POINT", "TEXTURE") \
                else (0.0, 0.0, 0.0)
            rot = self._const_values(node, "Rotation")
            scale = self._const_values(node, "Scale") if "Scale" in node.inputs else (1.0, 1.0, 1.0)
            return Op("mapping", (vtype, loc, rot, scale), (self._in(node, "Vector"),))
        if k == "ShaderNodeMath":
            args = tuple(self.socket(node.inputs[i]) for i in range(3))
            return Op("math", (node.operation, bool(node.use_clamp)), args)
        if k == "ShaderNodeVectorMath":
            op = node.operation
            from ..render.node_eval import _VMATH_SCALAR
            ok = ("ADD SUBTRACT MULTIPLY DIVIDE MULTIPLY_ADD SCALE ABSOLUTE MINIMUM MAXIMUM FLOOR FRACTION "
                  "DOT_PRODUCT LENGTH DISTANCE NORMALIZE").split()
            if op not in ok:
                raise Unsupported(f"{name} operation {op}")
            vecs = [s for s in node.inputs if s.type == "VECTOR"]
            args = tuple(self.socket(s) for s in vecs[:3])
            while len(args) < 3:
                args += (Const((0.0, 0.0, 0.0)),)
            sc = next((s for s in node.inputs if s.identifier == "Scale"), None)
            args += (self.socket(sc) if sc is not None else Const((1.0,)),)
            expr = Op("vmath", (op,), args)
            if out.type == "VALUE" and op not in _VMATH_SCALAR:
                return Op("to_float", ("VECTOR",), (expr,))
            return expr
        if k == "ShaderNodeMix":
            dt = node.data_type
            if dt not in ("FLOAT", "VECTOR", "RGBA"):
                raise Unsupported(f"{name} data type {dt}")
            if dt == "VECTOR" and node.factor_mode != "UNIFORM":
                raise Unsupported(f"{name} non-uniform factor")
            suffix = {"FLOAT": "Float", "VECTOR": "Vector", "RGBA": "Color"}[dt]
            blend = node.blend_type if dt == "RGBA" else "MIX"
            if blend in ("HUE", "SATURATION", "VALUE", "COLOR"):
                raise Unsupported(f"{name} blend mode {blend}")
            fac = self._in_id(node, "Factor_Float")
            a = self._in_id(node, f"A_{suffix}")
            b = self._in_id(node, f"B_{suffix}")
            return Op("mix", (dt, blend, bool(node.clamp_factor), bool(getattr(node, "clamp_result", False))),
                      (fac, a, b))
        if k == "ShaderNodeMixRGB":
            blend = node.blend_type
            if blend in ("HUE", "SATURATION", "VALUE", "COLOR"):
                raise Unsupported(f"{name} blend mode {blend}")
            return Op("mix", ("RGBA", blend, True, bool(node.use_clamp)),
                      (self._in(node, "Fac"), self._in(node, "Color1"), self._in(node, "Color2")))
        if k == "ShaderNodeInvert":
            return Op("invert", (), (self._in(node, "Fac"), self._in(node, "Color")))
        if k == "ShaderNodeValToRGB":
            ramp = node.color_ramp
            if ramp.color_mode != "RGB":
                raise Unsupported(f"{name} colour mode {ramp.color_mode}")
            els = sorted(ramp.elements, key=lambda e: e.position)
            pos = tuple(float(e.position) for e in els)
            cols = tuple(float(c) for e in els for c in e.color)
            return Op("ramp", ("Alpha" if out.identifier == "Alpha" else "Color", ramp.interpolation, pos, cols),
                      (self._in(node, "Fac"),))
        if k == "ShaderNodeRGB":
            v = node.outputs[0].default_value
            return Const((float(v[0]), float(v[1]), float(v[2])))
        if k == "ShaderNodeValue":
            return Const((float(node.outputs[0].default_value),))
        if k in ("ShaderNodeSeparateColor", "ShaderNodeSeparateRGB", "ShaderNodeSeparateHSV"):
            mode = getattr(node, "mode", "HSV" if k == "ShaderNodeSeparateHSV" else "RGB")
            if mode not in ("RGB", "HSV"):
                raise Unsupported(f"{name} mode {mode}")
            ch = [o.identifier for o in node.outputs].index(out.identifier)
            return Op("separate", (mode, ch), (self.socket(node.inputs[0]),))
        if k in ("ShaderNodeCombineColor", "ShaderNodeCombineRGB", "ShaderNodeCombineHSV"):
            mode = getattr(node, "mode", "HSV" if k == "ShaderNodeCombineHSV" else "RGB")
            if mode not in ("RGB", "HSV"):
                raise Unsupported(f"{name} mode {mode}")
            return Op("combine", (mode,), tuple(self.socket(node.inputs[i]) for i in range(3)))
        if k == "ShaderNodeGamma":
            return Op("gamma", (), (self._in(node, "Color"), self._in(node, "Gamma")))
        if k == "ShaderNodeBrightContrast":
            return Op("bright_contrast", (), (self._in(node, "Color"), self._in(node, "Bright"),
                                               self._in(node, "Contrast")))
        if k == "ShaderNodeHueSaturation":
            return Op("hsv", (), tuple(self._in(node, n) for n in ("Hue", "Saturation", "Value", "Fac", "Color")))
        raise Unsupported(f"{name} is not supported")
