"""The frame graph: passes declare what they provide, read, write and keep; the graph owns
the resources, the order, the memory barriers and the history.

The pass contract (docs/ARCHITECTURE.md has the full table):

* ``provides``: the effects a pass contributes (``Effect``); the planner runs a pass only
  when the scene calls for one of them, or when a running pass reads what it writes.
* ``reads`` / ``writes``: resource names (``"gbuffer.normal"``, ``"shadow.atlas"``,
  ``"color"``). ``optional_reads`` are used when some running pass writes them and pull
  nothing in. A read of ``"X@prev"`` reads last frame's value of the history resource ``X``.
* ``resources()``: typed declarations (``Res``) of what the pass writes: 2D, 2D array, 3D,
  depth or buffer; format; size relative to the frame (optionally scaled by a parameter) or
  absolute; transient or ``history`` (double-buffered by the graph). The graph allocates
  them; ``rc.resources[name]`` is this frame's object.
* ``kind``: ``"compute"`` (writes with imageStore / SSBO stores), ``"raster"`` (writes
  through framebuffer attachments) or ``"mixed"``; ``write_access`` / ``read_access`` say per
  resource how it is written and read (barriers.py lists the accesses). The graph derives
  the memory barriers from them. ``external``: objects the graph does not own.
* ``history_resets``: which events invalidate the pass's history: ``camera_cut``,
  ``param_change`` and the scene edits ``geometry``, ``transforms``, ``materials``,
  ``lights`` (any light or the world changed), ``light_set`` (which lights there are changed:
  one added, removed or of another type, the emissive instances, the world; always with
  ``lights``), ``textures`` (``SCENE_EDIT`` is all six). The graph applies them: it clears the
  pass's history resources and hands the pass ``history_valid = False`` for that frame.
* ``warmup_frames``: frames a pass's state needs to converge before an F12 render starts
  accumulating (probes, caches, reservoirs); ``converged(rc)`` may end the warm-up early.
* ``params``/``quality_ladder``; ``compile(rc)`` (after allocation, for pass-owned objects
  such as framebuffers), ``execute(rc, frame)``.

Planning (``FrameGraph.plan``) chooses the passes the scene needs, pulls in their
producers, and orders them topologically. Declaration order only decides the versions of a
resource written by several passes (``color`` written by DIRECT, then added to by each
composite); a read with no producer, or a cycle, is a ``PlanError`` naming the pass.
Execution (``FrameGraph.execute``) inserts ``glMemoryBarrier`` between an incoherent writer
(image or storage stores) and every later access, with the bits the access type needs
(barriers.required_bits), recorded in ``barrier_log``; clears and uploads through
``RenderContext`` are ordered and recorded the same way. ``GI_PREVIEW_VALIDATE=2`` (or
``GI_PREVIEW_VALIDATE_SYNC=1`` alone) checks the declarations and barriers against what the
passes do (sync_check).
With ``GI_PREVIEW_VALIDATE=1`` every resource a pass writes is read back and checked for
NaN, Inf and (for radiance) negative values; the first bad value raises
``ValidationError`` naming the pass and the resource.
"""
from __future__ import annotations

import enum
import heapq
import logging
import os
import time
from dataclasses import dataclass, field

import numpy as np

from . import sync_check
from .result import SkippedPass

log = logging.getLogger(__name__)


class Effect(str, enum.Enum):
    DIRECT = "direct"  # direct light from lights
    SHADOWS = "shadows"
    EMISSION = "emission"  # emissive surfaces seen directly and lighting others
    ENVIRONMENT = "environment"  # world background / world light
    INDIRECT_DIFFUSE = "indirect_diffuse"
    INDIRECT_SPECULAR = "indirect_specular"
    AO = "ao"


class PlanError(ValueError):
    """The graph cannot be planned: a read nobody writes, a cycle, a conflicting declaration."""


class ValidationError(RuntimeError):
    """GI_PREVIEW_VALIDATE found a NaN, Inf or negative value in a pass output."""


# ---------------------------------------------------------------- history events
CAMERA_CUT = "camera_cut"
PARAM_CHANGE = "param_change"
LIGHT_SET = "light_set"  # which lights there are: added, removed, type changed; emissive instances; the world
SCENE_EDITS = ("geometry", "transforms", "materials", "lights", LIGHT_SET, "textures")
SCENE_EDIT = frozenset(SCENE_EDITS)
ALL_EVENTS = frozenset({CAMERA_CUT, PARAM_CHANGE}) | SCENE_EDIT
PREV = "@prev"  # suffix: last frame's value of a history resource

# ---------------------------------------------------------------- GL barrier bits (one table: barriers.py)
from .barriers import (  # noqa: E402,F401  (re-exported: passes import the bits from here)
    ALL_BARRIER_BITS, BARRIER_NAMES, BUFFER_READ_BITS, BUFFER_UPDATE_BARRIER_BIT, COMMAND_BARRIER_BIT,
    ELEMENT_ARRAY_BARRIER_BIT, FRAMEBUFFER_BARRIER_BIT, INCOHERENT_WRITES, PIXEL_BUFFER_BARRIER_BIT,
    READ_ACCESS_NAMES, SHADER_IMAGE_ACCESS_BARRIER_BIT, SHADER_STORAGE_BARRIER_BIT, TEXTURE_FETCH_BARRIER_BIT,
    TEXTURE_READ_BITS, TEXTURE_UPDATE_BARRIER_BIT, UNIFORM_BARRIER_BIT, VERTEX_ATTRIB_ARRAY_BARRIER_BIT,
    WRITE_ACCESS_NAMES, barrier_names, required_bits)


# ---------------------------------------------------------------- resources
TEX2D, TEX2D_ARRAY, TEX3D, DEPTH, BUFFER, HOST = "tex2d", "tex2d_array", "tex3d", "depth", "buffer", "host"
TEXTURE_KINDS = (TEX2D, TEX2D_ARRAY, TEX3D, DEPTH)


@dataclass(frozen=True)
class Res:
    """A typed resource declaration.

    kind: ``tex2d``, ``tex2d_array``, ``tex3d``, ``depth``, ``buffer`` or ``host`` (a Python
    object a pass stores itself, e.g. a view range). components/dtype: texel format
    (moderngl dtypes ``f1``, ``f2``, ``f4``, ``u4``, ``i4``). size: ``None`` = the frame size
    times ``scale`` (a number, or the name of a pass parameter holding it); otherwise an
    absolute (w, h) / (w, h, d or layers) or, for buffers, a byte count. ``levels``: mip
    levels (0 = full chain). ``history``: double-buffered by the graph (``name`` is written
    this frame, ``name@prev`` holds last frame's). ``managed=False``: the pass allocates the
    object itself (sizes only it knows); the graph still orders, barriers and validates it.
    ``check``: what GI_PREVIEW_VALIDATE asserts: ``radiance`` (finite, >= 0), ``finite``, or
    ``none``. ``clear``: value the graph clears a history resource to on reset. ``tile``: a
    texture of ``per_tile`` texels per side for every ``tile`` x ``tile`` pixel tile of the
    frame (screen probes: one texel per probe, or a probe's ray texels)."""

    name: str
    kind: str = TEX2D
    components: int = 4
    dtype: str = "f4"
    size: tuple | int | None = None
    scale: float | str = 1.0
    levels: int = 1
    filter_linear: bool = False
    history: bool = False
    managed: bool = True
    check: str = "finite"
    clear: tuple = (0.0, 0.0, 0.0, 0.0)
    tile: int = 0
    per_tile: int = 1

    def resolve_size(self, frame_size, props: dict):
        if self.tile > 0:
            t = int(self.tile)
            return tuple(-(-int(x) // t) * int(self.per_tile) for x in frame_size[:2])
        if self.size is not None:
            return tuple(self.size) if not isinstance(self.size, int) else int(self.size)
        s = props[self.scale] if isinstance(self.scale, str) else self.scale
        s = float(s)
        if s == 1.0:
            return tuple(frame_size)
        return (max(1, int(np.ceil(frame_size[0] * s))), max(1, int(np.ceil(frame_size[1] * s))))


@dataclass(frozen=True)
class Param:
    name: str
    default: float | int | bool
    min: float | None = None
    max: float | None = None
    doc: str = ""

    def clamp(self, value):
        if isinstance(self.default, bool):
            return bool(value)
        if isinstance(self.default, int):
            value = int(round(value))
        else:
            value = float(value)
        if self.min is not None:
            value = max(self.min, value)
        if self.max is not None:
            value = min(self.max, value)
        return type(self.default)(value)


class Pass:
    """Base class of every pass. Subclasses set the class attributes and implement
    ``execute`` (and ``compile`` for objects they own besides declared resources)."""

    name: str = "pass"
    # "compute" (writes with image / storage stores), "raster" (writes through framebuffer
    # attachments) or "mixed" (both: every written resource is named in write_access)
    kind: str = "compute"
    provides: frozenset = frozenset()
    reads: tuple = ()
    optional_reads: tuple = ()  # used if some running pass writes them (e.g. shadows)
    writes: tuple = ()
    external: tuple = ()  # objects owned outside the graph that the pass uses (registered in rc.resources)
    declared: tuple = ()  # of Res: typed declarations of written resources (see resources())
    # resource -> how the pass writes it: "image" | "storage" | "framebuffer" | "upload" | "host",
    # or a tuple of these in the order the pass does them (clear by framebuffer, then image stores)
    write_access: dict = {}
    # resource -> how the pass reads it (barriers.READ_ACCESSES), or a tuple; default: a
    # texture is fetched or image-loaded, a buffer read as storage / uniform / vertex / indirect
    read_access: dict = {}
    history_resets: frozenset = ALL_EVENTS  # events that invalidate this pass's history
    warmup_frames: int = 0  # frames of state convergence before F12 accumulates
    # the state that needs warming up depends only on this pass and the producers of what it
    # reads (probes: their rays, not the image): warm-up frames then run just those passes
    warmup_alone: bool = False
    params: tuple = ()  # of Param
    quality_ladder: tuple = ()  # of dicts, index = quality level
    always: bool = False  # runs whatever the scene needs (e.g. the G-buffer, the final resolve)
    # the planned passes that read what this pass writes (set by FrameGraph.plan): a producer
    # may ask its consumers what they can do without it (the shadow pass: who traces shadows)
    consumers: tuple = ()

    def __init__(self, quality: int | None = None, **props):
        self.props = {p.name: p.default for p in self.params}
        if quality is not None and self.quality_ladder:
            q = max(0, min(int(quality), len(self.quality_ladder) - 1))
            self.set_properties(self.quality_ladder[q])
        self.set_properties(props)
        self.history_valid = False
        self.params_changed = False

    # -------------------------------------------------------------- declarations
    def resources(self) -> tuple:
        """Typed declarations of the resources this pass writes (default: ``declared``)."""
        return tuple(self.declared)

    @property
    def history(self) -> tuple:
        return tuple(r.name for r in self.resources() if r.history)

    def write_accesses(self, name: str, decl: "Res | None") -> tuple:
        """How this pass writes ``name``, in order: image, storage, framebuffer, upload or host."""
        if name in self.write_access:
            a = self.write_access[name]
            return (a,) if isinstance(a, str) else tuple(a)
        if decl is not None and decl.kind == HOST:
            return ("host",)
        if self.kind == "mixed":
            raise PlanError(f"pass '{self.name}' is kind='mixed' but does not say in write_access how it "
                            f"writes '{name}'")
        if decl is not None and decl.kind == BUFFER:
            return ("storage",) if self.kind == "compute" else ("upload",)
        return ("image",) if self.kind == "compute" else ("framebuffer",)

    def access(self, name: str, decl: "Res | None") -> str:
        """The last way this pass writes ``name`` (what a later reader waits on)."""
        return self.write_accesses(name, decl)[-1]

    def read_accesses(self, name: str, decl: "Res | None") -> tuple:
        """How this pass reads ``name`` (barriers.READ_ACCESSES)."""
        a = self.read_access.get(name, self.read_access.get(_base(name)))
        if a is not None:
            return (a,) if isinstance(a, str) else tuple(a)
        if decl is not None and decl.kind == HOST:
            return ("host",)
        if decl is not None and decl.kind == BUFFER:
            return ("storage", "uniform", "vertex", "index", "indirect")
        return ("texture", "image")

    def converged(self, rc) -> bool | None:
        """Measured convergence for the warm-up (None = count ``warmup_frames``)."""
        return None

    # -------------------------------------------------------------- properties
    def get_properties(self) -> dict:
        return dict(self.props)

    def set_properties(self, props: dict):
        decl = {p.name: p for p in self.params}
        changed = False
        for k, v in props.items():
            if k not in decl:
                log.warning("pass %s: unknown property %r ignored", self.name, k)
                continue
            v = decl[k].clamp(v)
            if self.props.get(k) != v:
                self.props[k] = v
                changed = True
        if changed:
            self.params_changed = True

    def __getitem__(self, key):
        return self.props[key]

    # -------------------------------------------------------------- lifecycle
    def compile(self, rc: "RenderContext"):
        """Create pass-owned objects (framebuffers, ...) after the graph allocated the
        declared resources. Called when the size or the allocation changes."""

    def execute(self, rc: "RenderContext", frame: "FrameState"):
        raise NotImplementedError

    def reset_history(self):
        """Forget state kept outside declared resources (the graph clears those)."""
        self.history_valid = False

    def release(self):
        """Free GL objects this pass owns (declared resources are freed by the graph)."""


@dataclass
class FrameState:
    """Per-frame values every pass can read."""

    index: int = 0  # frame number within the current accumulation (0 = first)
    sample: int = 0  # global sample counter (seeds)
    jitter: tuple = (0.0, 0.0)  # sub-pixel offset in pixels, in [-0.5, 0.5)
    view: np.ndarray | None = None
    proj: np.ndarray | None = None  # jittered projection
    proj_unjittered: np.ndarray | None = None
    prev_view_proj: np.ndarray | None = None
    camera_changed: bool = True  # the view moved since the previous frame
    camera_cut: bool = True  # the previous frame's view is not a predecessor of this one
    scene_changed: bool = True
    scene_edits: frozenset = frozenset()  # of SCENE_EDITS categories changed since last frame
    seed: int = 0
    warmup: bool = False  # a warm-up frame (not accumulated)
    keeps_history: bool = False  # history kept across renders (viewport, animation), not one fresh accumulation


class Resources(dict):
    """Named GL objects shared by passes (textures, buffers, framebuffers)."""

    def need(self, name: str, owner: str):
        if name not in self:
            raise KeyError(f"pass '{owner}' reads resource '{name}', which no pass has written")
        return self[name]

    def release(self):
        for obj in self.values():
            try:
                obj.release()
            except Exception:
                pass
        self.clear()


def _alloc(ctx, decl: Res, size):
    """Create the GL object of a declaration."""
    import moderngl

    filt = (moderngl.LINEAR, moderngl.LINEAR) if decl.filter_linear else (moderngl.NEAREST, moderngl.NEAREST)
    if decl.kind == TEX2D:
        obj = ctx.texture(size, decl.components, dtype=decl.dtype)
    elif decl.kind == TEX2D_ARRAY:
        obj = ctx.texture_array(size, decl.components, dtype=decl.dtype)
    elif decl.kind == TEX3D:
        obj = ctx.texture3d(size, decl.components, dtype=decl.dtype)
    elif decl.kind == DEPTH:
        return ctx.depth_texture(size)
    elif decl.kind == BUFFER:
        return ctx.buffer(reserve=max(4, int(size)))
    else:
        raise PlanError(f"resource '{decl.name}': kind '{decl.kind}' cannot be allocated")
    if decl.levels != 1:
        top = max(size[:2]) if decl.kind != TEX3D else max(size)
        levels = decl.levels if decl.levels > 0 else int(np.floor(np.log2(max(top, 1)))) + 1
        obj.build_mipmaps(0, levels - 1)
        obj.filter = ((moderngl.LINEAR_MIPMAP_LINEAR if decl.filter_linear else moderngl.NEAREST_MIPMAP_NEAREST),
                      filt[1])
    else:
        obj.filter = filt
    obj.repeat_x = obj.repeat_y = False
    if decl.kind == TEX3D:
        obj.repeat_z = False
    return obj


class RenderContext:
    """What passes see: the GL context, compiled programs, the GPU scene, resources, size.

    It also keeps, across frames and graphs of one session, the barrier state of every
    resource (who last wrote it, and how) and the allocation of declared resources."""

    def __init__(self, ctx, programs, gpu_scene, size: tuple[int, int]):
        self.ctx = ctx
        self.programs = programs
        self.scene = gpu_scene
        self.size = size  # (width, height)
        self.resources = Resources()
        self.timers: dict[str, float] = {}
        self.specs: dict[str, tuple] = {}  # resource name -> (Res, resolved size) it was allocated with
        # barrier state: name -> [writer pass, access, pending read bits (to be made visible)]
        self.sync: dict[str, list] = {}
        self._clear_fbos: dict = {}
        # objects owned outside the graph (the GPU scene's buffers) that a pass declares it
        # writes: name -> object; ``scene_wide``: those every pass may read undeclared
        self.external: dict[str, object] = {}
        self.scene_wide: set = set()

    @property
    def width(self) -> int:
        return self.size[0]

    @property
    def height(self) -> int:
        return self.size[1]

    # -------------------------------------------------------------- allocation
    def allocate(self, decl: Res, props: dict | None = None) -> bool:
        """Allocate ``decl`` (and its ``@prev`` twin for history) unless an object with the
        same spec exists. Returns True when something was (re)allocated."""
        if not decl.managed or decl.kind == HOST:
            return False
        size = decl.resolve_size(self.size, props or {})
        spec = (decl.kind, decl.components, decl.dtype, size, decl.levels, decl.filter_linear)
        names = (decl.name, decl.name + PREV) if decl.history else (decl.name,)
        if all(self.specs.get(n, (None, None))[1] == spec and n in self.resources for n in names):
            return False
        for n in names:
            old = self.resources.pop(n, None)
            if old is not None:
                self._drop_clear_fbo(old)
                old.release()
            self.resources[n] = _alloc(self.ctx, decl, size)
            self.specs[n] = (decl, spec)
            self.sync.pop(n, None)
        return True

    def texture(self, name: str, components: int = 4, dtype: str = "f4", size=None, *, filter_linear=False):
        """Get or create a 2D texture resource of the frame size (or ``size``): the same
        allocator as declared resources, for scratch textures a pass makes on the fly."""
        decl = Res(name, TEX2D, components, dtype, size=tuple(size) if size is not None else None,
                   filter_linear=filter_linear)
        self.allocate(decl)
        return self.resources[name]

    # -------------------------------------------------------------- history
    def swap_history(self, name: str):
        cur, prev = self.resources.get(name), self.resources.get(name + PREV)
        if cur is None or prev is None:
            return
        self.resources[name], self.resources[name + PREV] = prev, cur
        sp_cur, sp_prev = self.specs.pop(name, None), self.specs.pop(name + PREV, None)
        if sp_prev is not None:  # (unmanaged history has no spec)
            self.specs[name] = sp_prev
        if sp_cur is not None:
            self.specs[name + PREV] = sp_cur
        s_cur, s_prev = self.sync.pop(name, None), self.sync.pop(name + PREV, None)
        if s_cur is not None:
            self.sync[name + PREV] = s_cur
        if s_prev is not None:
            self.sync[name] = s_prev

    def clear_resource(self, name: str, value=(0.0, 0.0, 0.0, 0.0), *, by: str = "graph"):
        """Fill a texture or buffer with ``value`` (history reset). The clear is ordered after
        the resource's last incoherent write and recorded as its last write."""
        obj = self.resources.get(name)
        if obj is None:
            return
        decl = self.specs.get(name, (None,))[0]
        kind = decl.kind if decl is not None else (BUFFER if self.is_buffer(name) else TEX2D)
        if kind == HOST:
            return
        with _graph_op():
            done = self._clear(name, obj, kind, value)
        if done:
            self.record_write([name], "upload", by)

    def _clear(self, name, obj, kind, value):
        if kind == BUFFER:
            self.order_access([name], "upload")
            obj.clear()
            return True
        if kind == TEX2D and getattr(obj, "dtype", "f4").startswith("f"):
            self.order_access([name], "framebuffer")
            fbo = self._clear_fbos.get(id(obj))
            if fbo is None:
                fbo = self.ctx.framebuffer(color_attachments=[obj])
                self._clear_fbos[id(obj)] = fbo
            v = tuple(value) + (0.0,) * (4 - len(value))
            fbo.clear(*v[:4])
            return True
        if kind in (TEX2D, TEX2D_ARRAY, TEX3D):
            self.order_access([name], "upload")
            comps = obj.components
            dt = {"f1": np.uint8, "f2": np.float16, "f4": np.float32, "u4": np.uint32, "i4": np.int32}.get(
                obj.dtype, np.float32)
            shape = tuple(obj.size) + (comps,)
            arr = np.empty(shape, dt)
            arr[...] = np.asarray(tuple(value)[:comps] + (0,) * max(0, comps - len(value)), dt)
            obj.write(arr.tobytes())
            return True
        return False

    def upload(self, name: str, data: bytes, *, by: str = "graph"):
        """Write ``data`` into the resource ``name`` from the CPU, ordered after its last
        incoherent write and recorded as its last write."""
        with _graph_op():
            self.order_access([name], "upload")
            self.resources[name].write(data)
        self.record_write([name], "upload", by)

    def read_back(self, name: str) -> bytes:
        """The bytes of resource ``name``, after its last incoherent write is visible."""
        self.order_access([name], "readback")
        return self.resources[name].read()

    # -------------------------------------------------------------- synchronisation record
    def register_external(self, name: str, obj, *, scene_wide: bool = False):
        """Name an object the graph does not own (not released with the resources) so that
        its accesses are recorded and checked; ``scene_wide``: every pass reads it (bound
        with the scene), only its writers declare it."""
        self.external[name] = obj
        if scene_wide:
            self.scene_wide.add(name)

    def is_buffer(self, name: str) -> bool:
        decl = self.specs.get(name, (None,))[0]
        if decl is not None:
            return decl.kind == BUFFER
        import moderngl

        return isinstance(self.resources.get(name, self.external.get(name)), moderngl.Buffer)

    def order_access(self, names, access: str, *, extra: int = 0) -> int:
        """Issue the barrier that orders ``access`` (a read access of barriers.READ_ACCESSES,
        or a write access) to ``names`` after their last recorded incoherent writes; bits
        already issued since are not repeated. Returns the bits issued."""
        need = 0
        for n in names:
            st = self.sync.get(n)
            if st is None:
                continue
            is_buf = self.is_buffer(n)
            bits = required_bits(st[1], access, is_buf)
            if access in INCOHERENT_WRITES:  # an incoherent write after earlier accesses (WAW, WAR)
                bits |= SHADER_STORAGE_BARRIER_BIT if is_buf else SHADER_IMAGE_ACCESS_BARRIER_BIT
            bits |= extra if st[1] in INCOHERENT_WRITES else 0
            missing = bits & ~st[2]
            need |= missing
        if need:
            self.ctx.memory_barrier(need)
            self.barriers_issued(need)
        return need

    def barriers_issued(self, bits: int):
        """Bits issued (by the graph or inside a pass): every pending write they cover is visible."""
        for st in self.sync.values():
            if st[1] in INCOHERENT_WRITES:
                st[2] |= bits

    def record_write(self, names, access: str, by: str):
        """``by`` wrote ``names`` with ``access`` (image, storage, framebuffer, upload, host)."""
        for n in names:
            self.sync[n] = [by, access, 0]

    def _drop_clear_fbo(self, obj):
        fbo = self._clear_fbos.pop(id(obj), None)
        if fbo is not None:
            fbo.release()

    # -------------------------------------------------------------- raster helpers
    def layered_framebuffer(self, color: list[str], depth: str | None = None):
        """A framebuffer whose attachments are whole 2D arrays / 3D textures: a geometry
        shader picks the layer with ``gl_Layer`` (cube maps, voxelisation, layered shadow maps)."""
        res = self.resources
        return self.ctx.framebuffer(color_attachments=[res[n] for n in color],
                                    depth_attachment=res[depth] if depth else None)

    def empty_framebuffer(self, size, layers: int = 0):
        """A framebuffer with no attachments of ``size`` (rasterise to drive fragment-shader
        imageStore, e.g. conservative voxelisation into a 3D image)."""
        return self.ctx.empty_framebuffer(tuple(size), layers=layers)

    # -------------------------------------------------------------- dispatch
    def dispatch(self, program, groups_x: int, groups_y: int = 1, groups_z: int = 1):
        inv = self._inv_view_proj()
        if inv is not None:  # lib/world.glsl's camera rays (the background), where declared
            from .gpu_scene import set_uniform

            set_uniform(program, "u_inv_view_proj", inv)
        program.run(max(1, groups_x), max(1, groups_y), max(1, groups_z))

    def _inv_view_proj(self):
        """Inverse of the current frame's (jittered) view-projection, or None."""
        f = getattr(self, "frame", None)
        if f is None or f.view is None or f.proj is None:
            return None
        vp = np.asarray(f.proj, np.float64) @ np.asarray(f.view, np.float64)
        return np.linalg.inv(vp).astype(np.float32)

    def groups(self, local: int = 8) -> tuple[int, int]:
        return (self.width + local - 1) // local, (self.height + local - 1) // local

    def barrier_external(self, names, bits: int = TEXTURE_FETCH_BARRIER_BIT | TEXTURE_UPDATE_BARRIER_BIT
                         | BUFFER_UPDATE_BARRIER_BIT | SHADER_IMAGE_ACCESS_BARRIER_BIT) -> int:
        """Make incoherent writes to ``names`` visible to code outside the graph (the
        session's accumulation, read-backs): ``bits`` covers the accesses that code makes.
        Returns the bits issued (0 = none needed)."""
        return self.order_access(names, "host", extra=bits)


class _graph_op:
    """Accesses the graph orders and records itself (clears, uploads): sync validation does
    not attribute them to the pass that asked for them."""

    def __enter__(self):
        self.saved = sync_check.VALIDATOR.suspend()

    def __exit__(self, *exc):
        sync_check.VALIDATOR.resume(self.saved)


@dataclass
class Plan:
    active: list
    skipped: list[SkippedPass] = field(default_factory=list)


def _base(name: str) -> str:
    return name[: -len(PREV)] if name.endswith(PREV) else name


def validate_enabled() -> bool:
    return os.environ.get("GI_PREVIEW_VALIDATE", "") not in ("", "0", "false", "False")


_NP_DT = {"f1": np.uint8, "f2": np.float16, "f4": np.float32, "u4": np.uint32, "i4": np.int32}


class FrameGraph:
    """Passes planned against the effects the scene calls for, run in topological order with
    the barriers and history the declarations imply."""

    def __init__(self, passes: list[Pass]):
        names = [p.name for p in passes]
        if len(set(names)) != len(names):
            raise ValueError(f"duplicate pass names in graph: {names}")
        self.passes = list(passes)
        self._plan: Plan | None = None
        self._compiled_size = None
        self._compiled_rc = None
        self.barrier_log: list[dict] = []  # this frame's barriers: before, resources, bits, names
        self.history_log: list[dict] = []  # every history reset: pass, events, frame sample
        self.validation_log: list[str] = []
        self.sync_log: list[str] = []  # sync validation's findings (sync_check)
        self.derive_barriers = True  # False only to test the validation
        self._decls: dict[str, Res] = {}
        self._decl_owner: dict[str, str] = {}
        self._collect_declarations()

    def __iter__(self):
        return iter(self.passes)

    def find(self, name: str) -> Pass:
        for p in self.passes:
            if p.name == name:
                return p
        raise KeyError(name)

    def _collect_declarations(self):
        decls, owner = {}, {}
        for p in self.passes:
            for d in p.resources():
                if d.name not in p.writes:
                    raise PlanError(f"pass '{p.name}' declares resource '{d.name}' but does not list it in writes")
                old = decls.get(d.name)
                if old is not None and (old.kind, old.components, old.dtype, old.history) != (
                        d.kind, d.components, d.dtype, d.history):
                    raise PlanError(f"resource '{d.name}' is declared differently by passes "
                                    f"'{owner[d.name]}' and '{p.name}'")
                if old is None:
                    decls[d.name], owner[d.name] = d, p.name
        self._decls, self._decl_owner = decls, owner

    def declaration(self, name: str) -> Res | None:
        return self._decls.get(_base(name))

    # ------------------------------------------------------------------ planning
    def _writers(self, name: str, among=None) -> list[int]:
        return [i for i, p in enumerate(self.passes) if name in p.writes and (among is None or among[i])]

    def plan(self, needed: set, reasons: dict[str, str] | None = None) -> Plan:
        """Choose the passes to run: those that are ``always`` or provide a needed effect,
        plus (transitively) the producers of what they read; order them topologically.
        ``reasons`` maps an effect to why the scene does not need it."""
        reasons = reasons or {}
        n = len(self.passes)
        chosen = [p.always or bool(p.provides & needed) for p in self.passes]
        # every read must have a producer in the graph (history reads: last frame's value)
        for i, p in enumerate(self.passes):
            for r in p.reads:
                if r.endswith(PREV):
                    d = self._decls.get(_base(r))
                    if d is None or not d.history:
                        raise PlanError(f"pass '{p.name}' reads '{r}', but '{_base(r)}' is not a history "
                                        f"resource of any pass in the graph")
                elif not self._writers(r):
                    raise PlanError(f"pass '{p.name}' reads '{r}', which no pass in the graph writes")
        changed = True
        while changed:
            changed = False
            for i in range(n):
                if not chosen[i]:
                    continue
                for r in self.passes[i].reads:
                    if r.endswith(PREV):
                        r = _base(r)
                        for j in self._writers(r):
                            if not chosen[j]:
                                chosen[j] = changed = True
                        continue
                    before = [j for j in self._writers(r) if j < i]
                    if before:
                        if not any(chosen[j] for j in before):
                            chosen[before[-1]] = changed = True
                    else:
                        for j in self._writers(r):
                            if not chosen[j]:
                                chosen[j] = changed = True
        order = self._toposort(chosen)
        skipped = []
        for p, c in zip(self.passes, chosen):
            if not c:
                why = "; ".join(reasons.get(e, f"scene does not need {e.value}") for e in
                                sorted(p.provides, key=lambda e: e.value)) or "not needed"
                skipped.append(SkippedPass(p.name, sorted(e.value for e in p.provides), why))
        self._plan = Plan([self.passes[i] for i in order], skipped)
        for p in self._plan.active:
            outs = set(p.writes)
            p.consumers = tuple(q for q in self._plan.active
                                if q is not p and outs & (set(q.reads) | set(q.optional_reads)))
        return self._plan

    def _toposort(self, chosen: list[bool]) -> list[int]:
        """Kahn's algorithm over the active passes, ties broken by declaration order.

        Edges: the producer of each read (the nearest earlier writer; if none is declared
        earlier, every writer); writers of one resource in declaration order; a reader
        before the next writer of what it read (write-after-read)."""
        act = [i for i in range(len(self.passes)) if chosen[i]]
        edges: dict[int, set] = {i: set() for i in act}
        for i in act:
            p = self.passes[i]
            for r in tuple(p.reads) + tuple(p.optional_reads):
                if r.endswith(PREV):
                    continue
                ws = self._writers(r, chosen)
                before = [j for j in ws if j < i]
                producers = [before[-1]] if before else [j for j in ws if j != i]
                for j in producers:
                    edges[j].add(i)
                after = [j for j in ws if j > i]
                if before and after and after[0] != i:
                    edges[i].add(after[0])  # read the version before the next write
        for r in {w for i in act for w in self.passes[i].writes}:
            ws = self._writers(r, chosen)
            for a, b in zip(ws, ws[1:]):
                edges[a].add(b)
        indeg = {i: 0 for i in act}
        for a in act:
            for b in edges[a]:
                if b != a:
                    indeg[b] += 1
        ready = [i for i in act if indeg[i] == 0]
        heapq.heapify(ready)
        order = []
        while ready:
            a = heapq.heappop(ready)
            order.append(a)
            for b in sorted(edges[a]):
                if b == a:
                    continue
                indeg[b] -= 1
                if indeg[b] == 0:
                    heapq.heappush(ready, b)
        if len(order) != len(act):
            stuck = [self.passes[i].name for i in act if i not in order]
            raise PlanError(f"the passes {', '.join(repr(s) for s in stuck)} depend on each other in a cycle "
                            f"(each reads what another writes)")
        return order

    @property
    def order(self) -> list[str]:
        return [p.name for p in self._plan.active] if self._plan else []

    # ------------------------------------------------------------------ resources
    def allocate(self, rc: RenderContext) -> bool:
        """Allocate every declared resource of every pass for ``rc.size`` (idempotent)."""
        changed = False
        for p in self.passes:
            for d in p.resources():
                changed |= rc.allocate(d, p.props)
        return changed

    def compile(self, rc: RenderContext, force: bool = False):
        """Allocate declared resources; (re)compile passes when the size, the context or an
        allocation changed. Recompiling invalidates history."""
        realloc = self.allocate(rc)
        if force or realloc or self._compiled_size != rc.size or self._compiled_rc is not rc:
            for p in self.passes:
                p.compile(rc)
                p.reset_history()
                for h in p.history:
                    rc.clear_resource(h)
                    rc.clear_resource(h + PREV)
            self._compiled_size = rc.size
            self._compiled_rc = rc

    # ------------------------------------------------------------------ history
    def apply_history_events(self, rc: RenderContext, events: set) -> list[str]:
        """Invalidate the history of every pass whose ``history_resets`` meets ``events``
        (plus the passes whose parameters changed). Returns the names of reset passes."""
        reset = []
        for p in self.passes:
            ev = set(events) & set(p.history_resets)
            if p.params_changed and PARAM_CHANGE in p.history_resets:
                ev.add(PARAM_CHANGE)
            p.params_changed = False
            if not ev:
                continue
            p.reset_history()
            for h in p.history:
                d = self._decls[h]
                rc.clear_resource(h, d.clear)
                rc.clear_resource(h + PREV, d.clear)
            reset.append(p.name)
            self.history_log.append({"pass": p.name, "events": sorted(ev)})
        return reset

    def reset_history(self, rc: RenderContext | None = None):
        """Invalidate every pass's history (a camera cut for all)."""
        for p in self.passes:
            p.reset_history()
            p.params_changed = False
            if rc is not None:
                for h in p.history:
                    d = self._decls[h]
                    rc.clear_resource(h, d.clear)
                    rc.clear_resource(h + PREV, d.clear)

    def warmup_frames(self) -> int:
        if self._plan is None:
            return 0
        return max((int(p.warmup_frames) for p in self._plan.active), default=0)

    def warmup_passes(self) -> list:
        """The passes a warm-up frame runs: all planned ones, or, when every pass that asks
        for warm-up frames is ``warmup_alone``, only those and (transitively) the producers of
        what they read, this frame's and last frame's; the image of a warm-up frame is thrown
        away, so nothing else needs to run."""
        active = self._plan.active if self._plan else []
        warm = [p for p in active if int(p.warmup_frames) > 0]
        if not warm or not all(p.warmup_alone for p in warm):
            return list(active)
        keep = set(id(p) for p in warm)
        changed = True
        while changed:
            changed = False
            for i, p in enumerate(active):
                if id(p) not in keep:
                    continue
                for r in p.reads:
                    base = _base(r) if r.endswith(PREV) else r
                    for j, q in enumerate(active):
                        if id(q) in keep or base not in q.writes:
                            continue
                        if r.endswith(PREV) or j < i:
                            keep.add(id(q))
                            changed = True
        return [p for p in active if id(p) in keep]

    def converged(self, rc) -> bool | None:
        """True when every active pass that measures convergence says so (None: nobody measures)."""
        votes = [p.converged(rc) for p in self._plan.active] if self._plan else []
        votes = [v for v in votes if v is not None]
        return all(votes) if votes else None

    # ------------------------------------------------------------------ running
    def _decl(self, rc: RenderContext, name: str) -> Res | None:
        return self.declaration(name) or rc.specs.get(name, (None,))[0]

    def _barrier_before(self, rc: RenderContext, p: Pass) -> int:
        """Bits to issue before ``p`` so that every access it makes comes after the incoherent
        writes it depends on: for each resource, the bits that the way it was last written
        (the record in ``rc.sync``) and the way ``p`` reads or writes it call for."""
        bits, why = 0, []
        for r in tuple(p.reads) + tuple(p.optional_reads) + tuple(p.external):
            st = rc.sync.get(r)
            if r not in rc.resources or st is None:
                continue
            is_buf = rc.is_buffer(r)
            need = 0
            for a in p.read_accesses(r, self._decl(rc, r)):
                need |= required_bits(st[1], a, is_buf)
            if need & ~st[2]:
                bits |= need & ~st[2]
                why.append(r)
        for w in p.writes:
            st = rc.sync.get(w)
            if st is None:
                continue  # first write of a fresh resource
            is_buf = rc.is_buffer(w)
            need = always = 0
            for a in p.write_accesses(w, self._decl(rc, w)):
                need |= required_bits(st[1], a, is_buf)
                if a in INCOHERENT_WRITES:  # after earlier writes or reads of the resource (WAW, WAR)
                    always |= SHADER_STORAGE_BARRIER_BIT if is_buf else SHADER_IMAGE_ACCESS_BARRIER_BIT
            need = (need & ~st[2]) | always
            if need:
                bits |= need
                why.append(w)
        if bits:
            rc.ctx.memory_barrier(bits)
            rc.barriers_issued(bits)
            self.barrier_log.append({"before": p.name, "resources": sorted(set(why)), "bits": bits,
                                     "names": barrier_names(bits)})
        return bits

    def _after(self, rc: RenderContext, p: Pass):
        for w in p.writes:
            rc.record_write([w], p.access(w, self._decl(rc, w)), p.name)

    def _validate(self, rc: RenderContext, p: Pass):
        for w in p.writes:
            d = self.declaration(w) or rc.specs.get(w, (None,))[0]
            check = d.check if d is not None else "finite"
            obj = rc.resources.get(w)
            if check == "none" or obj is None:
                continue
            kind = d.kind if d is not None else TEX2D
            if kind in (HOST, DEPTH):
                continue
            rc.barrier_external([w])
            if kind == BUFFER:
                if d is None or d.dtype not in ("f4",):
                    continue
                arr = np.frombuffer(obj.read(), np.float32)
                where = lambda i: f"element {i}"  # noqa: E731
            else:
                dt = _NP_DT.get(getattr(obj, "dtype", "f4"), np.float32)
                if dt not in (np.float16, np.float32):
                    continue
                arr = np.frombuffer(obj.read(), dt).astype(np.float32)
                size = tuple(obj.size)
                comps = obj.components

                def where(i, size=size, comps=comps):
                    texel = i // comps
                    coords = np.unravel_index(texel, tuple(reversed(size)))
                    return f"texel {tuple(int(c) for c in reversed(coords))} channel {i % comps}"
            bad = ~np.isfinite(arr)
            what = "NaN/Inf"
            if not bad.any() and check == "radiance":
                bad = arr < -1e-6
                what = "a negative value"
            if bad.any():
                i = int(np.argmax(bad))
                msg = (f"GI_PREVIEW_VALIDATE: pass '{p.name}' wrote {what} ({arr[i]!r}) into '{w}' at "
                       f"{where(i)}")
                self.validation_log.append(msg)
                raise ValidationError(msg)

    def execute(self, rc: RenderContext, frame: FrameState, *, timers=True) -> dict[str, float]:
        """Run the planned passes in order with barriers; returns GPU ms per pass. ``timers``:
        True times each pass with a blocking GPU query, False with the CPU clock, a
        ``frame_sync.FrameTimers`` with queries read later (the returned dict is then empty:
        the results arrive in the FrameTimers)."""
        if self._plan is None:
            raise RuntimeError("FrameGraph.execute before plan()")
        self.allocate(rc)
        rc.frame = frame
        active = self.warmup_passes() if frame.warmup else self._plan.active
        for p in active:  # history: last frame's writes become @prev
            for h in p.history:
                rc.swap_history(h)
        self.barrier_log = []
        validate = validate_enabled()
        check = None
        if sync_check.enabled():
            sync_check.install()
            check = sync_check.VALIDATOR
        times: dict[str, float] = {}
        try:
            self._run(rc, active, frame, timers, validate, check, times)
        finally:
            if check is not None and check.pass_ is not None:
                check.end()
        if check is not None:
            found = check.take()
            if found:
                self.sync_log.extend(found)
                raise sync_check.SyncError("\n".join(found))
        return times

    def _run(self, rc, active, frame, timers, validate, check, times):
        for p in active:
            if self.derive_barriers:
                self._barrier_before(rc, p)
            if check is not None:
                check.begin(rc, p, self)
            if timers is not None and timers is not False and timers is not True:
                # a frame_sync.FrameTimers: GPU timer queries read a frame or two later
                timers.begin(p.name)
                try:
                    p.execute(rc, frame)
                finally:
                    timers.end()
            elif timers:
                q = rc.ctx.query(time=True)
                t0 = time.perf_counter()
                with q:
                    p.execute(rc, frame)
                ns = q.elapsed  # blocks until the GPU work is done
                # moderngl reads GL_TIME_ELAPSED as 32 bits (clamped at 2^32-1 ns = 4295 ms):
                # past that, the wall time up to the result (an upper bound of the GPU time)
                times[p.name] = ((time.perf_counter() - t0) * 1e3 if ns >= 0xFFFFFFFF
                                 else (ns / 1e6 if ns else 0.0))
            else:
                t0 = time.perf_counter()
                p.execute(rc, frame)
                times[p.name] = (time.perf_counter() - t0) * 1e3
            if check is not None:
                check.end()
            self._after(rc, p)
            if p.history:
                p.history_valid = True
            if validate:
                self._validate(rc, p)

    def get_properties(self) -> dict:
        return {p.name: p.get_properties() for p in self.passes}

    def set_properties(self, props: dict):
        for name, values in props.items():
            try:
                self.find(name).set_properties(values)
            except KeyError:
                log.warning("graph: unknown pass %r in properties", name)

    def release(self):
        for p in self.passes:
            p.release()
