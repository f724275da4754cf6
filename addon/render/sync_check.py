"""Synchronisation validation: what the passes actually do to GL objects, checked against
what they declare and against the barriers actually issued.

Enabled with ``GI_PREVIEW_VALIDATE=2`` (which also keeps the NaN/Inf checks of level 1),
``GI_PREVIEW_VALIDATE_SYNC=1`` (this check alone) or ``enable()``. While enabled, the moderngl
methods that access textures, buffers and framebuffers are wrapped so that every access is
seen: ``Texture.use`` (texture fetch), ``bind_to_image`` (image load / store),
``bind_to_storage_buffer`` / ``bind_to_uniform_block`` (storage / uniform),
``Framebuffer.use`` / ``clear`` (framebuffer writes of the attachments), ``write`` / ``clear``
(uploads), ``read`` (read-back), ``render_indirect`` (indirect commands) and every
``Context.memory_barrier``. An access is attributed to the pass the frame graph is running
(or to code outside the passes) and to the resource name the object has in a
``RenderContext.resources``; objects a pass keeps to itself are not checked.

Reported, each naming the pass and the resource:

* a pass that touches a resource it does not declare (reads, optional_reads, writes, external);
* a pass that writes a resource in a way its declaration does not say (a framebuffer draw into
  a resource of a ``kind="compute"`` pass, an image store it declares as a framebuffer write),
  or writes what it declares only as a read;
* an access after another pass's (or the graph's) incoherent write with no barrier covering
  that access type issued in between (barriers.required_bits).

Accesses inside one pass are not ordered against each other here: the pass orders its own
dispatches. Storage buffers count as written when the pass declares them written.
"""
from __future__ import annotations

import os
import weakref

from .barriers import (ALL_BARRIER_BITS, INCOHERENT_WRITES, READ_ACCESS_NAMES, WRITE_ACCESS_NAMES,
                       barrier_names, required_bits)

OUTSIDE = "<outside the passes>"


class SyncError(RuntimeError):
    """Synchronisation validation found undeclared use or a missing barrier."""


def enabled() -> bool:
    return (_forced or os.environ.get("GI_PREVIEW_VALIDATE", "").strip() == "2"
            or os.environ.get("GI_PREVIEW_VALIDATE_SYNC", "") not in ("", "0", "false", "False"))


_forced = False


def enable(on: bool = True):
    """Turn validation on or off for this process (the environment variable also turns it on)."""
    global _forced
    _forced = bool(on)
    if on:
        install()


class _State:
    __slots__ = ("writer", "access", "visible", "name", "obj")

    def __init__(self, writer, access, name, obj):
        # the object is held so that its id is not reused while the record exists
        self.writer, self.access, self.visible, self.name, self.obj = writer, access, 0, name, obj


class Validator:
    """Accesses of one process's GL objects; see the module docstring."""

    def __init__(self):
        self.contexts: "weakref.WeakSet" = weakref.WeakSet()
        self.state: dict[int, _State] = {}  # id(GL object) -> last write
        self.pass_ = None  # the running Pass, or None outside the passes
        self.rc = None
        # writes of the running pass: id -> [access, name, object, bits issued since]
        self.pending: dict[int, list] = {}
        self.graph = None
        # objects with no name: id -> (object, pass that last wrote it, its render context)
        self.unnamed: dict[int, tuple] = {}
        self.violations: list[str] = []
        self._seen: set = set()

    # ------------------------------------------------------------------ names
    def name_of(self, obj):
        rcs = [self.rc] if self.rc is not None else []
        rcs += [rc for rc in list(self.contexts) if rc is not self.rc]
        for rc in rcs:
            for k, v in rc.resources.items():
                if v is obj:
                    return k, rc
            for k, v in rc.external.items():
                if v is obj:
                    return k, rc
        return None, None

    def _report(self, key, msg):
        if key in self._seen:
            return
        self._seen.add(key)
        self.violations.append(msg)

    # ------------------------------------------------------------------ pass scope
    def begin(self, rc, p, graph=None):
        self.contexts.add(rc)
        self.rc, self.pass_, self.pending, self.graph = rc, p, {}, graph

    def suspend(self):
        """Attribute the accesses until ``resume`` to the graph, not to the running pass (a
        clear or upload the graph orders and records itself, even when a pass asks for it)."""
        saved = self.pass_
        self.pass_ = None
        return saved

    def resume(self, saved):
        self.pass_ = saved

    def end(self):
        who = self.pass_.name if self.pass_ is not None else OUTSIDE
        for oid, (access, name, obj, visible) in self.pending.items():
            st = self.state[oid] = _State(who, access, name, obj)
            st.visible = visible
        self.pass_, self.pending = None, {}

    def take(self) -> list[str]:
        out, self.violations = self.violations, []
        self._seen = set()
        return out

    # ------------------------------------------------------------------ events
    def barrier(self, bits):
        for st in self.state.values():
            st.visible |= bits
        for w in self.pending.values():  # the running pass's writes made before this barrier
            w[3] |= bits

    def access(self, obj, access: str, write: bool, is_buffer: bool):
        name, rc = self.name_of(obj)
        p = self.pass_
        who = p.name if p is not None else OUTSIDE
        if name is None:
            self._unnamed(obj, access, write, is_buffer)
            if p is None:
                return  # objects outside the passes and the graph's resources: not followed
            # a pass's own object: its accesses across frames are checked like a resource's
            name = f"<unnamed {'buffer' if is_buffer else 'texture'} of pass {p.name}>"
        elif p is not None:
            self._check_declared(p, rc, name, access, write, is_buffer)
        st = self.state.get(id(obj))
        # accesses after this pass's own writes of the frame are the pass's to order
        if st is not None and id(obj) not in self.pending:
            need = required_bits(st.access, access, is_buffer)
            missing = need & ~st.visible
            if missing:
                what = READ_ACCESS_NAMES.get(access, access) if not write else WRITE_ACCESS_NAMES.get(access, access)
                self._report((who, name, access, st.writer),
                             f"sync: pass '{who}' accesses '{name}' by {what} after '{st.writer}' wrote it by "
                             f"{WRITE_ACCESS_NAMES.get(st.access, st.access)}, with no "
                             f"{'|'.join(barrier_names(missing))} barrier between them")
        if write:
            if p is None:
                self.state[id(obj)] = _State(who, access, name, obj)
            else:
                prev = self.pending.get(id(obj))
                # the last incoherent write is the one a later access waits on
                if prev is None or access in INCOHERENT_WRITES or prev[0] not in INCOHERENT_WRITES:
                    self.pending[id(obj)] = [access, name, obj, 0]

    def _unnamed(self, obj, access, write, is_buffer):
        """An object no resource name refers to: private to one pass, unless a pass uses what
        another pass wrote (an object shared behind the graph's back)."""
        p = self.pass_
        if p is None:
            return
        rec = self.unnamed.get(id(obj))
        # within one render context: scene data one session's pass uploads on first use may
        # serve another session's passes
        if rec is not None and rec[0] is obj and rec[1] != p.name and rec[2] is self.rc:
            kind = "buffer" if is_buffer else "texture"
            self._report((p.name, rec[1], id(obj)),
                         f"sync: pass '{p.name}' uses a {kind} ({READ_ACCESS_NAMES.get(access, access)}) that pass "
                         f"'{rec[1]}' wrote, and no declared resource names it")
        if write:
            self.unnamed[id(obj)] = (obj, p.name, self.rc)

    def declared_writes(self, p, name) -> tuple:
        decl = self.graph.declaration(name) if self.graph is not None else None
        try:
            return p.write_accesses(name, decl)
        except Exception:
            return ()

    def _check_declared(self, p, rc, name, access, write, is_buffer):
        declared = set(p.reads) | set(p.optional_reads) | set(p.writes) | set(getattr(p, "external", ()))
        if name not in declared and not (not write and name in rc.scene_wide):
            self._report((p.name, name, "undeclared"),
                         f"sync: pass '{p.name}' uses '{name}' ({(WRITE_ACCESS_NAMES if write else READ_ACCESS_NAMES).get(access, access)}) "
                         f"but does not declare it (reads, optional_reads, writes or external)")
            return
        if not write:
            return
        if name not in p.writes:
            self._report((p.name, name, "write-undeclared"),
                         f"sync: pass '{p.name}' writes '{name}' by {WRITE_ACCESS_NAMES.get(access, access)} "
                         f"but declares it only as a read")
            return
        decl = (self.graph.declaration(name) if self.graph is not None else None) or rc.specs.get(name, (None,))[0]
        try:
            accesses = p.write_accesses(name, decl)
        except Exception as exc:  # a mixed pass without write_access
            self._report((p.name, name, "mixed"), f"sync: {exc}")
            return
        if access not in accesses:
            self._report((p.name, name, "write-kind", access),
                         f"sync: pass '{p.name}' writes '{name}' by {WRITE_ACCESS_NAMES.get(access, access)} but "
                         f"declares {' then '.join(WRITE_ACCESS_NAMES.get(a, a) for a in accesses)} "
                         f"(kind={p.kind!r}); the barriers derived from the declaration do not cover it")


VALIDATOR = Validator()
_installed = False


def install():
    """Wrap the moderngl methods that access GL objects (idempotent)."""
    global _installed
    if _installed:
        return
    _installed = True
    import moderngl

    V = VALIDATOR

    def wrap(cls, meth, fn):
        orig = getattr(cls, meth, None)
        if orig is None:
            return

        def wrapper(self, *a, **kw):
            if enabled():
                fn(self, *a, **kw)
            return orig(self, *a, **kw)

        wrapper.__name__ = meth
        wrapper.__wrapped__ = orig
        setattr(cls, meth, wrapper)

    tex_classes = [getattr(moderngl, n) for n in ("Texture", "TextureArray", "Texture3D", "TextureCube")
                   if hasattr(moderngl, n)]
    for cls in tex_classes:
        wrap(cls, "use", lambda self, *a, **k: V.access(self, "texture", False, False))

        def bind(self, unit, read=True, write=True, *a, **k):
            if read:
                V.access(self, "image", False, False)
            if write:
                V.access(self, "image", True, False)
        wrap(cls, "bind_to_image", bind)
        wrap(cls, "write", lambda self, *a, **k: V.access(self, "upload", True, False))
        wrap(cls, "build_mipmaps", lambda self, *a, **k: V.access(self, "upload", True, False))
        wrap(cls, "read", lambda self, *a, **k: V.access(self, "readback", False, False))
        wrap(cls, "read_into", lambda self, *a, **k: V.access(self, "readback", False, False))
    if hasattr(moderngl, "DepthTexture"):
        wrap(moderngl.DepthTexture, "use", lambda self, *a, **k: V.access(self, "texture", False, False))

    B = moderngl.Buffer

    def storage(self, *a, **k):
        V.access(self, "storage", False, True)
        p = V.pass_
        name = V.name_of(self)[0]
        if p is not None and name in p.writes and "storage" in V.declared_writes(p, name):
            V.access(self, "storage", True, True)
    wrap(B, "bind_to_storage_buffer", storage)
    wrap(B, "bind_to_uniform_block", lambda self, *a, **k: V.access(self, "uniform", False, True))
    for m in ("write", "write_chunks", "clear", "orphan"):
        wrap(B, m, lambda self, *a, **k: V.access(self, "upload", True, True))
    for m in ("read", "read_into", "read_chunks", "read_chunks_into"):
        wrap(B, m, lambda self, *a, **k: V.access(self, "readback", False, True))

    def fbo(self, *a, **k):
        for t in tuple(getattr(self, "color_attachments", ()) or ()) + (getattr(self, "depth_attachment", None),):
            if t is not None:
                V.access(t, "framebuffer", True, False)
    wrap(moderngl.Framebuffer, "use", fbo)
    wrap(moderngl.Framebuffer, "clear", fbo)

    def indirect(self, buffer, *a, **k):
        V.access(buffer, "indirect", False, True)
    wrap(moderngl.VertexArray, "render_indirect", indirect)

    def barrier(self, barriers=ALL_BARRIER_BITS, *a, **k):
        V.barrier(int(barriers))
    wrap(moderngl.Context, "memory_barrier", barrier)
