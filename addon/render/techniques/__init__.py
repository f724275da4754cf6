"""Technique registry: one module per technique id (one page each in docs/techniques/).

A technique is a list of passes (a FrameGraph) plus what it is compared against. Add a
technique by writing ``techniques/<id>.py`` with a ``Technique`` subclass decorated with
``@register`` and importing it in ``_load`` below.
"""
from __future__ import annotations

import importlib
import logging
from dataclasses import dataclass

from ..framegraph import FrameGraph

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TechniqueInfo:
    id: str
    label: str
    description: str
    family: str
    reference: str  # "direct" | "one_bounce" | "full" | "ao": the Cycles reference it models
    quality_levels: tuple
    default_quality: int
    converges: bool
    cost_rank: int


class Technique:
    """Base class. Subclasses set the metadata and implement ``passes(quality)``."""

    id = "NONE"
    label = "None"
    description = ""
    family = "core"
    reference = "full"
    quality_levels = (0, 1, 2, 3)
    default_quality = 1
    converges = True  # does accumulating frames (samples) improve the image
    # frames an F12 render runs before it accumulates, for state that converges over frames
    # (probes, caches, reservoirs); the graph also takes each pass's ``warmup_frames`` and
    # ``converged()``, and the larger count wins
    warmup_frames = 0
    cost_rank = 100  # relative cost for AUTO's choice (lower = cheaper)
    # the filter used when scene.gi_preview.denoiser is "AUTO" (Technique Default): "NONE" for
    # all but techniques that are only meant to be shown filtered (RESTIR_GI: "SVGF"); PT and
    # the filter ids keep "NONE", so PT stays the unfiltered reference
    default_denoiser = "NONE"
    # AOV name -> resource name (accumulated and returned; "Combined" comes from "color")
    outputs: dict = {}

    def passes(self, quality: int) -> list:
        raise NotImplementedError

    # the graph type that plans this technique's passes (RSM/LPV/VXGI: a graph that skips the
    # injected-light passes, with the reason, when no light casts shadows)
    graph_class = FrameGraph

    def build(self, quality: int, denoiser: str = "NONE", use_taa: bool = False) -> FrameGraph:
        """The technique's graph at ``quality``, ended by the filters ``scene.gi_preview.denoiser``
        and ``use_taa`` ask for (``with_filters``), planned by ``graph_class`` either way."""
        passes = self.passes(quality)
        if (denoiser or "NONE").upper() != "NONE" or use_taa:
            from ..passes.filters import with_filters
            passes = with_filters(passes, (denoiser or "NONE").upper(), bool(use_taa), quality)
        return self.graph_class(passes)

    @classmethod
    def info(cls) -> TechniqueInfo:
        return TechniqueInfo(cls.id, cls.label, cls.description, cls.family, cls.reference,
                             tuple(cls.quality_levels), cls.default_quality, cls.converges, cls.cost_rank)

    @classmethod
    def provides(cls) -> frozenset:
        eff = set()
        for p in cls().passes(cls.default_quality):
            eff |= set(p.provides)
        return frozenset(eff)


REGISTRY: dict[str, type] = {}

# Modules of techniques, in menu order. A module that fails to import is reported, not fatal.
_MODULES = ("direct", "pt", "ssao", "hbao", "ssdo", "ssr", "rsm", "lpv", "vxgi", "restir_di", "restir_gi",
            "atrous", "svgf", "taa", "irradiance_volume", "ddgi", "rtxgi", "surfel", "gi10", "screen_probes", "auto")
_loaded = False
LOAD_ERRORS: dict[str, str] = {}


def register(cls):
    REGISTRY[cls.id] = cls
    return cls


def _load():
    global _loaded
    if _loaded:
        return
    _loaded = True
    for mod in _MODULES:
        try:
            importlib.import_module(f"{__name__}.{mod}")
        except ModuleNotFoundError as exc:
            if exc.name and exc.name.endswith(f"techniques.{mod}"):
                continue  # not written yet
            LOAD_ERRORS[mod] = repr(exc)
            log.error("GI Preview: technique module %s failed to import: %r", mod, exc)
        except Exception as exc:  # pragma: no cover - a broken technique must not break the rest
            LOAD_ERRORS[mod] = repr(exc)
            log.error("GI Preview: technique module %s failed to import: %r", mod, exc)


def available() -> list[TechniqueInfo]:
    _load()
    return [cls.info() for cls in REGISTRY.values()]


def resolve_denoiser(technique_id: str, denoiser: str | None) -> str:
    """The filter a render uses: ``denoiser`` itself, or for ``"AUTO"`` (the Technique Default
    item of scene.gi_preview.denoiser) the technique's ``default_denoiser``."""
    d = (denoiser or "NONE").upper()
    return (getattr(get(technique_id), "default_denoiser", "NONE") or "NONE").upper() if d == "AUTO" else d


def get(technique_id: str) -> type:
    _load()
    try:
        return REGISTRY[technique_id]
    except KeyError:
        raise ValueError(f"unknown GI Preview technique '{technique_id}' (available: "
                         f"{', '.join(REGISTRY)})") from None
