"""Panels: GI Preview's own render panels, and Blender's panels that make sense for it."""
from __future__ import annotations

import bpy

from ..render import techniques
from . import engine as engine_mod
from . import properties

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

    def split_layout(self):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        return layout


def _info(tid: str):
    try:
        return techniques.get(tid).info()
    except ValueError:
        return None


class GIPREVIEW_RENDER_PT_technique(GIPreviewPanel, bpy.types.Panel):
    """The technique and its quality (the parent of GI Preview's render panels)."""

    bl_label = "GI Preview"

    def draw(self, context):
        layout = self.split_layout()
        s = context.scene.gi_preview
        layout.prop(s, "technique")
        layout.prop(s, "quality_preset")
        if s.technique == "AUTO":
            layout.prop(s, "auto_frame_budget")
            layout.prop(s, "auto_target_error")
            layout.prop(s, "auto_threshold")
        info = _info(s.technique) if s.technique != "AUTO" else None
        if info is not None:
            layout.label(text=f"Compared with Cycles: {info.reference.replace('_', ' ')} reference", icon="INFO")


def draw_settings(layout, s, settings):
    """One row per setting (the technique's or a filter's)."""
    col = layout.column(align=True)
    for st in settings:
        col.prop(s, st.prop)


class GIPREVIEW_RENDER_PT_technique_settings(GIPreviewPanel, bpy.types.Panel):
    """The selected technique's settings (0 keeps the Quality level's value)."""

    bl_label = "Technique Settings"
    bl_parent_id = "GIPREVIEW_RENDER_PT_technique"

    @classmethod
    def poll(cls, context):
        if not super().poll(context):
            return False
        s = context.scene.gi_preview
        info = _info(s.technique)
        return bool(properties.technique_settings(s.technique)) or (info is not None and info.family == "probes")

    def draw(self, context):
        layout = self.split_layout()
        s = context.scene.gi_preview
        draw_settings(layout, s, properties.technique_settings(s.technique))
        info = _info(s.technique)
        if info is not None and info.family == "probes":
            layout.prop(s, "show_probes")


class GIPREVIEW_RENDER_PT_sampling(GIPreviewPanel, bpy.types.Panel):
    bl_label = "Sampling"
    bl_parent_id = "GIPREVIEW_RENDER_PT_technique"

    def draw(self, context):
        layout = self.split_layout()
        s = context.scene.gi_preview
        col = layout.column(align=True)
        col.prop(s, "samples", text="Render Samples")
        col.prop(s, "viewport_samples", text="Viewport Samples")
        layout.prop(s, "viewport_scale")


class GIPREVIEW_RENDER_PT_denoising(GIPreviewPanel, bpy.types.Panel):
    bl_label = "Denoising"
    bl_parent_id = "GIPREVIEW_RENDER_PT_sampling"

    def draw(self, context):
        layout = self.split_layout()
        s = context.scene.gi_preview
        layout.prop(s, "denoiser")
        layout.prop(s, "use_taa")
        # the filters' own settings, unless the technique's panel shows them (ATROUS/SVGF/TAA)
        extra = [st for st in properties.filter_settings(s, s.technique) if s.technique not in st.techniques]
        draw_settings(layout, s, extra)


REFERENCE_NAMES = {i[0]: i[1] for i in properties.COMPARE_REFERENCE_ITEMS}


class GIPREVIEW_RENDER_PT_compare(GIPreviewPanel, bpy.types.Panel):
    bl_label = "Compare with Cycles"
    bl_parent_id = "GIPREVIEW_RENDER_PT_technique"

    def draw(self, context):
        from .compare_ops import GIPREVIEW_OT_compare, _fmt, load_results

        layout = self.split_layout()
        scene = context.scene
        s = scene.gi_preview
        col = layout.column(align=True)
        col.prop(s, "compare_reference")
        col.prop(s, "compare_samples")
        op = layout.operator(GIPREVIEW_OT_compare.bl_idname, icon="IMAGE_REFERENCE")
        op.reference = s.compare_reference
        op.ref_spp = s.compare_samples
        res = load_results(scene)
        if not res:
            layout.label(text="No comparison yet", icon="INFO")
            return
        box = layout.box()
        box.use_property_split = False
        grid = box.grid_flow(row_major=True, columns=7, even_columns=False, align=True)
        for title in ("Technique", "Reference", "relMSE", "FLIP", "SSIM", "ms/frame", "Setup ms"):
            grid.label(text=title)
        for tech in sorted(res):
            e = res[tech]
            grid.label(text=f"{properties.technique_label(tech)} q{e.get('quality', '')}")
            ref = REFERENCE_NAMES.get(str(e.get("reference", "")).upper(), e.get("reference"))
            grid.label(text=f"{ref} {e.get('ref_spp', '')}".strip() if ref else "-")
            grid.label(text=_fmt(e.get("relmse")))
            grid.label(text=_fmt(e.get("flip")))
            grid.label(text=_fmt(e.get("ssim"), "{:.3f}"))
            grid.label(text=_fmt(e.get("ms_per_frame"), "{:.1f}"))
            grid.label(text=_fmt(e.get("setup_ms"), "{:.0f}"))
        last = res.get(getattr(getattr(scene, "gi_preview_comparison", None), "last_technique", ""), None)
        if last and last.get("nonfinite_pixels"):
            box.label(text=f"{last['nonfinite_pixels']} non-finite pixels", icon="ERROR")


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
        quality = {v: n for _i, n, _d, v in properties.QUALITY_ITEMS}.get(info["quality"], info["quality"])
        col.label(text=f"{properties.technique_label(info['technique'])} ({quality}): {info['samples']} samples, "
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
        skipped = engine_mod.skipped_text(_Skipped(info.get("skipped_passes", [])))
        for part in skipped.split("; ") if skipped else ():
            col.label(text=f"Skipped {part}", icon="FORWARD")
        for name, ms in info.get("pass_ms", {}).items():
            col.label(text=f"  {name}: {ms:.2f} ms")


class _Skipped:
    """``last_render``'s skipped passes (dicts) in the shape ``engine.skipped_text`` reads."""

    def __init__(self, rows):
        from types import SimpleNamespace

        self.skipped_passes = [SimpleNamespace(name=r.get("pass"), effects=r.get("effects", []),
                                               reason=r.get("reason", "")) for r in rows]


# parents before children (registration order)
classes = (GIPREVIEW_RENDER_PT_technique, GIPREVIEW_RENDER_PT_technique_settings, GIPREVIEW_RENDER_PT_sampling,
           GIPREVIEW_RENDER_PT_denoising, GIPREVIEW_RENDER_PT_compare, GIPREVIEW_RENDER_PT_last)

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
