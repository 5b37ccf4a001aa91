"""STRNN Motion for Blender: extend and denoise an armature's action with the motion model.

Everything here touches bpy; the maths lives in the sibling package ``model_core``.
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
