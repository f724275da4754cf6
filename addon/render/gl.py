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


class GLThread:
    """A daemon thread that owns the GL context and runs submitted callables in order."""

    def __init__(self):
        self._queue: queue.Queue = queue.Queue()
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self.ctx = None
        self.info: dict = {}
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
        while True:
            item = self._queue.get()
            if item is None:
                break
            fn, args, kwargs, fut = item
            if not fut.set_running_or_notify_cancel():
                continue
            try:
                fut.set_result(fn(*args, **kwargs))
            except BaseException as exc:
                fut.set_exception(exc)
        try:
            self.ctx.release()
        except Exception:
            pass

    # ---------------------------------------------------------------- API
    @property
    def on_thread(self) -> bool:
        return threading.current_thread() is self._thread

    def submit(self, fn, *args, **kwargs) -> Future:
        """Queue ``fn(*args, **kwargs)`` on the GL thread; returns a Future."""
        fut: Future = Future()
        if self.on_thread:
            try:
                fut.set_result(fn(*args, **kwargs))
            except BaseException as exc:
                fut.set_exception(exc)
            return fut
        if not self._thread.is_alive():
            raise GLUnavailableError("the GI Preview GL thread has stopped")
        self._queue.put((fn, args, kwargs, fut))
        return fut

    def call(self, fn, *args, **kwargs):
        """Run ``fn`` on the GL thread and return its result (exceptions are re-raised here)."""
        return self.submit(fn, *args, **kwargs).result()

    def stop(self):
        if self._thread.is_alive():
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

            try:
                _gl.call(session.release_all)
            except Exception:
                pass
            _gl.stop()
            _gl = None
