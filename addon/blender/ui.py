"""Panels: GI Preview's own render panels, and Blender's panels that make sense for it."""
from __future__ import annotations

import bpy

from ..render import techniques
from . import engine as engine_mod

ENGINE = "GI_PREVIEW"

# Blender panels (besides every panel listing BLENDER_RENDER) that apply to GI Preview.
EXTRA_PANELS = (
    "EEVEE_MATERIAL_PT_surface", "EEVEE_MATERIAL_PT_context_material", "EEVEE_MATERIAL_PT_settings",
    "EEVEE_WORLD_PT_surface", "DATA_PT_EEVEE_light", "DATA_PT_light", "DATA_PT_EEVEE_light_distance",
    "DATA_PT_spot", "DATA_PT_context_light", "RENDER_PT_color_management",
    "DATA_PT_lens", "DATA_PT_camera", "DATA_PT_camera_dof", "DATA_PT_context_camera",
    "RENDER_PT_format", "RENDER_PT_frame_range", "RENDER_PT_output", "RENDER_PT_encoding",
    "VIEWLAYER_PT_layer_passes",
)


class GIPreviewPanel:
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "render"
    COMPAT_ENGINES = {ENGINE}

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES


class GIPREVIEW_RENDER_PT_technique(GIPreviewPanel, bpy.types.Panel):
    bl_label = "GI Preview"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        s = context.scene.gi_preview
        layout.prop(s, "technique")
        layout.prop(s, "quality")
        layout.prop(s, "denoiser")
        layout.prop(s, "use_taa")
        col = layout.column(align=True)
        col.prop(s, "samples", text="Render Samples")
        col.prop(s, "viewport_samples", text="Viewport Samples")
        layout.prop(s, "viewport_scale")
        if s.technique != "AUTO":
            try:
                info = techniques.get(s.technique).info()
                if info.family == "probes":
                    layout.prop(s, "show_probes")
                layout.label(text=f"Compared with Cycles: {info.reference} reference", icon="INFO")
            except ValueError:
                pass


class GIPREVIEW_RENDER_PT_last(GIPreviewPanel, bpy.types.Panel):
    bl_label = "Last Render"
    bl_parent_id = "GIPREVIEW_RENDER_PT_technique"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        info = engine_mod.last_render
        col = self.layout.column(align=True)
        if not info:
            col.label(text="No render yet")
            return
        col.label(text=f"{info['technique']} q{info['quality']}: {info['samples']} samples, "
                       f"{info['frame_ms']:.1f} ms/frame")
        sup = info.get("scene_support")
        if sup:
            col.label(text=sup["summary"], icon="CHECKMARK" if sup["counts"]["materials_exact"] ==
                      sup["counts"]["materials"] else "INFO")
            for kind in ("materials", "lights"):
                for name, e in sup[kind].items():
                    if e["status"] != "exact":
                        col.label(text=f"  {name}: {e['status']}: {e['detail']}")
            if sup["world"]["status"] != "exact":
                col.label(text=f"  World: {sup['world']['status']}: {sup['world']['detail']}")
        for name, ms in info.get("pass_ms", {}).items():
            col.label(text=f"  {name}: {ms:.2f} ms")
        for s in info.get("skipped_passes", []):
            col.label(text=f"Skipped {s['pass']}: {s['reason']}", icon="FORWARD")


class GIPREVIEW_RENDER_PT_compare(GIPreviewPanel, bpy.types.Panel):
    bl_label = "Compare with Cycles"
    bl_parent_id = "GIPREVIEW_RENDER_PT_technique"

    def draw(self, context):
        from .compare_ops import draw_comparison

        draw_comparison(self.layout, context.scene)


classes = (GIPREVIEW_RENDER_PT_technique, GIPREVIEW_RENDER_PT_last, GIPREVIEW_RENDER_PT_compare)

_added: list = []


def get_panels():
    exclude = {"VIEWLAYER_PT_filter", "VIEWLAYER_PT_layer_passes_lightgroups"}
    panels = []
    for panel in bpy.types.Panel.__subclasses__():
        engines = getattr(panel, "COMPAT_ENGINES", None)
        if engines is None or panel.__name__ in exclude:
            continue
        if "BLENDER_RENDER" in engines or panel.__name__ in EXTRA_PANELS:
            panels.append(panel)
    return panels


def register_panels():
    for panel in get_panels():
        if ENGINE not in panel.COMPAT_ENGINES:
            panel.COMPAT_ENGINES.add(ENGINE)
            _added.append(panel)


def unregister_panels():
    while _added:
        panel = _added.pop()
        panel.COMPAT_ENGINES.discard(ENGINE)
