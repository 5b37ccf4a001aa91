"""STRNN Motion for Blender: Extend Clip, Denoise Action, Foot Lock and Follow Curve on an
armature's action with the motion model, and Auto-Map Bones to map a rig's bones to its joints.

Everything here touches bpy (``scene/`` reads and writes the scene, ``stages/`` runs each
operation); the maths lives in the sibling package ``model_core``. See ARCHITECTURE.md.
"""

from __future__ import annotations

import bpy

from . import operators, props, torch_install, ui

classes = (*props.classes, *operators.classes, *torch_install.classes, *ui.classes)


def register():
    torch_install.add_to_path()  # torch installed by Preferences > Install PyTorch
    for cls in classes:
        bpy.utils.register_class(cls)
    props.register_properties()
    ui.register_menus()


def unregister():
    ui.unregister_menus()
    props.unregister_properties()
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
    torch_install.remove_from_path()
