"""A Cycles reference rendered in a child process, so the UI never waits and Esc stops it.

A Cycles render is one blocking call that Python cannot interrupt. For *Compare with
Cycles* from the UI, :func:`launch` saves a copy of the current .blend
(``wm.save_as_mainfile(copy=True)``: the user's file path and unsaved-changes state are
untouched) into a temporary folder and renders the reference there, in a child process:

* with Blender itself (``bpy.app.binary_path``): ``blender -b copy.blend --factory-startup
  -P reference_worker.py -- ARGS``;
* with the PyPI ``bpy`` module (no binary): ``python reference_worker.py ARGS``, the child
  opening the copy itself.

The child imports this add-on from its folder, calls :func:`reference.get_reference` with
the same fair settings, fingerprint and cache folder as the parent would (so the result
is also stored in the reference cache), and writes ``reference.exr`` plus
``reference.json`` (:meth:`reference.Reference.info`). It prints ``GI_PROGRESS done total``
lines (Cycles' samples, from the ``render_stats`` handler) that :class:`ReferenceProcess`
turns into a fraction. :meth:`ReferenceProcess.kill` ends the child at once (the render
with it) and removes the temporary folder.

:func:`cached_reference` looks a reference up in the cache without rendering (the parent
checks it before starting a child).
"""
from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import time

_PROGRESS = re.compile(r"GI_PROGRESS (\d+) (\d+)")
_SAMPLE = re.compile(r"Sample (\d+)/(\d+)")


# ------------------------------------------------------------------ parent side (bpy)
def cached_reference(scene, kind: str, spp: int, *, seed: int | None = None, width: int, height: int,
                     fingerprint: str, cache_dir: str | None = None, ao_distance: float | None = None):
    """The cached :class:`reference.Reference` for these settings, or None (never renders).
    The key is the one :func:`reference.get_reference` uses."""
    import bpy

    from ..compare import cache as _cache
    from . import reference as R

    seed = R.DEFAULT_SEED if seed is None else seed
    ao_distance = R.DEFAULT_AO_DISTANCE if ao_distance is None else ao_distance
    bounces = dict(R.KIND_BOUNCES[kind])
    extra = {"ao_distance": float(ao_distance)} if kind == "ao" else {}
    key = _cache.reference_key(fingerprint, kind, spp, bounces, (width, height), seed, bpy.app.version, **extra)
    hit = _cache.ReferenceCache(cache_dir or R.default_cache_dir()).get(key)
    if hit is None or hit[0].shape[:2] != (height, width):
        return None
    image, meta = hit
    return R.Reference(image=image, time_ms=float(meta.get("time_ms", 0.0)), spp=int(spp), kind=kind, seed=seed,
                       bounces=bounces, width=width, height=height, cached=True, key=key, fingerprint=fingerprint,
                       blender_version=".".join(str(v) for v in bpy.app.version), meta=meta)


class ReferenceProcess:
    """A reference render in a child process (see the module docstring). Poll it from a
    timer: :attr:`progress` (0..1), :meth:`poll` (None while running, then the Reference;
    raises RuntimeError with the child's last output when it failed), :meth:`kill`."""

    def __init__(self, proc: subprocess.Popen, tmpdir: str, args: dict):
        self.proc = proc
        self.tmpdir = tmpdir
        self.args = args
        self.progress = 0.0
        self.lines: list[str] = []
        self.started = time.perf_counter()
        self._reader = threading.Thread(target=self._read, name="gi_preview-ref-reader", daemon=True)
        self._reader.start()

    def _read(self):
        for line in self.proc.stdout:
            line = line.rstrip()
            m = _PROGRESS.search(line)
            if m:
                done, total = int(m.group(1)), max(int(m.group(2)), 1)
                self.progress = min(1.0, done / total)
                continue
            self.lines.append(line)
            del self.lines[:-40]

    @property
    def running(self) -> bool:
        return self.proc.poll() is None

    def poll(self):
        if self.proc.poll() is None:
            return None
        self._reader.join(timeout=2)
        try:
            if self.proc.returncode != 0:
                tail = "\n".join(self.lines[-12:])
                raise RuntimeError(f"the Cycles reference process failed (exit code {self.proc.returncode}):\n{tail}")
            return self._load()
        finally:
            self.cleanup()

    def _load(self):
        import bpy

        from ..compare import imageio
        from . import reference as R

        R.ensure_oiio()
        with open(os.path.join(self.tmpdir, "reference.json")) as f:
            info = json.load(f)
        image = imageio.read_exr(os.path.join(self.tmpdir, "reference.exr"))
        return R.Reference(image=image, time_ms=float(info["time_ms"]), spp=int(info["spp"]), kind=info["kind"],
                           seed=int(info["seed"]), bounces=dict(info["bounces"]), width=int(info["width"]),
                           height=int(info["height"]), cached=False, key=info["key"],
                           fingerprint=info["fingerprint"],
                           blender_version=info.get("blender_version") or ".".join(map(str, bpy.app.version)),
                           meta={"created": info.get("created"), "ao_distance": info.get("ao_distance"),
                                 "process_ms": (time.perf_counter() - self.started) * 1e3})

    def kill(self) -> float:
        """End the child (and its Cycles render) now; returns the milliseconds it took until
        the process was gone. The temporary folder is removed."""
        t0 = time.perf_counter()
        if self.proc.poll() is None:
            self.proc.kill()
            try:
                self.proc.wait(timeout=5)
            except subprocess.TimeoutExpired:  # pragma: no cover - SIGKILL does not wait for the child
                pass
        ms = (time.perf_counter() - t0) * 1e3
        self.cleanup()
        return ms

    def cleanup(self):
        if self.proc.stdout is not None:
            try:
                self.proc.stdout.close()
            except OSError:
                pass
        shutil.rmtree(self.tmpdir, ignore_errors=True)


def save_copy(path: str) -> None:
    """Save the current file's data into ``path`` without changing the user's file path or
    its unsaved-changes flag (``copy=True``); checked, since a changed title would be a
    visible side effect of comparing."""
    import bpy

    filepath, dirty = bpy.data.filepath, bpy.data.is_dirty
    bpy.ops.wm.save_as_mainfile(filepath=path, copy=True, check_existing=False)
    if bpy.data.filepath != filepath:
        raise RuntimeError(f"saving the reference copy changed the file path to {bpy.data.filepath!r}")
    if bpy.data.is_dirty != dirty:
        raise RuntimeError("saving the reference copy changed the file's unsaved-changes state")


def launch(scene, kind: str, spp: int, *, width: int, height: int, fingerprint: str, seed: int | None = None,
           cache_dir: str | None = None, ao_distance: float | None = None) -> ReferenceProcess:
    """Start rendering a Cycles reference of ``scene`` in a child process (returns at once)."""
    import bpy

    from . import reference as R

    tmpdir = tempfile.mkdtemp(prefix="gi_preview_refjob_")
    blend = os.path.join(tmpdir, "scene.blend")
    try:
        save_copy(blend)
    except Exception:
        shutil.rmtree(tmpdir, ignore_errors=True)
        raise
    args = {"blend": blend, "scene": scene.name, "kind": kind, "spp": int(spp), "width": int(width),
            "height": int(height), "fingerprint": fingerprint,
            "seed": R.DEFAULT_SEED if seed is None else int(seed),
            "cache_dir": cache_dir or R.default_cache_dir(),
            "ao_distance": R.DEFAULT_AO_DISTANCE if ao_distance is None else float(ao_distance),
            "out": tmpdir, "package_dir": os.path.dirname(os.path.dirname(os.path.abspath(__file__)))}
    worker = os.path.abspath(__file__)
    payload = json.dumps(args)
    binary = getattr(bpy.app, "binary_path", "") or ""
    if binary and os.path.basename(binary).lower().startswith("blender"):
        cmd = [binary, "-b", blend, "--factory-startup", "--python-exit-code", "1", "-P", worker, "--", payload]
    else:
        cmd = [sys.executable, worker, payload]
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                            text=True, bufsize=1, env=env)
    return ReferenceProcess(proc, tmpdir, args)


# ------------------------------------------------------------------ child side
def _child_main(payload: str) -> int:
    args = json.loads(payload)
    pkg_dir = args["package_dir"]
    sys.path.insert(0, os.path.dirname(pkg_dir))
    import importlib

    import bpy

    if os.path.abspath(bpy.data.filepath or "") != os.path.abspath(args["blend"]):
        bpy.ops.wm.open_mainfile(filepath=args["blend"], load_ui=False)
    pkg = importlib.import_module(os.path.basename(pkg_dir))
    R = importlib.import_module(pkg.__name__ + ".blender.reference")
    imageio = importlib.import_module(pkg.__name__ + ".compare.imageio")

    def stats(*a):
        text = " ".join(str(x) for x in a if isinstance(x, str))
        m = _SAMPLE.search(text)
        if m:
            print(f"GI_PROGRESS {m.group(1)} {m.group(2)}", flush=True)

    bpy.app.handlers.render_stats.append(stats)
    scene = bpy.data.scenes[args["scene"]]
    print(f"GI_PROGRESS 0 {args['spp']}", flush=True)
    ref = R.get_reference(scene, args["kind"], args["spp"], seed=args["seed"], width=args["width"],
                          height=args["height"], fingerprint=args["fingerprint"], cache_dir=args["cache_dir"],
                          use_cache=False, ao_distance=args["ao_distance"])
    imageio.write_exr(os.path.join(args["out"], "reference.exr"), ref.image)
    info = ref.info()
    info["blender_version"] = ref.blender_version
    with open(os.path.join(args["out"], "reference.json"), "w") as f:
        json.dump(info, f)
    print(f"GI_PROGRESS {args['spp']} {args['spp']}", flush=True)
    return 0


if __name__ == "__main__":
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    sys.exit(_child_main(argv[0]))
