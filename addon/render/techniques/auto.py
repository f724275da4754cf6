"""AUTO: one graph per scene, composed per effect from measured effect shares and a table of
measured cost and error.

For each render (cached per scene version and camera, ``render/effect_shares.py``) AUTO
measures every effect's share of what the camera sees with a small path-traced image. An
indirect effect below ``threshold`` (default 1 %) is skipped, with the number in the
planner's reason ("indirect glossy: 0.3 % of the image -> skipped"). The remaining effects
choose among the candidates of ``CANDIDATES`` (every single technique, RESTIR_GI with its
default SVGF, and compositions): each is a list of member techniques merged by pass name (``merge_passes``: the G-buffer, shadows and direct light run once; RTXGI_SSR
is RTXGI with SSR's passes using the probes as miss fallback). ``auto_table.json``
(written by ``scripts/sweep_auto.py``) holds, per demo scene, its measured shares and each
candidate's relMSE against Cycles full and ms/frame on llvmpipe. The scene's class is the
demo scene nearest in shares (L1); the candidate's predicted error is the table's relMSE
on that class, its predicted cost the table's ms scaled by pixel count and by the scene's
measured cost factor (below). AUTO takes the most
accurate candidate whose predicted cost fits the frame budget (0 = unlimited), or DIRECT when
every one that fits is predicted worse than DIRECT and DIRECT's cost is within
``DIRECT_SLACK`` of the budget; with a target error, the cheapest one predicted to reach it. Without a table AUTO runs the bundle
DIRECT + SSDO + SSR (``DEFAULT_MEMBERS``).

The class's costs need not hold for the scene (many shadow-mapped lights, many triangles). So
a render with a budget measures its own frames: when the chosen candidate's measured ms/frame
is over the budget and more than ``REPLAN_FACTOR`` times the prediction, the session keeps
measured / predicted as the scene's cost factor, plans again with every candidate's cost
scaled by it and, when that picks another candidate, restarts the render with it. A viewport
renders one frame per call: the session keeps the candidate's latest four frames across calls,
and once they measure over, the next call plans with the factor. Later plans of the same scene
start from the factor, until its lights or triangle count change.
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass, field

from ..framegraph import Effect, FrameGraph
from . import Technique, get, register

DEFAULT_MEMBERS = ("DIRECT", "SSDO", "SSR")
# candidate id -> (members, diffuse method, glossy method)
CANDIDATES = {
    "DIRECT": (("DIRECT",), None, None),
    "DIRECT+SSR": (("DIRECT", "SSR"), None, "SSR"),
    "DIRECT+SSDO": (("DIRECT", "SSDO"), "SSDO", None),
    "DIRECT+SSDO+SSR": (("DIRECT", "SSDO", "SSR"), "SSDO", "SSR"),
    "DDGI": (("DDGI",), "DDGI", None),
    "DDGI+SSR": (("DDGI", "SSR"), "DDGI", "SSR"),
    "RTXGI": (("RTXGI",), "RTXGI", "probes"),
    "RTXGI_SSR": (("RTXGI_SSR",), "RTXGI", "probes+SSR"),
    "SVGF": (("SVGF",), "PT", "PT"),
    # every other single technique, so that AUTO at a budget is never short of one that fits
    "PT": (("PT",), "PT", "PT"),
    "TAA": (("TAA",), "PT", "PT"),
    "ATROUS": (("ATROUS",), "PT", "PT"),
    "RESTIR_DI": (("RESTIR_DI",), None, None),
    "RESTIR_GI+SVGF": (("RESTIR_GI+SVGF",), "RESTIR_GI", "RESTIR_GI"),
    "SSAO": (("SSAO",), "AO", None),
    "HBAO": (("HBAO",), "AO", None),
    "RSM": (("RSM",), "RSM", None),
    "LPV": (("LPV",), "LPV", None),
    "VXGI": (("VXGI",), "VXGI", "VXGI"),
    "IRRADIANCE_VOLUME": (("IRRADIANCE_VOLUME",), "IRRADIANCE_VOLUME", None),
    "GI10": (("GI10",), "GI10", "probes"),
    "SCREEN_PROBES": (("SCREEN_PROBES",), "SCREEN_PROBES", "probes"),
    "SURFEL": (("SURFEL",), "SURFEL", None),
}
BUNDLE = "DIRECT+SSDO+SSR"
COMPOSITIONS = ("DIRECT+SSDO+SSR", "DDGI+SSR")  # the candidates that are not one technique's own graph
# A budget's floor: when every candidate predicted to fit is predicted worse than DIRECT, AUTO
# runs DIRECT if its predicted cost is within this factor of the budget (llvmpipe's ms/frame
# drift by 10-30 % from run to run, more than the gap between candidates of similar cost).
DIRECT_SLACK = 1.25
# A measured frame over the budget re-plans only beyond this factor over the prediction (the
# run-to-run drift of llvmpipe's ms/frame)
REPLAN_FACTOR = 1.25
TABLE_PATH = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "auto_table.json")
# effects with passes of their own that the threshold can skip, and the share that measures them
SKIPPABLE = {Effect.INDIRECT_DIFFUSE: "indirect_diffuse", Effect.INDIRECT_SPECULAR: "indirect_glossy"}
LABEL = {"indirect_diffuse": "indirect diffuse", "indirect_glossy": "indirect glossy"}


def split_member(member: str) -> tuple[str, str]:
    """A member is a technique id, or ``"ID+FILTER"``: that technique's graph ended by the
    denoiser FILTER (RESTIR_GI+SVGF, as RESTIR_GI renders by default)."""
    tid, _, den = member.partition("+")
    return tid, (den or "NONE").upper()


def merge_passes(groups: list[list]) -> list:
    """Concatenate pass lists, keeping the first pass of each name (shared passes)."""
    out, seen = [], set()
    for passes in groups:
        for p in passes:
            if p.name not in seen:
                seen.add(p.name)
                out.append(p)
    return out


_TABLE_CACHE: dict = {}


def load_table(path: str = TABLE_PATH) -> dict | None:
    """The measured table (``auto_table.json``), or None when there is none."""
    try:
        mtime = os.path.getmtime(path)
    except OSError:
        return None
    hit = _TABLE_CACHE.get(path)
    if hit is None or hit[0] != mtime:
        with open(path, encoding="utf-8") as f:
            _TABLE_CACHE[path] = (mtime, json.load(f))
    return _TABLE_CACHE[path][1]


@dataclass
class AutoPlan:
    candidate: str
    members: tuple
    shares: dict = field(default_factory=dict)
    skipped: dict = field(default_factory=dict)  # Effect -> reason
    scene_class: str | None = None
    predicted_relmse: float | None = None
    predicted_ms: float | None = None
    budget_ms: float = 0.0
    target_error: float = 0.0
    notes: list = field(default_factory=list)
    considered: dict = field(default_factory=dict)  # candidate -> (relMSE, ms) predicted

    def as_dict(self) -> dict:
        return {"candidate": self.candidate, "members": list(self.members),
                "shares": {k: round(float(v), 5) for k, v in self.shares.items()},
                "skipped": {e.value: r for e, r in self.skipped.items()}, "scene_class": self.scene_class,
                "predicted_relmse": self.predicted_relmse, "predicted_ms": self.predicted_ms,
                "budget_ms": self.budget_ms, "target_error": self.target_error, "notes": list(self.notes),
                "considered": {k: [round(v[0], 5), round(v[1], 2)] for k, v in self.considered.items()}}


def scene_class(shares: dict, table: dict) -> str:
    """The demo scene of the table whose measured shares are nearest (L1) to ``shares``."""
    best, dist = None, None
    for name, row in table["scenes"].items():
        d = sum(abs(float(shares.get(e, 0.0)) - float(row["shares"].get(e, 0.0))) for e in row["shares"])
        if dist is None or d < dist:
            best, dist = name, d
    return best


def choose(shares: dict, table: dict | None, width: int, height: int, *, budget_ms: float = 0.0,
           target_error: float = 0.0, threshold: float = 0.01, force: str | None = None,
           cost_factor: float = 1.0) -> AutoPlan:
    """The plan for a scene with measured ``shares`` (effect -> fraction) at ``width`` x ``height``.
    ``force``: a candidate id to run whatever the table says (the sweep, comparisons).
    ``cost_factor``: the scene's measured cost over the table's prediction (every candidate's
    predicted ms is scaled by it)."""
    skipped = {}
    for eff, key in SKIPPABLE.items():
        s = float(shares.get(key, 0.0))
        if s < threshold:
            skipped[eff] = f"{LABEL[key]}: {100.0 * s:.1f} % of the image -> skipped"
    if Effect.INDIRECT_DIFFUSE in skipped:
        skipped[Effect.AO] = skipped[Effect.INDIRECT_DIFFUSE]
    plan = AutoPlan(BUNDLE, CANDIDATES[BUNDLE][0], dict(shares), skipped, budget_ms=float(budget_ms or 0.0),
                    target_error=float(target_error or 0.0))
    if force:
        if force not in CANDIDATES:
            raise ValueError(f"unknown AUTO candidate {force!r} (one of {', '.join(CANDIDATES)})")
        plan.candidate, plan.members = force, CANDIDATES[force][0]
        plan.notes.append("candidate forced")
        return plan
    if table is None:
        plan.notes.append("no measured table (auto_table.json): the DIRECT + SSDO + SSR bundle")
        return plan
    cls = scene_class(shares, table)
    plan.scene_class = cls
    scale = (width * height) / float(table["width"] * table["height"]) * float(cost_factor)
    if cost_factor != 1.0:
        plan.notes.append(f"predicted costs x {cost_factor:.2f}, measured on this scene")
    rows = {r["candidate"]: r for r in table["rows"] if r["scene"] == cls and r["candidate"] in CANDIDATES}
    diff_skip = Effect.INDIRECT_DIFFUSE in skipped
    gloss_skip = Effect.INDIRECT_SPECULAR in skipped
    cands = {}
    for cid, (members, dmeth, gmeth) in CANDIDATES.items():
        if cid not in rows:
            continue
        if diff_skip and dmeth is not None:
            continue  # nothing to gather: no diffuse GI member
        if gloss_skip and gmeth and "SSR" in gmeth:
            continue  # its SSR passes would be skipped: the same graph as the one without SSR
        cands[cid] = (float(rows[cid]["relmse"]), float(rows[cid]["ms"]) * scale)
    if not cands:
        plan.notes.append(f"the table has no candidate for class {cls}: the bundle")
        return plan
    plan.considered = dict(cands)
    budget = float(budget_ms or 0.0)
    fits = {c: v for c, v in cands.items() if budget <= 0.0 or v[1] <= budget}
    if not fits:
        pick = min(cands, key=lambda c: cands[c][1])
        plan.notes.append(f"no candidate fits {budget:.0f} ms: the cheapest ({cands[pick][1]:.0f} ms)")
    elif target_error and target_error > 0.0 and any(v[0] <= target_error for v in fits.values()):
        pick = min((c for c in fits if fits[c][0] <= target_error), key=lambda c: fits[c][1])
    else:
        pick = min(fits, key=lambda c: (fits[c][0], fits[c][1]))
        d = cands.get("DIRECT")
        if budget > 0.0 and d is not None and cands[pick][0] > d[0] and d[1] <= DIRECT_SLACK * budget:
            plan.notes.append(f"every candidate predicted to fit is predicted worse than DIRECT ({d[0]:.4f}); "
                              f"DIRECT, predicted {d[1]:.0f} ms, is within {DIRECT_SLACK:g}x the budget")
            pick = "DIRECT"
    plan.candidate = pick
    plan.members = CANDIDATES[pick][0]
    plan.predicted_relmse, plan.predicted_ms = cands[pick]
    return plan


def all_members() -> tuple:
    out = []
    for members, _d, _g in CANDIDATES.values():
        for m in members:
            if m not in out:
                out.append(m)
    return tuple(out)


@register
class Auto(Technique):
    id = "AUTO"
    label = "Auto"
    description = ("Measures each effect's share of the image and runs the most accurate technique or "
                   "composition (e.g. DDGI + SSR) that fits the frame budget, from a measured table")
    family = "auto"
    reference = "full"
    cost_rank = 50

    def __init__(self, members: tuple | None = None):
        self.chosen = tuple(members) if members else None
        self.members = self.chosen or DEFAULT_MEMBERS

    def _members(self):
        return [get(split_member(t)[0]) for t in self.members if t != self.id]

    @property
    def graph_class(self):  # noqa: D401 - the first member's own graph type (RSM, LPV, VXGI gate on lights)
        for m in self._members():
            if m.graph_class is not FrameGraph:
                return m.graph_class
        return FrameGraph

    @property
    def warmup_frames(self):  # noqa: D401 - the longest warm-up of the members
        return max([int(getattr(m, "warmup_frames", 0) or 0) for m in self._members()] + [0])

    @property
    def outputs(self):  # noqa: D401 - the chosen members' AOVs (unchosen: every AOV AUTO can give)
        out = {}
        names = self.members if self.chosen else tuple(reversed(all_members()))
        for t in reversed(names):  # the first member's resource wins for a shared AOV name
            out.update(get(split_member(t)[0]).outputs)
        return out

    def passes(self, quality):
        groups = []
        for t in self.members:
            if t == self.id:
                continue
            tid, den = split_member(t)
            passes = get(tid)().passes(quality)
            if den != "NONE":
                from ..passes.filters import with_filters
                passes = with_filters(passes, den, False, quality)
            groups.append(passes)
        return merge_passes(groups)
