"""Render sessions: SceneData in, RenderResult out. bpy-free; all GL work on the GL thread.

``render()`` is the one entry point used by the engine (F12, animation, viewport), the
comparison operator, the batch script and the tests. It plans the technique's frame graph
against the scene analysis, runs ``samples`` frames (jittered, accumulated as a running
mean) and reads back the image and AOVs. Sessions are keyed (``"final"``, ``"viewport"``,
...) so that the viewport's progressive accumulation and an F12 render do not disturb
each other; temporal state (history) lives in the session's graphs.
"""
from __future__ import annotations

import logging
import queue
import statistics
import threading
import time
from concurrent.futures import Future
from concurrent.futures import TimeoutError as FutureTimeout

import numpy as np

from . import techniques
from .analysis import analyse
from . import frame_sync, framegraph
from .framegraph import CAMERA_CUT, SCENE_EDITS, FrameState, RenderContext
from .gl import PRIORITY_BACKGROUND, PRIORITY_INTERACTIVE, PRIORITY_NORMAL, get_gl
from .gpu_scene import GPUScene, set_uniform
from .result import RenderResult, SkippedPass
from .scene_data import SceneData, SceneError
from .shaders import ProgramCache

log = logging.getLogger(__name__)

_sessions: dict[str, "Session"] = {}


class Cancelled(Exception):
    pass


def _r2(k: int) -> tuple[float, float]:
    """R2 low-discrepancy jitter in [-0.5, 0.5)^2; k = 0 is the pixel centre."""
    g = 1.32471795724474602596
    return (((0.5 + k / g) % 1.0) - 0.5, ((0.5 + k / (g * g)) % 1.0) - 0.5)


def validate_scene(scene: SceneData):
    if scene.camera is None:
        raise SceneError(f"Scene '{scene.name}' has no camera: add a camera and make it the scene camera "
                         f"(Scene Properties > Camera).")
    if scene.width < 4 or scene.height < 4:
        raise SceneError(f"Render resolution {scene.width}x{scene.height} is too small: GI Preview needs at "
                         f"least 4x4 pixels (Output Properties > Format).")
    if not any(scene.meshes[i.mesh].triangle_count for i in scene.instances):
        raise SceneError(f"Scene '{scene.name}' is empty: no visible mesh to render. Add geometry or make "
                         f"hidden objects renderable.")


class Session:
    """GL-thread state for one stream of renders: GPU scene, compiled graphs, accumulators."""

    def __init__(self, ctx):
        self.ctx = ctx
        self.programs = ProgramCache(ctx)
        self.gpu_scene = GPUScene(ctx)
        self.rc: RenderContext | None = None
        self.graphs: dict = {}
        self.acc: dict[str, object] = {}
        self.acc_count = 0
        self.acc_key = None
        self.prev_view_proj = None
        self.sample_counter = 0
        self._last_graph = None
        self._shares = None  # effect_shares.SharesCache (AUTO), made on first use
        self._cost_factor: dict = {}  # _cost_key -> AUTO's measured cost factor (the latest scene only)
        self._auto_recent: dict = {}  # (_cost_key, candidate) -> its latest frame times

    def effect_shares(self, scene: SceneData):
        """The measured effect shares of ``scene`` (cached per scene version and camera)."""
        if self._shares is None:
            from .effect_shares import SharesCache
            self._shares = SharesCache(self.ctx, self.programs, self.gpu_scene)
        return self._shares.get(scene)

    def auto_plan(self, scene: SceneData, auto: dict | None = None):
        """AUTO's plan for ``scene``: shares measured, members chosen (techniques/auto.py)."""
        from .techniques import auto as auto_mod
        o = auto or {}
        shares = self.effect_shares(scene)
        plan = auto_mod.choose(shares.shares, auto_mod.load_table(), scene.width, scene.height,
                               budget_ms=float(o.get("budget_ms", 0.0) or 0.0),
                               target_error=float(o.get("target_error", 0.0) or 0.0),
                               threshold=float(o.get("threshold", 0.01)), force=o.get("candidate"),
                               cost_factor=self._cost_factor.get(self._cost_key(scene), 1.0))
        plan.notes.append(f"shares measured at {shares.size[0]}x{shares.size[1]}, {shares.samples} spp, "
                          f"{shares.time_ms:.0f} ms")
        return plan

    @staticmethod
    def _cost_key(scene: SceneData):
        """What AUTO's measured cost factor holds for: the scene, its size and what its cost
        grows with (lights, triangles). Moving things keeps it, so an artist's edits do not
        send the viewport back to a candidate already measured over the budget."""
        return (scene.name, scene.width, scene.height, len(scene.lights), scene.triangle_count)

    @staticmethod
    def _auto_budgeted(plan, auto: dict | None) -> bool:
        return float(plan.budget_ms or 0.0) > 0.0 and bool(plan.predicted_ms) and not (auto or {}).get("candidate")

    def _auto_over_budget(self, scene: SceneData, plan, measured: float, auto: dict | None) -> bool:
        """AUTO's chosen candidate measured ``measured`` ms/frame on ``scene``: when that is over
        the budget and beyond REPLAN_FACTOR x the prediction, keep the scene's cost factor and
        say whether the plan it gives picks another candidate."""
        from .techniques import auto as auto_mod
        if measured <= float(plan.budget_ms) or measured / plan.predicted_ms <= auto_mod.REPLAN_FACTOR:
            return False
        key = self._cost_key(scene)
        self._cost_factor = {key: self._cost_factor.get(key, 1.0) * measured / plan.predicted_ms}
        return self.auto_plan(scene, auto).candidate != plan.candidate

    def _auto_frames_over_budget(self, scene: SceneData, plan, frames_acc, prev_frame,
                                 auto: dict | None) -> str | None:
        """Within a render: the median of the latest four complete frames (a cache's cost can
        grow as it fills), once two are complete. Returns the re-plan's note, or None."""
        if not self._auto_budgeted(plan, auto):
            return None
        done = [f for f in frames_acc if f.done]
        if len(done) < 2:
            return None
        before = done[-5] if len(done) > 4 else prev_frame
        measured = statistics.median(frame_sync.frame_interval_ms(done[-4:], before))
        if not self._auto_over_budget(scene, plan, measured, auto):
            return None
        return (f"re-planned: {plan.candidate} measured {measured:.0f} ms/frame over {len(done)} frames, "
                f"over the {plan.budget_ms:.0f} ms budget")

    def _auto_redraws_over_budget(self, scene: SceneData, plan, frame_times: list, auto: dict | None) -> bool:
        """Across calls of a frame or two each (the viewport): the median of the latest four
        frames of the same candidate on the same scene; when over, the next call plans with
        the cost factor."""
        if not self._auto_budgeted(plan, auto) or not frame_times:
            return False
        rkey = (self._cost_key(scene), plan.candidate)
        recent = self._auto_recent.get(rkey, []) + list(frame_times)
        self._auto_recent = {rkey: recent[-4:]}
        if len(recent) < 4 or not self._auto_over_budget(scene, plan, statistics.median(recent[-4:]), auto):
            return False
        self._auto_recent = {}
        return True

    # -------------------------------------------------------------- helpers
    def _graph(self, technique_id: str, quality: int, denoiser: str = "NONE", use_taa: bool = False,
               members: tuple | None = None):
        key = (technique_id, quality, (denoiser or "NONE").upper(), bool(use_taa)) + ((members,) if members else ())
        if key not in self.graphs:
            tech = techniques.get(technique_id)(members) if members else techniques.get(technique_id)()
            # scene.gi_preview.denoiser / use_taa end the graph; the technique's own graph type
            # plans it either way (a filtered RSM still skips its passes without shadow lights)
            graph = tech.build(quality, key[2], key[3])
            self.graphs[key] = (tech, graph)
        return self.graphs[key]

    def _accumulate(self, name: str, res_name: str, weight: float, coverage: bool = False):
        """acc[name] += (resource - acc) * weight (running mean) on the GPU; the graph's
        barrier state makes the pass's image stores visible to this texture fetch. With
        ``coverage`` the resource is the G-buffer's position (w < 0: background) and what
        is accumulated is 1 where a surface covers the pixel, 0 elsewhere."""
        tex = self.rc.resources[res_name]
        acc = self.acc.get(name)
        if acc is None or acc.size != tex.size:
            if acc is not None:
                acc.release()
            acc = self.ctx.texture(tex.size, 4, dtype="f4")
            self.acc[name] = acc
        self.rc.barrier_external([res_name, "acc:" + name],
                                 framegraph.TEXTURE_FETCH_BARRIER_BIT | framegraph.SHADER_IMAGE_ACCESS_BARRIER_BIT)
        prog = self.programs.compute("common/accumulate.comp")
        acc.bind_to_image(0, read=True, write=True)
        tex.use(0)
        set_uniform(prog, "u_input", 0)
        set_uniform(prog, "u_weight", float(weight))
        set_uniform(prog, "u_coverage", 1 if coverage else 0)
        w, h = tex.size
        prog.run((w + 7) // 8, (h + 7) // 8, 1)
        # the accumulator was stored into: visible to the next accumulation and the read-back
        self.rc.record_write(["acc:" + name], "image", "accumulate")

    @staticmethod
    def _read(tex, components=4) -> np.ndarray:
        w, h = tex.size
        dt = np.float16 if tex.dtype == "f2" else np.float32
        arr = np.frombuffer(tex.read(), dt).reshape(h, w, tex.components)[..., :components]
        return arr.astype(np.float32)

    # -------------------------------------------------------------- render
    def render(self, scene: SceneData, technique: str, quality: int, samples: int, **kw) -> RenderResult:
        """Run :meth:`render_steps` to the end (blocking, on the GL thread)."""
        steps = self.render_steps(scene, technique, quality, samples, **kw)
        while True:
            try:
                next(steps)
            except StopIteration as stop:
                return stop.value

    def render_steps(self, scene: SceneData, technique: str, quality: int, samples: int, *,
                     cancel: threading.Event | None = None, progress=None,
                     continue_accumulation: bool = False, keep_history: bool = False,
                     camera_cut: bool | None = None, warmup: bool | None = None,
                     denoiser: str = "NONE", use_taa: bool = False, params: dict | None = None,
                     auto: dict | None = None):
        """Render ``samples`` accumulated frames as a generator: it yields after every frame
        (warm-up frames included) so the GL thread can serve other sessions in between, and
        returns the RenderResult (``StopIteration.value``).

        keep_history: temporal state survives from the previous call (viewport, animation);
        otherwise this render starts with a camera cut. Scene edits since the last call
        (lights, materials, geometry, transforms, textures) reset the history of the passes
        that declare them. warmup: run the graph's warm-up frames before accumulating (default:
        for a fresh render that keeps no history, i.e. F12; the first frame of an animation
        asks for it explicitly; the viewport shows the convergence instead). params: pass
        parameters (``{pass name: {param: value}}``) over the quality level's values (the
        scene's technique settings); given, the graph holds exactly these on top of its
        quality ladder (a parameter no longer given returns to the ladder's value); None
        leaves the graph's parameters as they are (:func:`set_pass_properties`). auto: AUTO's
        settings (``budget_ms``, ``target_error``, ``threshold``, ``candidate``: techniques/auto.py)."""
        validate_scene(scene)
        t_start = time.perf_counter()
        setup0 = self._setup_clock()
        analysis = analyse(scene)
        denoiser = techniques.resolve_denoiser(technique, denoiser)  # "AUTO": the technique's default
        changes = self.gpu_scene.update(scene)
        plan_auto = None
        if technique == "AUTO":
            plan_auto = self.auto_plan(scene, auto)
            for eff, why in plan_auto.skipped.items():
                analysis.needed.discard(eff)
                analysis.reasons[eff] = why
        tech, graph = self._graph(technique, quality, denoiser, use_taa,
                                  plan_auto.members if plan_auto is not None else None)
        if params is not None:
            apply_overrides(graph, params)
        size = (scene.width, scene.height)
        if self.rc is None:
            self.rc = RenderContext(self.ctx, self.programs, self.gpu_scene, size)
        if self.rc.size != size:
            self.rc.size = size
        # the session's resources are shared by its graphs: a graph compiled earlier may find
        # them reallocated (another size) by another graph since, so switching graphs recompiles
        switched = graph is not self._last_graph
        t_graph = time.perf_counter()
        graph.compile(self.rc, force=switched)
        graph_ms = (time.perf_counter() - t_graph) * 1e3
        self._last_graph = graph
        plan = graph.plan(analysis.needed, analysis.reasons)
        cam = scene.camera
        view = cam.view.astype(np.float64)
        proj = cam.projection.astype(np.float64)
        vp = proj @ view
        acc_key = (technique, plan_auto.members if plan_auto is not None else None, quality, denoiser, use_taa,
                   size, self.gpu_scene.version, vp.astype(np.float32).tobytes(),
                   params_key(params))
        fresh = not (continue_accumulation and acc_key == self.acc_key)
        if fresh:
            self.acc_count = 0
        edits = {k for k, v in changes.items() if v and k in SCENE_EDITS}
        cut = (not keep_history or switched) if camera_cut is None else bool(camera_cut)
        events = set(edits) | ({CAMERA_CUT} if cut else set())
        reset = graph.apply_history_events(self.rc, events)
        if cut:
            self.prev_view_proj = None
        self.acc_key = acc_key
        # only what a pass that runs this frame writes (a skipped pass's old image is stale)
        written = {w for p in plan.active for w in p.writes}
        outputs = {aov: r for aov, r in {"Combined": "color", **tech.outputs}.items() if r in written}
        n_warm = 0
        if warmup if warmup is not None else (fresh and not keep_history):
            n_warm = max(int(getattr(tech, "warmup_frames", 0) or 0), graph.warmup_frames())
        # before the first frame: one-time work (compiles, BVH builds, uploads of new data,
        # allocation) is setup; the rest (scene analysis, the change check of the upload, AUTO's
        # plan from its cached shares) is what every call pays, a viewport redraw included
        # (the graph's allocation check counts as setup: it allocates on a first frame or a resize)
        t_loop = time.perf_counter()
        setup_ms = self._setup_clock() - setup0 + graph_ms
        prep_ms = max(0.0, (t_loop - t_start) * 1e3 - setup_ms)
        last_warm = None  # the last warm-up frame (its completion ends the warm-up)
        warm_excluded_ms = 0.0
        pass_ms = {}
        sync = frame_sync.for_context(self.ctx)
        frames_acc = []  # the accumulated frames (frame_sync.Frame): their times
        frames_all = []  # every frame of this call: the last one's timers are the pass times
        prev_frame = None  # the frame before the first accumulated one (its completion starts the clock)
        samples = max(1, int(samples))
        warm_done = 0
        acc_done = 0  # frames accumulated by this call
        first_frame = True
        i = -1
        # the warm-up may end early (measured convergence): the render then still accumulates
        # exactly `samples` frames
        while acc_done < samples:
            i += 1
            if cancel is not None and cancel.is_set():
                if self.acc_count == 0:
                    raise Cancelled()
                break
            is_warm = warm_done < n_warm
            k = self.acc_count
            # jitter: the accumulation index, so a render that does not continue an accumulation
            # (an animation frame, a moved viewport frame) is at the pixel centre; warm-up frames
            # take the running counter where history is kept, and their own index in a fresh
            # render (so F12 twice gives the same image)
            jx, jy = _r2((self.sample_counter if keep_history else warm_done) if is_warm else k)
            jit = np.eye(4)
            jit[0, 3] = 2.0 * jx / size[0]
            jit[1, 3] = 2.0 * jy / size[1]
            # seeds: the accumulation index for a fresh render (deterministic F12), the running
            # counter when history is kept (viewport, animation: new noise every frame);
            # warm-up frames use seeds no accumulated frame uses
            seed = self.sample_counter if keep_history else (k if not is_warm else (1 << 30) + warm_done)
            frame = FrameState(index=k, sample=seed, jitter=(jx, jy), view=view.astype(np.float32),
                               proj=(jit @ proj).astype(np.float32), proj_unjittered=proj.astype(np.float32),
                               prev_view_proj=(self.prev_view_proj if self.prev_view_proj is not None else vp
                                               ).astype(np.float32),
                               camera_changed=self.prev_view_proj is None or not np.allclose(vp, self.prev_view_proj),
                               camera_cut=cut and first_frame, scene_changed=bool(edits) and first_frame,
                               scene_edits=frozenset(edits) if first_frame else frozenset(),
                               seed=seed, warmup=is_warm, keeps_history=bool(keep_history))
            # frame N waits here for frame N-2: at most two frames in flight, no glFinish
            fr = sync.begin_frame()
            setup_f0 = self._setup_clock()
            graph.execute(self.rc, frame, timers=fr.timers)
            if not is_warm:
                w = 1.0 / (k + 1)
                for aov, res_name in outputs.items():
                    if res_name in self.rc.resources:
                        self._accumulate(aov, res_name, w)
                if scene.film_transparent and "gbuffer.position" in written:
                    self._accumulate("Alpha", "gbuffer.position", w, coverage=True)
            sync.end_frame(fr)
            # one-time work done inside this frame (shader compiles, BVH builds) is setup
            in_frame_setup = self._setup_clock() - setup_f0
            setup_ms += in_frame_setup
            fr.excluded_ms = in_frame_setup
            frames_all.append(fr)
            for old in frames_all[:-3]:  # timers of frames whose results nobody reads
                old.timers.drop()
            del frames_all[:-3]
            self.prev_view_proj = vp
            self.sample_counter += 1
            first_frame = False
            if is_warm:
                warm_done += 1
                last_warm = fr
                warm_excluded_ms += in_frame_setup
                if graph.converged(self.rc):
                    n_warm = warm_done  # measured: state settled early
            else:
                if not frames_acc:
                    prev_frame = frames_all[-2] if len(frames_all) > 1 else None
                frames_acc.append(fr)
                self.acc_count += 1
                acc_done += 1
                # checked after every frame: a candidate's cost can grow as its caches fill
                replanned = (self._auto_frames_over_budget(scene, plan_auto, frames_acc, prev_frame, auto)
                             if plan_auto is not None and acc_done < samples else None)
                if replanned:
                    # the chosen candidate measured over the budget on this scene: start again
                    # with the plan its measured cost gives
                    sync.wait(fr)
                    for f in frames_all:
                        f.timers.drop()
                    result = yield from self.render_steps(
                        scene, technique, quality, samples, cancel=cancel, progress=progress,
                        continue_accumulation=False, keep_history=keep_history, camera_cut=True,
                        warmup=warmup, denoiser=denoiser, use_taa=use_taa, params=params, auto=auto)
                    result.auto.setdefault("notes", []).append(replanned)
                    result.total_ms = (time.perf_counter() - t_start) * 1e3
                    return result
            if progress is not None:
                progress((i + 1) / max(n_warm + samples, 1))
            yield (i + 1) / max(n_warm + samples, 1)
        if self.acc_count == 0:
            raise Cancelled()
        # the read-back below is of the last frame: wait for its fence (and so for every
        # frame before it), then read the timers of the latest frame that has them
        if frames_all:
            sync.wait(frames_all[-1])
        for fr in reversed(frames_all):
            if fr.timers.collect():
                pass_ms = dict(fr.timers.results)
                break
        for fr in frames_all:
            fr.timers.drop()
        frame_times = frame_sync.frame_interval_ms(frames_acc, prev_frame) if frames_acc and all(
            f.done for f in frames_acc) else []
        # the warm-up: from the end of the preparation to the last warm-up frame's completion
        warmup_ms = (max(0.0, (last_warm.t_done - t_loop) * 1e3 - warm_excluded_ms)
                     if last_warm is not None and last_warm.t_done is not None else 0.0)
        self.rc.barrier_external(list(self.acc_keys()))
        image = self._read(self.acc["Combined"])
        alpha_note = None
        if scene.film_transparent and "gbuffer.position" in written and "Alpha" in self.acc:
            image[..., 3] = self._read(self.acc["Alpha"])[..., 0]  # the surfaces' coverage
        elif scene.film_transparent and technique == "PT":
            pass  # PT's colour alpha is its camera rays' coverage
        else:
            if scene.film_transparent:
                alpha_note = f"film transparency: {technique} gives no coverage; the image is opaque"
            image[..., 3] = 1.0
        aovs = {}
        for aov in outputs:
            if aov != "Combined" and aov in self.acc:
                aovs[aov] = self._read(self.acc[aov], 3)
        if "gbuffer.position" in written:  # a graph without a G-buffer (PT) has none this frame
            self.rc.barrier_external(["gbuffer.position", "gbuffer.normal", "gbuffer.albedo", "gbuffer.geonormal"])
            aovs.update(self._gbuffer_aovs(scene))
        effects = sorted({e.value for p in plan.active for e in p.provides} & {e.value for e in analysis.needed})
        auto_record = plan_auto.as_dict() if plan_auto is not None else {}
        if plan_auto is not None and self._auto_redraws_over_budget(scene, plan_auto, frame_times, auto):
            auto_record["notes"].append(f"{plan_auto.candidate} measured over the {plan_auto.budget_ms:.0f} ms "
                                        "budget over the latest frames: the next frame is planned again")
        # what the scene export and the passes that ran approximated (e.g. DIRECT's many lights)
        warnings = list(scene.warnings) + [n for p in plan.active for n in getattr(p, "notes", ())]
        if alpha_note:
            warnings.append(alpha_note)
        return RenderResult(
            image=image, aovs=aovs, technique=technique, quality=quality, samples=self.acc_count,
            pass_ms=pass_ms, frame_ms=float(statistics.fmean(frame_times)) if frame_times else 0.0,
            total_ms=(time.perf_counter() - t_start) * 1e3, effects=effects,
            skipped_passes=list(plan.skipped), warnings=warnings,
            cancelled=bool(cancel is not None and cancel.is_set()),
            setup_ms=float(setup_ms), prep_ms=float(prep_ms), warmup_frames=int(warm_done),
            warmup_ms=float(warmup_ms), history_resets=list(reset),
            pass_order=graph.order, auto=auto_record)

    def _setup_clock(self) -> float:
        """Milliseconds of one-time work done so far: shader compiles and scene setup
        (BVH builds and uploads add to ``gpu_scene.setup_ms``)."""
        return float(self.programs.compile_ms) + float(getattr(self.gpu_scene, "setup_ms", 0.0))

    def acc_keys(self):
        return ["acc:" + k for k in self.acc]

    def _gbuffer_aovs(self, scene: SceneData) -> dict:
        """Depth (distance along the view axis), Normal (world) and DiffCol from the last G-buffer."""
        res = self.rc.resources
        out = {}
        if "gbuffer.position" not in res:
            return out
        pos = self._read(res["gbuffer.position"])
        bg = pos[..., 3] < 0
        cam = scene.camera
        fwd = cam.forward.astype(np.float32)
        depth = (pos[..., :3] - cam.position[None, None, :]) @ fwd
        depth = np.where(bg, np.float32(1e10), depth).astype(np.float32)
        out["Depth"] = depth[..., None]
        n = self._read(res["gbuffer.normal"], 3)
        out["Normal"] = np.where(bg[..., None], 0.0, n).astype(np.float32)
        alb = self._read(res["gbuffer.albedo"], 3)
        metal = self._read(res["gbuffer.geonormal"])[..., 3:4]
        out["DiffCol"] = np.where(bg[..., None], 0.0, alb * (1.0 - np.clip(metal, 0, 1))).astype(np.float32)
        return out

    def release(self):
        for tech, g in self.graphs.values():
            g.release()
        self.graphs.clear()
        for t in self.acc.values():
            t.release()
        self.acc.clear()
        if self.rc is not None:
            self.rc.resources.release()
        if self._shares is not None:
            self._shares.release()
            self._shares = None
        self.gpu_scene.release()
        self.programs.release()


def params_key(params: dict | None) -> tuple:
    """A hashable form of ``{pass name: {param: value}}`` (accumulation and viewport keys)."""
    return tuple(sorted((p, tuple(sorted(v.items()))) for p, v in (params or {}).items()))


def apply_overrides(graph, params: dict):
    """Hold ``params`` (``{pass name: {param: value}}``) over the graph's own values: each
    pass's parameters as built (its quality ladder) are kept on the graph the first time, and
    every call sets the pass to those plus ``params``, so a parameter left out returns to its
    ladder value. Passes or parameters the graph does not have are ignored (one settings
    table serves every technique). A change marks the pass's parameters changed (its
    history resets, as for any parameter change)."""
    base = getattr(graph, "_base_props", None)
    if base is None:
        base = {p.name: p.get_properties() for p in graph}
        graph._base_props = base
    for p in graph:
        want = dict(base.get(p.name, {}))
        declared = {d.name for d in p.params}
        want.update({k: v for k, v in params.get(p.name, {}).items() if k in declared})
        p.set_properties(want)  # marks the pass changed only where a value differs


def _get_session(key) -> Session:
    """The session named ``key`` (any hashable: ``"final"``, ``("viewport", region)``),
    created on first use. GL thread only."""
    s = _sessions.get(key)
    if s is None:
        s = Session(get_gl().ctx)
        _sessions[key] = s
    return s


def set_pass_properties(key, props: dict, technique: str | None = None, quality: int = 1,
                        denoiser: str = "NONE", use_taa: bool = False):
    """Set pass properties (``{pass name: {param: value}}``, FrameGraph.set_properties) on
    session ``key``'s graphs, for benches and tests that sweep a parameter: with ``technique``
    on that technique's graph at ``quality`` (built now if the session has none yet, so the
    values hold from its first frame), otherwise on every graph the session has built.
    Blocks until done. Runs on the GL thread as a job of the session's own queue, so it
    keeps submission order with that session's renders and with :func:`release_session`:
    after ``release_session(key)`` it applies to the fresh session, not to the one being
    released."""
    def go():
        s = _get_session(key)
        if technique:
            graphs = [s._graph(technique, quality, denoiser, use_taa)[1]]
        else:
            graphs = [g for _t, g in s.graphs.values()]
        for g in graphs:
            g.set_properties(props)
    get_gl().submit_job(go, key=("session", key)).result()


def release_all():
    """Free every session (runs on the GL thread)."""
    for s in _sessions.values():
        s.release()
    _sessions.clear()
    frame_sync.release_all()


def _release_session(key) -> bool:
    s = _sessions.pop(key, None)
    if s is None:
        return False
    s.release()
    return True


def release_session(key) -> Future | None:
    """Free the session ``key`` and its GL resources (a closed 3D view), after any render of
    it still queued. Non-blocking: returns the Future (None when no GL thread runs)."""
    from . import gl as _glmod

    if _glmod._gl is None or not _glmod._gl._thread.is_alive():
        return None
    return _glmod._gl.submit_job(_release_session, (key,), key=("session", key), priority=PRIORITY_BACKGROUND)


def session_keys() -> list:
    """The keys of the live sessions (read on the GL thread)."""
    return get_gl().call(lambda: list(_sessions))


def available_techniques():
    return techniques.available()


class RenderFuture(Future):
    """A render in flight (:func:`submit_render`): a ``concurrent.futures.Future`` whose
    result is the RenderResult, plus ``cancel_event`` (set it to stop at the next frame) and
    ``progress`` (the last fraction reported, updated from the GL thread)."""

    def __init__(self, cancel_event: threading.Event):
        super().__init__()
        self.cancel_event = cancel_event
        self.progress = 0.0
        self.submitted = time.perf_counter()


def submit_render(scene: SceneData, technique: str = "DIRECT", quality: int = 1, samples: int = 1, *,
                  cancel: threading.Event | None = None, continue_accumulation: bool = False,
                  keep_history: bool = False, session="final", priority: int = PRIORITY_INTERACTIVE,
                  on_done=None, post=None, **options) -> RenderFuture:
    """Queue a render on the GL thread and return at once (the viewport's entry point).

    The render runs as cooperative steps (one frame each, :meth:`Session.render_steps`): a
    render of ``PRIORITY_INTERACTIVE`` (the default: viewport frames) is served before the
    next frame of a longer job (an F12 accumulation, a sweep), so it waits for at most one
    frame of them. Renders of one session run in submission order. ``on_done(future)`` is
    called on the GL thread when the render ends (e.g. ``RenderEngine.tag_redraw``); the
    result (or the exception: ``Cancelled``, ``SceneError``, ...) is in the future.
    ``post(session, scene, result) -> result``, when given, runs on the GL thread after the
    render and before the future completes (e.g. the probe overlay, ``probe_overlay.py``)."""
    techniques.get(technique)  # unknown ids fail here, on the caller's thread
    gl = get_gl()
    stop = cancel if isinstance(cancel, threading.Event) else threading.Event()
    out = RenderFuture(stop)

    def progress(f):
        out.progress = float(f)

    def job():
        sess = _get_session(session)
        steps = sess.render_steps(scene, technique, int(quality), int(samples), cancel=stop, progress=progress,
                                  continue_accumulation=continue_accumulation, keep_history=keep_history,
                                  **options)
        if post is None:
            return steps

        def steps_then_post():
            res = yield from steps
            return post(sess, scene, res)
        return steps_then_post()

    inner = gl.submit_job(job, priority=priority, key=("session", session))

    def relay(f: Future):
        try:
            exc = f.exception()
        except BaseException as e:  # noqa: BLE001 - cancelled inner future
            exc = e
        if exc is not None:
            out.set_exception(exc)
        else:
            out.set_result(f.result())
        if on_done is not None:
            try:
                on_done(out)
            except Exception:  # noqa: BLE001 - a callback must not kill the GL thread
                log.exception("GI Preview: render callback failed")

    inner.add_done_callback(relay)
    return out


def render(scene: SceneData, technique: str = "DIRECT", quality: int = 1, samples: int = 1, *,
           progress=None, cancel=None, continue_accumulation: bool = False, keep_history: bool = False,
           session="final", poll_s: float = 0.05, priority: int = PRIORITY_NORMAL, **options) -> RenderResult:
    """Render ``scene`` with a technique; blocks until done. Callable from any thread.

    The GL thread runs it one frame at a time (see :func:`submit_render`), so viewport
    frames and other sessions are served between its frames. progress: ``f(fraction)``
    called on the calling thread. cancel: a ``threading.Event`` or a callable returning True
    to stop; checked between frames (a cancelled render returns what has accumulated, with
    ``cancelled=True``; cancelled before the first frame raises ``Cancelled``). options:
    passed to :meth:`Session.render_steps` (``camera_cut``, ``warmup``).
    """
    stop = cancel if isinstance(cancel, threading.Event) else threading.Event()
    prog_q: queue.Queue = queue.Queue()
    fut = submit_render(scene, technique, quality, samples, cancel=stop, continue_accumulation=continue_accumulation,
                        keep_history=keep_history, session=session, priority=priority, **options)
    last = [0.0]

    def relay_progress():
        if progress and fut.progress != last[0]:
            last[0] = fut.progress
            progress(fut.progress)

    while True:
        try:
            result = fut.result(timeout=poll_s)
            break
        except FutureTimeout:
            pass
        if callable(cancel) and not isinstance(cancel, threading.Event) and cancel():
            stop.set()
        relay_progress()
    relay_progress()
    return result
