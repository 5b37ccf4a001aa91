"""Entry point of the STRNN Motion extension (Blender loads this file), and the top of the
``strnn_motion`` Python package (``pip install .``).

The add-on lives in ``strnn_addon/``; the maths it calls in ``model_core/``, a sibling
package inside the built extension (see scripts/build_extension.py) and ``strnn_motion.model_core``
when installed with pip. The add-on, which needs bpy, is imported only when Blender registers it.
"""


def register():
    from . import strnn_addon

    strnn_addon.register()


def unregister():
    from . import strnn_addon

    strnn_addon.unregister()
