"""Viewport overlay of the probe techniques (IRRADIANCE_VOLUME, DDGI, RTXGI): the probes drawn
as small spheres shaded with their irradiance, as DDGI tools show them.

Toggled by ``scene.gi_preview.show_probes`` (GI Preview panel, "Show Probes"); drawn in the
Rendered viewport only (F12 renders and render passes are unchanged; the render passes
``GI_ProbeIrradiance`` and ``GI_ProbeState`` draw spheres too). The engine's ``view_draw``
submits its frame through :func:`submit_render` instead of ``session.submit_render`` when the
setting is on: the frame renders as usual (same session, accumulation and history), then, on
the GL thread and before the future completes, ``shaders/probes/overlay.comp`` traces the
probe spheres for every pixel of the frame (2x2 rays per pixel, unjittered camera,
depth-tested against the G-buffer, sphere point with normal n shaded E(n)/pi from the
irradiance atlas) and the result is composited over the accumulated image ("over", by the
coverage). A technique without probes returns the image unchanged. The overlay costs one
dispatch looping over every probe per ray: volumes up to ``MAX_PROBES`` probes are drawn.
"""
from __future__ import annotations

import numpy as np

from .barriers import TEXTURE_UPDATE_BARRIER_BIT
from .gpu_scene import set_uniform
from .passes.gbuffer import POSITION
from .passes.probes import IRR, STATE, find_volume
from .passes.screen_space import Units

RADIUS = 0.15       # sphere radius, fraction of the smallest cell side
MAX_PROBES = 4096   # larger volumes are not drawn (one loop over the probes per ray)


def overlay_rgba(sess, scene) -> np.ndarray | None:
    """The overlay of session ``sess``'s last frame, (H, W, 4) float32: rgb premultiplied by
    a = coverage. None when the last graph has no probe volume (or too many probes). GL thread."""
    rc = sess.rc
    vol = find_volume(getattr(sess, "_last_graph", None))
    if rc is None or vol is None or vol.probe_count > MAX_PROBES:
        return None
    if any(n not in rc.resources for n in (IRR, STATE, POSITION)):
        return None
    rc.barrier_external([IRR, STATE, POSITION])
    prog = sess.programs.compute("probes/overlay.comp")
    vol.set_uniforms(prog)
    cam = scene.camera
    vp = cam.projection.astype(np.float64) @ cam.view.astype(np.float64)
    set_uniform(prog, "u_inv_view_proj", np.linalg.inv(vp).astype(np.float32))
    set_uniform(prog, "u_radius", float(RADIUS * float(vol.spacing.min())))
    units = Units(1)
    units.tex(prog, "u_probe_irr", rc.resources[IRR])
    units.tex(prog, "u_probe_state", rc.resources[STATE])
    units.tex(prog, "u_gb_position", rc.resources[POSITION])
    w, h = rc.size
    out = sess.ctx.texture((w, h), 4, dtype="f4")
    try:
        out.bind_to_image(0, read=False, write=True)
        prog.run((w + 7) // 8, (h + 7) // 8, 1)
        sess.ctx.memory_barrier(TEXTURE_UPDATE_BARRIER_BIT)  # the image stores, before the read-back
        return np.frombuffer(out.read(), np.float32).reshape(h, w, 4).copy()
    finally:
        out.release()


def composite(image: np.ndarray, overlay: np.ndarray) -> np.ndarray:
    """``image`` (H, W, 4) with the premultiplied overlay drawn over it."""
    out = image.copy()
    a = overlay[..., 3:4]
    out[..., :3] = image[..., :3] * (1.0 - a) + overlay[..., :3]
    return out


def _post(sess, scene, res):
    """``session.submit_render``'s post hook: the overlay composited over ``res.image``."""
    ov = overlay_rgba(sess, scene)
    if ov is not None and ov.shape[:2] == res.image.shape[:2]:
        res.image = composite(res.image, ov)
        res.aovs["ProbeOverlay"] = ov
    return res


def submit_render(scene, technique: str, quality: int, samples: int, *, session, on_done=None, **options):
    """``session.submit_render`` with the probe overlay composited over the result's image
    (on the GL thread, before the returned future completes). Same arguments and future."""
    from . import session as S
    return S.submit_render(scene, technique, quality, samples, session=session, on_done=on_done, post=_post,
                           **options)
