# SPDX-License-Identifier: GPL-3.0-or-later
"""GI Preview extension entry point.

PLACEHOLDER written by the packaging work so the built zip can be installed and
tested before the real entry point exists: it only registers an empty render
engine with the public id "GI_PREVIEW". Replace it wholesale with the team's
register()/unregister(); keep bpy imports inside register().
"""

_classes = []


def register():
    import bpy

    class GIPreviewRenderEngine(bpy.types.RenderEngine):
        bl_idname = "GI_PREVIEW"
        bl_label = "GI Preview"
        bl_use_preview = False
        bl_use_shading_nodes_custom = False

        def render(self, depsgraph):
            scene = depsgraph.scene
            scale = scene.render.resolution_percentage / 100.0
            w = max(4, int(scene.render.resolution_x * scale))
            h = max(4, int(scene.render.resolution_y * scale))
            result = self.begin_result(0, 0, w, h)
            result.layers[0].passes["Combined"].rect = [[0.0, 0.0, 0.0, 1.0]] * (w * h)
            self.end_result(result)

    bpy.utils.register_class(GIPreviewRenderEngine)
    _classes.append(GIPreviewRenderEngine)


def unregister():
    import bpy

    while _classes:
        bpy.utils.unregister_class(_classes.pop())
