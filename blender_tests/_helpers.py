"""Helpers shared by the render tests: export a Blender scene, dump images as EXR for a
failure's post-mortem, and the mean of an image over a reference's."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from gi_preview.blender import reference
from gi_preview.blender.export import export_scene


def export(sc):
    """SceneData of ``sc`` through its evaluated depsgraph."""
    return export_scene(reference.evaluated_depsgraph(sc))


def dump_exr(folder: Path, name: str, **images) -> None:
    """Write each image as ``folder/<name>_<key>.exr``."""
    from gi_preview.compare import imageio

    reference.ensure_oiio()
    folder.mkdir(parents=True, exist_ok=True)
    for k, img in images.items():
        imageio.write_exr(str(folder / f"{name}_{k}.exr"), np.asarray(img, np.float32))


def mean_ratio(img, ref) -> float:
    """Mean of ``img``'s RGB over the mean of ``ref``'s."""
    return float(img[..., :3].mean() / max(ref[..., :3].mean(), 1e-12))


def build_named_scene(builders: dict, name: str, resolution: int, prefix: str, what: str):
    """A new scene ``<prefix>_<name>`` at ``resolution``² built by ``builders[name](builder,
    make_principled, make_world)`` with the demo scenes' builder (the caller removes it)."""
    import bpy

    from gi_preview.blender import demo_scenes

    if name not in builders:
        raise ValueError(f"unknown {what} {name!r}; choose one of {', '.join(builders)}")
    sc = bpy.data.scenes.new(f"{prefix}_{name}")
    sc.render.resolution_x = sc.render.resolution_y = int(resolution)
    sc.render.resolution_percentage = 100
    builders[name](demo_scenes._Builder(sc, f"{prefix}_{name}"), demo_scenes.make_principled, demo_scenes.make_world)
    return sc
