"""Entry point of the STRNN Motion extension (Blender loads this file).

The add-on lives in ``strnn_addon/``; the maths it calls in ``model_core/``, a sibling
package inside the built extension (see scripts/build_extension.py).
"""

from . import strnn_addon


def register():
    strnn_addon.register()


def unregister():
    strnn_addon.unregister()
