# SPDX-License-Identifier: GPL-3.0-or-later
"""GI Preview: real-time global illumination techniques rendered in Blender and measured
against Cycles.

bpy is imported only inside ``register()`` so that the bpy-free packages (``render``,
``compare``) can be imported and tested without Blender.
"""


def register():
    from . import blender

    blender.register()


def unregister():
    from . import blender

    blender.unregister()
