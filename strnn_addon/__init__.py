"""STRNN Motion for Blender: Extend Clip, Fill Gap, Denoise Action, Foot Lock, Follow Curve and
Transfer Motion on an armature's action with the motion model, and Auto-Map Bones to map a rig's
bones to its joints. It needs nothing beyond Blender's own Python and NumPy.

Everything here touches bpy (``scene/`` reads and writes the scene, ``stages/`` runs each
operation); the maths lives in the sibling package ``model_core``. See ARCHITECTURE.md.
"""

from __future__ import annotations

import bpy

from . import operators, props, ui

classes = (*props.classes, *operators.classes, *ui.classes)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    props.register_properties()
    ui.register_menus()


def unregister():
    ui.unregister_menus()
    props.unregister_properties()
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
