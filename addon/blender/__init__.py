"""The only package that imports bpy: engine, export, properties, panels, operators.

``register()``/``unregister()`` are the add-on's; every class is registered through one
``classes`` tuple and unregistered in reverse order.
"""
from __future__ import annotations

import bpy

from . import compare_ops, demo_scenes, engine, properties, ui

classes = (
    *properties.classes,
    *compare_ops.classes,
    *engine.classes,
    *ui.classes,
    *demo_scenes.classes,
)


def register():
    if hasattr(bpy.utils, "expose_bundled_modules"):
        bpy.utils.expose_bundled_modules()  # OpenImageIO for EXR I/O (PyPI bpy module)
    for cls in classes:
        bpy.utils.register_class(cls)
    properties.register_props()
    compare_ops.register_props()
    ui.register_panels()
    bpy.types.VIEW3D_MT_add.append(demo_scenes.menu_func)


def unregister():
    bpy.types.VIEW3D_MT_add.remove(demo_scenes.menu_func)
    ui.unregister_panels()
    compare_ops.unregister_props()
    properties.unregister_props()
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
    from ..render import gl

    gl.shutdown()
