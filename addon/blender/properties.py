"""Scene settings: ``scene.gi_preview`` (public contract: scripts and saved files rely on these names)."""
from __future__ import annotations

import zlib

import bpy

from ..render import techniques


def enum_value(identifier: str) -> int:
    """The number a .blend file stores for an enum item: Blender saves an enum property as its
    item's integer value, and items without one are numbered by position, so inserting an item
    would change what every saved file reads. Technique ids keep the value of their name."""
    return zlib.crc32(identifier.encode()) & 0x7FFFFFFF


def technique_items() -> list:
    """Every registered technique (AUTO first), as static enum items (introspectable by
    scripts through ``bl_rna``) with stable values (``enum_value``); built when the add-on
    registers."""
    infos = sorted(techniques.available(), key=lambda i: i.id != "AUTO")
    return [(i.id, i.label, i.description, enum_value(i.id)) for i in infos]


def _update(self, context):
    # Any change restarts the viewport's accumulation (handled by the engine comparing keys).
    for area in getattr(getattr(context, "screen", None), "areas", []) or []:
        if area.type == "VIEW_3D":
            area.tag_redraw()


class GIPreviewSceneSettings(bpy.types.PropertyGroup):
    technique: bpy.props.EnumProperty(
        name="Technique", items=technique_items(), default="AUTO", update=_update,
        description="Global-illumination technique GI Preview renders with")
    samples: bpy.props.IntProperty(
        name="Samples", default=16, min=1, max=65536, soft_max=1024,
        description="Frames accumulated by an F12 render (anti-aliasing, soft shadows, noise)")
    viewport_samples: bpy.props.IntProperty(
        name="Viewport Samples", default=16, min=1, max=65536, soft_max=1024,
        description="Frames the viewport accumulates while nothing changes")
    quality: bpy.props.IntProperty(
        name="Quality", default=1, min=0, max=3, update=_update,
        description="Level of the technique's quality ladder (0 = fastest, 3 = most accurate)")
    denoiser: bpy.props.EnumProperty(
        name="Denoiser", default="AUTO", update=_update,
        # explicit values: files saved before "AUTO" existed stored NONE/ATROUS/SVGF as 0/1/2
        items=[("AUTO", "Technique Default", "The technique's own filter: SVGF for ReSTIR GI (meant to be shown "
                "filtered), none for every other technique (PT stays the unfiltered reference)", 3),
               ("NONE", "None", "No filter", 0),
               ("ATROUS", "À-Trous", "Edge-avoiding à-trous wavelet filter (Dammertz 2010)", 1),
               ("SVGF", "SVGF", "Spatiotemporal variance-guided filtering (Schied 2017)", 2)],
        description="Filter that ends the technique's frame graph (for noisy techniques)")
    use_taa: bpy.props.BoolProperty(
        name="TAA", default=False, update=_update,
        description="End the frame graph with temporal anti-aliasing (Karis 2014)")
    show_probes: bpy.props.BoolProperty(
        name="Show Probes", default=False, update=_update,
        description="Rendered viewport: draw the probes of a probe technique (Irradiance volume, DDGI, "
                    "RTXGI) as small spheres shaded with their irradiance")
    viewport_scale: bpy.props.FloatProperty(
        name="Viewport Resolution", default=0.5, min=0.1, max=1.0, subtype="FACTOR",
        description="Viewport render resolution relative to the region (lower is faster)")


classes = (GIPreviewSceneSettings,)


def register_props():
    bpy.types.Scene.gi_preview = bpy.props.PointerProperty(type=GIPreviewSceneSettings)


def unregister_props():
    del bpy.types.Scene.gi_preview
