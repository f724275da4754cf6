"""The one OpenGL context of GI Preview, owned by one thread.

An EGL context is usable only on the thread that created it, and Blender calls the engine
from several threads (the render job thread for F12, the main thread for the viewport and
for ``bpy.ops.render.render()`` in background mode). So GI Preview makes exactly one
moderngl context, on a daemon thread of its own, and every GL call goes through
:meth:`GLThread.submit` / :meth:`GLThread.call`. Blender's own GL context is never made
current by us, and ours is never made current on Blender's threads.

Set ``GI_PREVIEW_GL_REQUIRE`` (e.g. ``460``) to demand a newer OpenGL than 4.3, and
``GI_PREVIEW_GL_BACKEND`` to force a moderngl backend (``egl`` by default on Linux when
there is no display).
"""
from __future__ import annotations

import inspect
import itertools
import os
import queue
import sys
import threading
from concurrent.futures import Future

REQUIRED_GL = 430
MESA_HINT = ("On Debian/Ubuntu install Mesa's EGL/GL packages: "
             "`apt-get install libegl1 libgl1-mesa-dri libegl-mesa0`.")


class GLUnavailableError(RuntimeError):
    """OpenGL 4.3 (with compute shaders) cannot be had on this machine."""


def required_version() -> int:
    try:
        return int(os.environ.get("GI_PREVIEW_GL_REQUIRE", REQUIRED_GL))
    except ValueError:
        return REQUIRED_GL


def create_context():
    """Create a standalone moderngl context with OpenGL >= 4.3, or raise GLUnavailableError."""
    try:
        import moderngl
    except ImportError as exc:  # pragma: no cover - depends on the installation
        raise GLUnavailableError(
            f"GI Preview needs the Python package 'moderngl' (OpenGL 4.3 compute and raster), "
            f"which could not be imported: {exc}. Install the extension zip (it bundles the wheel) "
            f"or `pip install moderngl`.") from exc
    need = required_version()
    backend = os.environ.get("GI_PREVIEW_GL_BACKEND")
    backends = [backend] if backend else (["egl", None] if sys.platform.startswith("linux") else [None])
    errors = []
    for be in backends:
        try:
            kwargs = {"require": need}
            if be:
                kwargs["backend"] = be
            ctx = moderngl.create_standalone_context(**kwargs)
        except Exception as exc:  # moderngl raises plain Exception for missing libraries
            errors.append(f"{be or 'default'}: {exc}")
            continue
        if ctx.version_code < need:
            got = ctx.version_code
            ctx.release()
            errors.append(f"{be or 'default'}: OpenGL {got // 100}.{(got % 100) // 10} < required")
            continue
        return ctx
    raise GLUnavailableError(
        f"GI Preview needs OpenGL {need // 100}.{(need % 100) // 10} with compute shaders and could "
        f"not create such a context ({'; '.join(errors)}). {MESA_HINT} On a machine with a GPU, "
        f"update the graphics driver.")


class _Job:
    """One submitted callable. A job whose callable returns a generator is *stepped*: the GL
    thread runs it to its next ``yield`` (one frame), then serves other jobs before the next
    step. Jobs with the same ``key`` (a render session) run one after the other, in
    submission order, because they share that session's state."""

    __slots__ = ("fn", "args", "kwargs", "fut", "priority", "key", "seq", "order", "gen", "steps")

    def __init__(self, fn, args, kwargs, fut, priority, key, seq):
        self.fn, self.args, self.kwargs, self.fut = fn, args, kwargs, fut
        self.priority, self.key, self.seq, self.order = int(priority), key, seq, seq
        self.gen = None
        self.steps = 0


# Priorities (lower runs first): a viewport frame is served before the next step of a long job.
PRIORITY_INTERACTIVE = 0
PRIORITY_NORMAL = 10
PRIORITY_BACKGROUND = 20


class GLThread:
    """A daemon thread that owns the GL context and runs submitted jobs.

    Scheduling: a plain callable runs to completion when picked. A callable that returns a
    generator (``Session.render_steps``: one ``yield`` per frame) is stepped cooperatively:
    after each step the thread takes any newly queued jobs and picks the next step by
    priority (``PRIORITY_INTERACTIVE`` for viewport frames, ``PRIORITY_NORMAL`` for F12 and
    the comparison, ``PRIORITY_BACKGROUND`` for sweeps), round robin within one priority.
    So a viewport frame submitted while an F12 accumulation of thousands of frames runs
    waits for at most the F12 frame in progress. Jobs sharing a ``key`` (a session) are
    serialised in submission order, so interleaving never mixes one session's state."""

    def __init__(self):
        self._queue: queue.Queue = queue.Queue()
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self.ctx = None
        self.info: dict = {}
        self._seq = itertools.count()
        self._steps = 0  # generator steps run so far (all jobs; for tests and benchmarks)
        self._final = None  # run on the thread when it stops (see stop())
        self._thread = threading.Thread(target=self._run, name="gi_preview-gl", daemon=True)
        self._thread.start()
        self._ready.wait()
        if self._error is not None:
            raise self._error

    # ---------------------------------------------------------------- thread body
    def _run(self):
        try:
            self.ctx = create_context()
            self.info = {k: self.ctx.info.get(k) for k in ("GL_RENDERER", "GL_VENDOR", "GL_VERSION")}
        except BaseException as exc:  # reported to the creating thread
            self._error = exc
            self._ready.set()
            return
        self._ready.set()
        pending: list[_Job] = []  # submitted, not finished (started generators included)
        stopping = False
        while True:
            # take what was queued: block only when there is nothing else to do
            try:
                item = self._queue.get(block=not pending)
            except queue.Empty:
                item = False
            while item is not False:
                if item is None:
                    stopping = True
                else:
                    pending.append(item)
                try:
                    item = self._queue.get_nowait()
                except queue.Empty:
                    item = False
            if stopping:
                # unfinished jobs end first (their generators closed), then the final clean-up
                for job in pending:
                    self._close(job, GLUnavailableError("the GI Preview GL thread has stopped"))
                if self._final is not None:
                    try:
                        self._final()
                    except Exception:  # noqa: BLE001 - best effort at shutdown
                        pass
                break
            job = self._pick(pending)
            if job is None:
                continue
            done = self._step(job)
            if done:
                pending.remove(job)
            else:
                # round robin within a priority: the job goes behind its peers
                job.seq = next(self._seq)
        try:
            self.ctx.release()
        except Exception:
            pass

    @staticmethod
    def _pick(pending: list) -> "_Job | None":
        """The runnable job to step next: lowest priority value, then least recently run;
        a job whose key has an earlier unfinished job waits for it."""
        head: dict = {}
        for job in pending:
            if job.key is not None and (job.key not in head or job.order < head[job.key].order):
                head[job.key] = job
        runnable = [j for j in pending if j.key is None or head[j.key] is j]
        return min(runnable, key=lambda j: (j.priority, j.seq)) if runnable else None

    def _step(self, job: _Job) -> bool:
        """Run one step of ``job``; True when it finished (result or exception set)."""
        if job.gen is None:
            if not job.fut.set_running_or_notify_cancel():
                return True
            try:
                out = job.fn(*job.args, **job.kwargs)
            except BaseException as exc:
                job.fut.set_exception(exc)
                return True
            if not inspect.isgenerator(out):
                job.fut.set_result(out)
                return True
            job.gen = out
        try:
            next(job.gen)
            job.steps += 1
            self._steps += 1
            return False
        except StopIteration as stop:
            job.fut.set_result(stop.value)
        except BaseException as exc:
            job.fut.set_exception(exc)
        return True

    @staticmethod
    def _close(job: _Job, exc: BaseException):
        if job.gen is not None:
            try:
                job.gen.close()
            except Exception:
                pass
        if not job.fut.done():
            if job.gen is None and not job.fut.set_running_or_notify_cancel():
                return
            job.fut.set_exception(exc)

    # ---------------------------------------------------------------- API
    @property
    def on_thread(self) -> bool:
        return threading.current_thread() is self._thread

    def submit(self, fn, *args, **kwargs) -> Future:
        """Queue ``fn(*args, **kwargs)`` on the GL thread; returns a Future (normal priority,
        no key). A generator returned by ``fn`` is stepped cooperatively (see the class)."""
        return self.submit_job(fn, args, kwargs)

    def submit_job(self, fn, args=(), kwargs=None, *, priority: int = PRIORITY_NORMAL, key=None) -> Future:
        """Queue ``fn(*args, **kwargs)`` with a scheduling ``priority`` (lower first) and an
        optional serialisation ``key``. When ``fn`` returns a generator, the Future's result is
        the generator's return value. Called on the GL thread itself, the job runs at once
        (to the end: a nested job cannot yield to the scheduler)."""
        fut: Future = Future()
        kwargs = kwargs or {}
        if self.on_thread:
            try:
                out = fn(*args, **kwargs)
                if inspect.isgenerator(out):
                    while True:
                        try:
                            next(out)
                        except StopIteration as stop:
                            out = stop.value
                            break
                fut.set_result(out)
            except BaseException as exc:
                fut.set_exception(exc)
            return fut
        if not self._thread.is_alive():
            raise GLUnavailableError("the GI Preview GL thread has stopped")
        self._queue.put(_Job(fn, args, kwargs, fut, priority, key, next(self._seq)))
        return fut

    @property
    def steps_run(self) -> int:
        """Generator steps (frames) run so far by all jobs."""
        return self._steps

    def call(self, fn, *args, **kwargs):
        """Run ``fn`` on the GL thread and return its result (exceptions are re-raised here)."""
        return self.submit(fn, *args, **kwargs).result()

    def stop(self, final=None):
        """Stop the thread: unfinished jobs fail with GLUnavailableError (a stepped render
        stops between two frames), then ``final()`` runs on the thread (freeing sessions)
        before the context is released."""
        if self._thread.is_alive():
            self._final = final
            self._queue.put(None)
            self._thread.join(timeout=10)


_lock = threading.Lock()
_gl: GLThread | None = None


def get_gl() -> GLThread:
    """The process-wide GL thread, created on first use (raises GLUnavailableError)."""
    global _gl
    with _lock:
        if _gl is None or not _gl._thread.is_alive():
            _gl = GLThread()
        return _gl


def shutdown():
    """Stop the GL thread and free every GL resource (add-on unregister, tests)."""
    global _gl
    with _lock:
        if _gl is not None:
            from . import session  # local import: session state lives on the GL thread

            _gl.stop(final=session.release_all)
            _gl = None
