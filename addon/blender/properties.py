"""Scene settings: ``scene.gi_preview`` (public contract: scripts and saved files rely on these names)."""
from __future__ import annotations

import zlib
from dataclasses import dataclass

import bpy

from ..render import techniques


def enum_value(identifier: str) -> int:
    """The number a .blend file stores for an enum item: Blender saves an enum property as its
    item's integer value, and items without one are numbered by position, so inserting an item
    would change what every saved file reads. Technique ids keep the value of their name."""
    return zlib.crc32(identifier.encode()) & 0x7FFFFFFF


# The technique menu: families as headings (Blender's enum headings, as in its modifier menu),
# short names and one-line descriptions for artists. A technique missing here is listed under
# its own family with its registry label.
MENU_GROUPS = (
    ("Automatic", ("AUTO",)),
    ("Reference", ("DIRECT", "PT")),
    ("Screen Space", ("SSAO", "HBAO", "SSDO", "SSR")),
    ("Light Volumes", ("RSM", "LPV", "VXGI")),
    ("Probes", ("IRRADIANCE_VOLUME", "DDGI", "RTXGI", "RTXGI_SSR")),
    ("Radiance Caches", ("SURFEL", "GI10", "SCREEN_PROBES")),
    ("Ray Traced", ("RESTIR_DI", "RESTIR_GI")),
    ("Path Traced + Filter", ("ATROUS", "SVGF", "TAA")),
)
MENU_TEXT = {
    "AUTO": ("Auto", "Picks the cheapest passes that cover what the scene needs"),
    "DIRECT": ("Direct Light", "Lights and shadows only, no bounced light"),
    "PT": ("Path Tracing", "Every effect, noisy at first; converges to Cycles"),
    "SSAO": ("SSAO", "Ambient occlusion from the visible pixels, with a flat ambient fill"),
    "HBAO": ("HBAO", "Horizon-based ambient occlusion, softer and more accurate than SSAO"),
    "SSDO": ("SSDO", "One bounce of coloured light from what is on screen"),
    "SSR": ("Screen-Space Reflections", "Glossy reflections of what is on screen"),
    "RSM": ("Reflective Shadow Maps", "One bounce of light from the lights' shadow maps, no occlusion"),
    "LPV": ("Light Propagation Volumes", "One bounce spread through a coarse grid; soft, can leak"),
    "VXGI": ("Voxel Cone Tracing", "Bounced light and glossy reflections from a voxelised scene"),
    "RESTIR_DI": ("ReSTIR Direct Light", "Many lights with ray-traced shadows, little noise"),
    "RESTIR_GI": ("ReSTIR GI", "Ray-traced bounced light reused across pixels and frames"),
    "ATROUS": ("Path Tracing + À-Trous", "One sample of path tracing per frame, blurred along edges"),
    "SVGF": ("Path Tracing + SVGF", "One sample of path tracing per frame, denoised over time and space"),
    "TAA": ("Path Tracing + TAA", "One sample of path tracing per frame, averaged over time"),
    "IRRADIANCE_VOLUME": ("Irradiance Volume", "Light probes on a grid; fast, leaks through walls"),
    "DDGI": ("DDGI", "Ray-traced light probes that know what they see; little leaking"),
    "RTXGI": ("RTXGI", "DDGI whose probes move out of walls and switch off where not needed"),
    "RTXGI_SSR": ("RTXGI + SSR", "RTXGI with screen-space reflections for glossy surfaces"),
    "SURFEL": ("Surfel GI", "Light cached on small discs spawned on the visible surfaces; they follow moving objects"),
    "GI10": ("GI-1.0", "Light probes on the visible surfaces over a world-space light cache; no set-up"),
    "SCREEN_PROBES": ("Screen Probes (Lumen)", "Probes on the visible surfaces traced every frame, refined at edges, "
                      "over a world-space light cache"),
}


def technique_items() -> list:
    """Every registered technique, grouped by family under enum headings (``("", name, "")``;
    ``None`` separates groups), as static enum items (introspectable by scripts through
    ``bl_rna``; headings and separators are not items) with stable values (``enum_value``);
    built when the add-on registers."""
    infos = {i.id: i for i in techniques.available()}
    groups = [(title, [t for t in ids if t in infos]) for title, ids in MENU_GROUPS]
    listed = {t for _title, ids in groups for t in ids}
    rest: dict = {}
    for tid, info in infos.items():
        if tid not in listed:
            rest.setdefault(info.family.replace("_", " ").title(), []).append(tid)
    groups += list(rest.items())
    items = []
    for title, ids in groups:
        if not ids:
            continue
        if items:
            items.append(None)
        items.append(("", title, ""))
        for tid in ids:
            label, desc = MENU_TEXT.get(tid, (infos[tid].label, infos[tid].description))
            items.append((tid, label, desc, enum_value(tid)))
    return items


def technique_label(tid: str) -> str:
    """The menu's short name of a technique id."""
    if tid in MENU_TEXT:
        return MENU_TEXT[tid][0]
    try:
        return techniques.get(tid).label
    except ValueError:
        return tid


def _update(self, context):
    # Any change restarts the viewport's accumulation (handled by the engine comparing keys).
    for area in getattr(getattr(context, "screen", None), "areas", []) or []:
        if area.type == "VIEW_3D":
            area.tag_redraw()


# ---------------------------------------------------------------- quality
QUALITY_ITEMS = [
    ("DRAFT", "Draft", "Fastest: fewer samples, probes and voxels; good for blocking out", 0),
    ("MEDIUM", "Medium", "Balanced speed and accuracy (default)", 1),
    ("HIGH", "High", "More samples and finer grids; slower", 2),
    ("ULTRA", "Ultra", "The most accurate level; slowest", 3),
]


def _get_quality_preset(self) -> int:
    return max(0, min(3, int(self.quality)))


def _set_quality_preset(self, value: int):
    self.quality = int(value)


# ---------------------------------------------------------------- technique settings
@dataclass(frozen=True)
class Setting:
    """One technique setting: a scene property that overrides pass parameters.

    ``targets``: (pass name, parameter) pairs it sets (passes a graph does not have are
    ignored); ``techniques``: the ids it is shown and applied for; ``filter``: also shown
    and applied (in Denoising) when that filter ends the graph. The value 0 means "the
    Quality level's value": the pass keeps its quality ladder's value."""

    prop: str
    label: str
    description: str
    targets: tuple
    techniques: tuple
    kind: str = "INT"  # "INT" | "FLOAT"
    max: float = 1024
    soft_max: float | None = None
    subtype: str = "NONE"
    filter: str | None = None
    zero: str = "0 uses the Quality level's value"

    def make(self):
        desc = f"{self.description}. {self.zero}"
        if self.kind == "FLOAT":
            return bpy.props.FloatProperty(
                name=self.label, description=desc, default=0.0, min=0.0, max=float(self.max),
                soft_max=float(self.soft_max if self.soft_max is not None else self.max),
                subtype=self.subtype, unit="LENGTH" if self.subtype == "DISTANCE" else "NONE",
                update=_update)
        return bpy.props.IntProperty(
            name=self.label, description=desc, default=0, min=0, max=int(self.max),
            soft_max=int(self.soft_max if self.soft_max is not None else self.max), update=_update)


PROBES = ("IRRADIANCE_VOLUME", "DDGI", "RTXGI", "RTXGI_SSR")
SHADOWED = ("DIRECT", "SSAO", "HBAO", "SSDO", "SSR", "RSM", "LPV", "VXGI", "RESTIR_GI", *PROBES, "SURFEL", "GI10", "SCREEN_PROBES", "AUTO")

SETTINGS = (
    Setting("probe_spacing", "Probe Spacing",
            "Distance between neighbouring probes (smaller: finer light, slower)",
            (("probe_trace", "spacing"),), PROBES, "FLOAT", 1e4, 10.0, "DISTANCE", zero="0 uses Probe Count"),
    Setting("probe_count", "Probe Count", "Probes along the longest side of the scene",
            (("probe_trace", "probes"),), PROBES, max=64, soft_max=32),
    Setting("probe_rays", "Rays per Probe", "Rays each probe traces per frame (more: less flicker, slower)",
            (("probe_trace", "rays"),), PROBES, max=1024, soft_max=512),
    Setting("screen_probe_tile", "Probe Spacing", "Pixels between neighbouring screen probes (smaller: finer "
            "light, slower)", (("sp_place", "tile"),), ("GI10", "SCREEN_PROBES"), max=64, soft_max=32),
    Setting("screen_probe_rays", "Rays per Probe", "Rays along each side of a screen probe's hemisphere "
            "(8: 64 rays)", (("sp_place", "res"), ("spa_place", "res")), ("GI10", "SCREEN_PROBES"), max=16),
    Setting("surfel_capacity", "Surfels", "Most surfels alive at once (the pool's fixed size)",
            (("surfel_prepare", "capacity"),), ("SURFEL",), max=262144, soft_max=65536),
    Setting("surfel_rays", "Rays per Surfel", "Rays each surfel traces per frame",
            (("surfel_prepare", "rays"),), ("SURFEL",), max=64, soft_max=16),
    Setting("surfel_glossy_rays", "Glossy Rays", "Rays each glossy pixel traces through its reflection lobe per "
            "frame, for the light other surfaces reflect in it",
            (("surfel_glossy", "glossy_rays"),), ("SURFEL",), max=16, soft_max=4),
    Setting("cache_rays", "Cache Rays", "Rays each cell of the world light cache traces per frame",
            (("radiance_cache", "rays"),), ("GI10", "SCREEN_PROBES"), max=64, soft_max=16),
    Setting("voxel_resolution", "Voxel Resolution", "Voxels along each side of a cascade (more: sharper light, "
            "more memory)", (("vxgi_voxelize", "resolution"),), ("VXGI",), max=256, soft_max=128),
    Setting("voxel_cascades", "Cascades", "Nested voxel grids around the camera, each twice as coarse",
            (("vxgi_voxelize", "cascades"),), ("VXGI",), max=4),
    Setting("cone_distance", "Max Distance", "How far bounced light is gathered from",
            (("vxgi_inject", "max_distance"), ("vxgi_trace", "max_distance")), ("VXGI",), "FLOAT", 1e4, 100.0,
            "DISTANCE"),
    Setting("lpv_cells", "Grid Resolution", "Cells along each side of a cascade (more: sharper, slower spread)",
            (("lpv", "grid"),), ("LPV",), max=64),
    Setting("lpv_cascades", "Cascades", "Nested grids around the camera, each twice as coarse",
            (("lpv", "cascades"),), ("LPV",), max=4),
    Setting("lpv_cell_size", "Cell Size", "Size of the finest cell (by default the coarsest grid covers the scene)",
            (("lpv", "cell_size"),), ("LPV",), "FLOAT", 100.0, 10.0, "DISTANCE"),
    Setting("ao_distance", "Distance", "How far away an object still darkens a surface, as Cycles' AO distance",
            (("ssao", "radius"), ("hbao", "radius"), ("ssdo", "radius")), ("SSAO", "HBAO", "SSDO", "AUTO"),
            "FLOAT", 100.0, 10.0, "DISTANCE"),
    Setting("ao_samples", "Samples", "Directions sampled per pixel per frame (more: less noise, slower)",
            (("ssao", "samples"), ("hbao", "directions"), ("ssdo", "samples")), ("SSAO", "HBAO", "SSDO", "AUTO"),
            max=64, soft_max=32),
    Setting("ssr_thickness", "Thickness", "How thick surfaces are assumed to be behind what the camera sees",
            (("ssr_trace", "thickness"),), ("SSR", "RTXGI_SSR", "AUTO"), "FLOAT", 10.0, 1.0, "DISTANCE"),
    Setting("ssr_max_distance", "Max Distance", "How far reflection rays travel",
            (("ssr_trace", "max_distance"),), ("SSR", "RTXGI_SSR", "AUTO"), "FLOAT", 1000.0, 100.0, "DISTANCE"),
    Setting("rsm_resolution", "Map Resolution", "Texels along each side of a light's reflective shadow map",
            (("rsm", "rsm_resolution"),), ("RSM",), max=1024, soft_max=512),
    Setting("rsm_world_directions", "Sky Directions", "Directions of the world light rendered as reflective shadow "
            "maps each frame, so that sky-lit surfaces bounce light (more: smoother, slower)",
            (("rsm", "world_directions"),), ("RSM", "LPV"), max=24, soft_max=16),
    Setting("rsm_samples", "Samples", "Light samples gathered per pixel per frame",
            (("rsm_gather", "vpl_samples"),), ("RSM",), max=1024, soft_max=256),
    Setting("restir_candidates", "Light Candidates", "Lights tried per pixel per frame before one is kept",
            (("restir_di", "candidates"),), ("RESTIR_DI",), max=256, soft_max=64),
    Setting("restir_radius", "Reuse Radius", "How far (in pixels) neighbouring samples are reused from",
            (("restir_gi", "radius"),), ("RESTIR_GI",), "FLOAT", 64.0, 32.0, "PIXEL"),
    Setting("max_bounces", "Max Bounces", "Most times light bounces along a path, as Cycles' Max Bounces",
            (("path_trace", "max_bounces"), ("restir_gi", "max_bounces")), ("PT", "ATROUS", "SVGF", "TAA", "RESTIR_GI"),
            max=64, soft_max=32),
    Setting("shadow_resolution", "Shadow Resolution", "Texels along each side of a shadow map",
            (("shadows", "shadow_resolution"),), SHADOWED, max=4096, soft_max=2048),
    Setting("shadow_rays", "Shadow Rays", "Rays per pixel per frame for shadows not taken from a shadow map: "
            "lights with size (area, sphere and mesh lights) on images small enough that rays cost less than "
            "their moving maps, and lights over the shadow-map budget (more: less noise in soft shadows)",
            (("direct_light", "rt_shadow_rays"),), SHADOWED, max=8),
    Setting("atrous_iterations", "Filter Steps", "Blur steps of the à-trous filter (more: smoother, blurrier)",
            (("atrous", "iterations"),), ("ATROUS",), max=8, filter="ATROUS"),
    Setting("svgf_history", "History Length", "Most frames SVGF averages (more: less noise, more lag)",
            (("svgf", "max_history"),), ("SVGF",), max=1024, soft_max=128, filter="SVGF"),
    Setting("taa_history", "History Length", "Most frames TAA averages (more: smoother, more ghosting)",
            (("taa", "max_history"),), ("TAA",), max=1024, soft_max=128, filter="TAA"),
)
SETTINGS_BY_PROP = {st.prop: st for st in SETTINGS}


def active_filters(s, technique_id: str) -> set:
    """The filters ending the graph: the denoiser (``AUTO`` resolved) and TAA."""
    out = set()
    try:
        d = techniques.resolve_denoiser(technique_id, str(s.denoiser))
    except ValueError:
        d = "NONE"
    if d != "NONE":
        out.add(d)
    if bool(s.use_taa):
        out.add("TAA")
    return out


def technique_settings(technique_id: str) -> list:
    """The settings shown in the technique's panel (its own, not the filters')."""
    return [st for st in SETTINGS if technique_id in st.techniques]


def filter_settings(s, technique_id: str) -> list:
    """The filter settings shown in Denoising: those of the filters ending the graph."""
    f = active_filters(s, technique_id)
    return [st for st in SETTINGS if st.filter in f]


def auto_options(s, technique_id: str) -> dict:
    """AUTO's settings as ``session.render(auto=...)`` (empty for other techniques)."""
    if technique_id != "AUTO":
        return {}
    return {"auto": {"budget_ms": float(getattr(s, "auto_frame_budget", 0.0)),
                     "target_error": float(getattr(s, "auto_target_error", 0.0)),
                     "threshold": float(getattr(s, "auto_threshold", 1.0)) / 100.0}}


def pass_overrides(s, technique_id: str) -> dict:
    """``{pass name: {parameter: value}}`` from the settings of ``technique_id`` and of the
    filters ending its graph that are not 0 (0 keeps the Quality level's value): what the
    engine hands to ``session.render(params=...)``."""
    chosen = technique_settings(technique_id) + [st for st in filter_settings(s, technique_id)
                                                 if technique_id not in st.techniques]
    out: dict = {}
    for st in chosen:
        v = getattr(s, st.prop, 0)
        if not v or v <= 0:
            continue
        for pass_name, param in st.targets:
            out.setdefault(pass_name, {})[param] = float(v) if st.kind == "FLOAT" else int(v)
    return out


# ---------------------------------------------------------------- the scene's settings
COMPARE_REFERENCE_ITEMS = [
    ("AUTO", "Auto", "The Cycles reference the technique models (e.g. one bounce for one-bounce GI)"),
    ("FULL", "Full", "Cycles with 12 bounces: the ground truth"),
    ("DIRECT", "Direct", "Cycles with no bounces: direct light only"),
    ("ONE_BOUNCE", "One Bounce", "Cycles with one bounce of light"),
    ("AO", "AO", "Cycles ambient occlusion"),
]


class GIPreviewSceneSettings(bpy.types.PropertyGroup):
    technique: bpy.props.EnumProperty(
        name="Technique", items=technique_items(), default="AUTO", update=_update,
        description="How GI Preview computes light")
    samples: bpy.props.IntProperty(
        name="Samples", default=16, min=1, max=65536, soft_max=1024,
        description="Frames averaged by a final render (smoother edges, soft shadows, less noise)")
    viewport_samples: bpy.props.IntProperty(
        name="Viewport Samples", default=16, min=1, max=65536, soft_max=1024,
        description="Frames the viewport averages while nothing changes")
    # Stored as an integer, as files and scripts have always had it; the panel shows
    # quality_preset, a named view of the same value
    quality: bpy.props.IntProperty(
        name="Quality Level", default=1, min=0, max=3, update=_update,
        description="Quality as a number: 0 Draft, 1 Medium, 2 High, 3 Ultra")
    quality_preset: bpy.props.EnumProperty(
        name="Quality", items=QUALITY_ITEMS, get=_get_quality_preset, set=_set_quality_preset, update=_update,
        description="Speed against accuracy of the technique's samples, grids and maps")
    denoiser: bpy.props.EnumProperty(
        name="Denoiser", default="AUTO", update=_update,
        # explicit values: files saved before "AUTO" existed stored NONE/ATROUS/SVGF as 0/1/2
        items=[("AUTO", "Technique Default", "The technique's own choice: SVGF for ReSTIR GI, "
                "none for the others (Path Tracing stays unfiltered)", 3),
               ("NONE", "None", "No denoising", 0),
               ("ATROUS", "À-Trous", "Edge-aware blur; fast, can smear detail", 1),
               ("SVGF", "SVGF", "Denoises over time and space; smoother, can lag behind motion", 2)],
        description="Removes noise from noisy techniques")
    use_taa: bpy.props.BoolProperty(
        name="TAA", default=False, update=_update,
        description="Temporal anti-aliasing: averages frames over time for smooth edges")
    show_probes: bpy.props.BoolProperty(
        name="Show Probes", default=False, update=_update,
        description="Rendered viewport: draw the light probes as small spheres with their light")
    viewport_scale: bpy.props.FloatProperty(
        name="Viewport Resolution", default=0.5, min=0.1, max=1.0, subtype="FACTOR",
        description="Viewport render resolution relative to the view (lower is faster)")
    auto_frame_budget: bpy.props.FloatProperty(
        name="Frame Budget", default=0.0, min=0.0, soft_max=1000.0, unit="NONE", update=_update,
        description="AUTO: milliseconds one frame may take (0 = unlimited); AUTO picks the most accurate "
                    "combination whose measured cost fits")
    auto_target_error: bpy.props.FloatProperty(
        name="Target Error", default=0.0, min=0.0, soft_max=1.0, precision=4, update=_update,
        description="AUTO: relMSE against Cycles to aim for (0 = as accurate as the budget allows); AUTO picks "
                    "the cheapest combination predicted to reach it")
    auto_threshold: bpy.props.FloatProperty(
        name="Skip Below", default=1.0, min=0.0, max=100.0, subtype="PERCENTAGE", update=_update,
        description="AUTO: an indirect effect whose measured share of the image is below this is skipped")
    compare_reference: bpy.props.EnumProperty(
        name="Reference", items=COMPARE_REFERENCE_ITEMS, default="AUTO",
        description="What Cycles renders for the comparison")
    compare_samples: bpy.props.IntProperty(
        name="Cycles Samples", default=128, min=1, max=65536, soft_max=4096,
        description="Samples of the Cycles reference")


for _st in SETTINGS:
    GIPreviewSceneSettings.__annotations__[_st.prop] = _st.make()
del _st

classes = (GIPreviewSceneSettings,)


def register_props():
    bpy.types.Scene.gi_preview = bpy.props.PointerProperty(type=GIPreviewSceneSettings)


def unregister_props():
    del bpy.types.Scene.gi_preview
