"""Frame pacing without ``glFinish``: one fence per frame, at most two frames in flight, and
GPU timer queries read when their results are ready.

The frame loop (``Session.render_steps``) brackets every frame with :meth:`FrameSync.begin_frame`
and :meth:`FrameSync.end_frame`. ``end_frame`` puts a fence (``glFenceSync``) behind the
frame's commands and flushes them, so the GPU starts on frame N while the CPU records frame
N+1; ``begin_frame`` of frame N waits (``glClientWaitSync``) for frame N-2, so at most two
frames are in flight and the CPU never runs more than one frame ahead. A read-back of a
frame's result (the render result, the viewport image) first waits for that frame's own
fence (:meth:`FrameSync.wait`).

Per-pass GPU times come from ``GL_TIME_ELAPSED`` queries taken from a pool, one pair of
begin/end per pass; their 64-bit results are read once ``GL_QUERY_RESULT_AVAILABLE`` says so,
normally a frame or two later, so timing never stalls the pipeline. A frame's time is the
interval between its completion and the previous frame's (or its own start, when the
previous frame had completed before it started): under pipelining that is what a frame
costs in throughput.

The GL entry points are resolved with ctypes from the process's GL loader
(``eglGetProcAddress``, else ``glXGetProcAddressARB``), on the GL thread whose context is
current. Where they cannot be resolved (or ``GI_PREVIEW_FRAME_SYNC=finish``), every frame
ends with ``glFinish`` and the timer queries are read at once, as a blocking fallback.
"""
from __future__ import annotations

import collections
import ctypes
import ctypes.util
import logging
import os
import time

log = logging.getLogger(__name__)

GL_SYNC_GPU_COMMANDS_COMPLETE = 0x9117
GL_SYNC_FLUSH_COMMANDS_BIT = 0x00000001
GL_ALREADY_SIGNALED = 0x911A
GL_TIMEOUT_EXPIRED = 0x911B
GL_CONDITION_SATISFIED = 0x911C
GL_WAIT_FAILED = 0x911D
GL_TIME_ELAPSED = 0x88BF
GL_QUERY_RESULT = 0x8866
GL_QUERY_RESULT_AVAILABLE = 0x8867

MAX_FRAMES_IN_FLIGHT = 2
WAIT_SLICE_NS = 100_000_000  # one glClientWaitSync call waits at most this long (then again)

_GLenum, _GLbitfield, _GLuint, _GLint, _GLsizei = (ctypes.c_uint, ctypes.c_uint, ctypes.c_uint, ctypes.c_int,
                                                   ctypes.c_int)
_GLuint64 = ctypes.c_uint64
_GLsync = ctypes.c_void_p

# name -> (return type, argument types)
_SIGNATURES = {
    "glFenceSync": (_GLsync, (_GLenum, _GLbitfield)),
    "glClientWaitSync": (_GLenum, (_GLsync, _GLbitfield, _GLuint64)),
    "glDeleteSync": (None, (_GLsync,)),
    "glFlush": (None, ()),
    "glFinish": (None, ()),
    "glGenQueries": (None, (_GLsizei, ctypes.POINTER(_GLuint))),
    "glDeleteQueries": (None, (_GLsizei, ctypes.POINTER(_GLuint))),
    "glBeginQuery": (None, (_GLenum, _GLuint)),
    "glEndQuery": (None, (_GLenum,)),
    "glGetQueryObjectiv": (None, (_GLuint, _GLenum, ctypes.POINTER(_GLint))),
    "glGetQueryObjectui64v": (None, (_GLuint, _GLenum, ctypes.POINTER(_GLuint64))),
}


class GLEntryPoints:
    """The raw GL functions frame pacing needs (module docstring), as ctypes callables."""

    def __init__(self, fns: dict):
        for name, fn in fns.items():
            setattr(self, name, fn)


def _loaders():
    """``(library, proc-address function name)`` pairs to try, the context's backend first."""
    egl = ("libEGL.so.1", "eglGetProcAddress")
    glx = ("libGL.so.1", "glXGetProcAddressARB")
    backend = (os.environ.get("GI_PREVIEW_GL_BACKEND") or "egl").lower()
    return [egl, glx] if backend == "egl" else [glx, egl]


def resolve_entry_points() -> GLEntryPoints | None:
    """The entry points through the process's GL loader, or None (call on the GL thread)."""
    if os.environ.get("GI_PREVIEW_FRAME_SYNC", "").lower() == "finish":
        return None
    for lib_name, getter_name in _loaders():
        try:
            lib = ctypes.CDLL(lib_name)
            getter = getattr(lib, getter_name)
        except (OSError, AttributeError):
            continue
        getter.restype = ctypes.c_void_p
        getter.argtypes = [ctypes.c_char_p]
        fns = {}
        for name, (res, args) in _SIGNATURES.items():
            addr = getter(name.encode())
            if not addr:
                break
            fns[name] = ctypes.CFUNCTYPE(res, *args)(addr)
        if len(fns) != len(_SIGNATURES):
            continue
        gl = GLEntryPoints(fns)
        if _works(gl):
            return gl
    return None


def _works(gl: GLEntryPoints) -> bool:
    """A fence made and waited on through these pointers behaves as GL says (a loader of
    another API than the current context's would hand out pointers that do nothing)."""
    try:
        s = gl.glFenceSync(GL_SYNC_GPU_COMMANDS_COMPLETE, 0)
        if not s:
            return False
        r = gl.glClientWaitSync(s, GL_SYNC_FLUSH_COMMANDS_BIT, 10_000_000_000)
        gl.glDeleteSync(s)
        return r in (GL_ALREADY_SIGNALED, GL_CONDITION_SATISFIED)
    except Exception:  # noqa: BLE001 - any failure means: use the fallback
        return False


class QueryPool:
    """GL query objects reused across frames (never more than the frames in flight need)."""

    def __init__(self, gl: GLEntryPoints):
        self.gl = gl
        self.free: list[int] = []
        self.made = 0

    def acquire(self) -> int:
        if not self.free:
            ids = (_GLuint * 16)()
            self.gl.glGenQueries(16, ids)
            self.free.extend(int(i) for i in ids)
            self.made += 16
        return self.free.pop()

    def give_back(self, qid: int):
        self.free.append(qid)

    def release(self):
        if self.free:
            ids = (_GLuint * len(self.free))(*self.free)
            self.gl.glDeleteQueries(len(self.free), ids)
        self.free = []


class FrameTimers:
    """One frame's pass timers: ``begin(name)`` / ``end()`` around each pass (not nested).
    With entry points, GL_TIME_ELAPSED queries read later (:meth:`collect`); without, the
    blocking moderngl query of the fallback (results at once)."""

    def __init__(self, ctx, pool: QueryPool | None):
        self.ctx, self.pool = ctx, pool
        self.entries: list = []  # (pass name, query id)
        self.results: dict[str, float] | None = None if pool is not None else {}
        self._q = self._t0 = None

    def begin(self, name: str):
        if self.pool is not None:
            qid = self.pool.acquire()
            self.pool.gl.glBeginQuery(GL_TIME_ELAPSED, qid)
            self.entries.append((name, qid))
        else:
            self._q = self.ctx.query(time=True)
            self._t0 = time.perf_counter()
            self._q.__enter__()
            self.entries.append((name, None))

    def end(self):
        if self.pool is not None:
            self.pool.gl.glEndQuery(GL_TIME_ELAPSED)
            return
        self._q.__exit__(None, None, None)
        ns = self._q.elapsed  # blocks until the pass's GPU work is done
        name = self.entries[-1][0]
        # moderngl reads the result as 32 bits (clamped at 2^32-1 ns): past that, the wall time
        self.results[name] = ((time.perf_counter() - self._t0) * 1e3 if ns >= 0xFFFFFFFF
                              else (ns / 1e6 if ns else 0.0))
        self._q = None

    def collect(self) -> bool:
        """Read the results if every query has one (never blocks). True once read."""
        if self.results is not None:
            return True
        gl = self.pool.gl
        avail = _GLint(0)
        for _name, qid in self.entries:
            gl.glGetQueryObjectiv(qid, GL_QUERY_RESULT_AVAILABLE, ctypes.byref(avail))
            if not avail.value:
                return False
        out, ns = {}, _GLuint64(0)
        for name, qid in self.entries:
            gl.glGetQueryObjectui64v(qid, GL_QUERY_RESULT, ctypes.byref(ns))
            out[name] = out.get(name, 0.0) + ns.value / 1e6
            self.pool.give_back(qid)
        self.results = out
        return True

    def drop(self):
        """Give the queries back unread (the frame's results are not wanted)."""
        if self.pool is not None and self.results is None:
            for _name, qid in self.entries:
                self.pool.give_back(qid)
            self.results = {}


class Frame:
    """One frame of the loop: its fence, its timers and when it started and completed."""

    __slots__ = ("serial", "fence", "timers", "t_begin", "t_end", "t_done", "excluded_ms")

    def __init__(self, serial: int, timers: FrameTimers):
        self.serial = serial
        self.fence = None
        self.timers = timers
        self.t_begin = time.perf_counter()
        self.t_end = None  # commands all submitted
        self.t_done = None  # seen complete
        self.excluded_ms = 0.0  # one-time work inside the frame (shader compiles, BVH builds)

    @property
    def done(self) -> bool:
        return self.t_done is not None


class FrameSync:
    """Fences, the frames in flight and the timer pool of one GL context (module docstring)."""

    def __init__(self, ctx, max_in_flight: int = MAX_FRAMES_IN_FLIGHT, entry_points="auto"):
        self.ctx = ctx
        self.gl = resolve_entry_points() if entry_points == "auto" else entry_points
        self.max_in_flight = max(1, int(max_in_flight))
        self.pool = QueryPool(self.gl) if self.gl is not None else None
        self.in_flight: collections.deque = collections.deque()
        self.max_in_flight_seen = 0
        self.finish_calls = 0  # glFinish issued by the fallback
        self.waits = 0  # blocking waits on a fence
        self._serial = 0
        if self.gl is None:
            log.info("GI Preview: GL fence entry points not available; frames end with glFinish")

    @property
    def fallback(self) -> bool:
        return self.gl is None

    # ---------------------------------------------------------------- frame loop
    def begin_frame(self) -> Frame:
        """Start frame N: wait for frame N-2 (at most ``max_in_flight`` frames in flight)."""
        self.poll()
        while len(self.in_flight) >= self.max_in_flight:
            self.wait(self.in_flight[0])
        self._serial += 1
        return Frame(self._serial, FrameTimers(self.ctx, self.pool))

    def end_frame(self, frame: Frame):
        """Every command of ``frame`` is recorded: fence it and hand it to the GPU."""
        frame.t_end = time.perf_counter()
        if self.gl is None:
            self.ctx.finish()
            self.finish_calls += 1
            frame.t_done = time.perf_counter()
            return
        frame.fence = self.gl.glFenceSync(GL_SYNC_GPU_COMMANDS_COMPLETE, 0)
        self.gl.glFlush()
        self.in_flight.append(frame)
        self.max_in_flight_seen = max(self.max_in_flight_seen, len(self.in_flight))

    def poll(self):
        """Mark the frames whose fences have signalled as complete (never blocks)."""
        while self.in_flight:
            f = self.in_flight[0]
            if self._client_wait(f.fence, 0) == GL_TIMEOUT_EXPIRED:
                return
            self._complete(f)

    def wait(self, frame: Frame):
        """Block until ``frame`` has completed on the GPU (before reading back its result)."""
        if frame.done or frame.fence is None:
            return
        self.waits += 1
        while True:
            r = self._client_wait(frame.fence, WAIT_SLICE_NS)
            if r != GL_TIMEOUT_EXPIRED:
                break
        # fences signal in submission order: every older frame is complete too
        while self.in_flight:
            f = self.in_flight[0]
            self._complete(f)
            if f is frame:
                break

    def wait_all(self):
        if self.in_flight:
            self.wait(self.in_flight[-1])

    def _client_wait(self, fence, timeout_ns: int) -> int:
        r = self.gl.glClientWaitSync(fence, GL_SYNC_FLUSH_COMMANDS_BIT, int(timeout_ns))
        if r == GL_WAIT_FAILED:  # a lost fence: finish, so nothing waits forever
            self.ctx.finish()
            self.finish_calls += 1
            return GL_ALREADY_SIGNALED
        return r

    def _complete(self, f: Frame):
        f.t_done = time.perf_counter()
        if f.fence is not None:
            self.gl.glDeleteSync(f.fence)
            f.fence = None
        if self.in_flight and self.in_flight[0] is f:
            self.in_flight.popleft()

    def release(self):
        self.wait_all()
        if self.pool is not None:
            self.pool.release()


def frame_interval_ms(frames: list, previous: Frame | None = None) -> list[float]:
    """Each frame's completion-to-completion time (from its own start when the previous frame
    completed before it started), less its one-time work. ``frames`` are complete."""
    out = []
    prev = previous
    for f in frames:
        start = f.t_begin if prev is None or prev.t_done is None else max(prev.t_done, f.t_begin)
        out.append(max(0.0, (f.t_done - start) * 1e3 - f.excluded_ms))
        prev = f
    return out


_syncs: dict = {}


def for_context(ctx) -> FrameSync:
    """The FrameSync of ``ctx`` (one per context: the frames in flight are the context's,
    whichever session records them). GL thread only."""
    s = _syncs.get(id(ctx))
    if s is None or s.ctx is not ctx:
        s = FrameSync(ctx)
        _syncs[id(ctx)] = s
    return s


def release_all():
    for s in list(_syncs.values()):
        try:
            s.release()
        except Exception:  # noqa: BLE001 - best effort at shutdown
            pass
    _syncs.clear()
