"""Optional PyTorch for Follow Curve: pip-installed into the extension's own user folder.

Extend, Denoise and Foot Lock run on Blender's NumPy; Follow Curve needs torch. The add-on
preferences offer *Install PyTorch*, which runs ``pip install --target <folder> torch==2.13.0``
with Blender's own Python, only when Blender is allowed online (``bpy.app.online_access``).
The folder (``extensions/.user/<repository>/strnn_motion/site-packages``) survives extension
upgrades and is put on ``sys.path`` when the add-on registers.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import subprocess
import sys

import bpy

from .props import ADDON_ID

TORCH_PIN = "torch==2.13.0"
OFFLINE = ("Online access is off: allow it in Preferences > System > Network > Allow Online Access "
           "to install PyTorch from here")


def site_packages(create: bool = False) -> str:
    """The extension's user folder for Python packages; '' when Blender has none for this module
    (the add-on imported bare, outside an extension repository)."""
    try:
        return bpy.utils.extension_path_user(ADDON_ID, path="site-packages", create=create) or ""
    except (ValueError, AttributeError):
        return ""


def install_command(target: str, python: str | None = None) -> list[str]:
    """The pip command that installs the pinned torch into ``target`` with ``python``
    (default: the running interpreter, Blender's own Python)."""
    return [python or sys.executable, "-m", "pip", "install", "--target", str(target), TORCH_PIN]


def online_access() -> bool:
    """Whether Blender may go online (Preferences > System > Network, or --online-mode)."""
    return bool(getattr(bpy.app, "online_access", False))


def torch_available() -> bool:
    return importlib.util.find_spec("torch") is not None


_added: list[str] = []


def add_to_path() -> None:
    """Put the user folder on ``sys.path`` (at the end: Blender's own modules win) if it exists."""
    folder = site_packages()
    if folder and os.path.isdir(folder) and folder not in sys.path:
        sys.path.append(folder)
        _added.append(folder)
        importlib.invalidate_caches()


def remove_from_path() -> None:
    while _added:
        folder = _added.pop()
        if folder in sys.path:
            sys.path.remove(folder)


def _run(cmd: list[str]) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, capture_output=True, text=True, check=False)


class STRNN_OT_install_torch(bpy.types.Operator):
    """Install the CPU build of PyTorch (needed by Follow Curve) into this extension's user folder with pip"""

    bl_idname = "strnn.install_torch"
    bl_label = "Install PyTorch"
    bl_options = {"REGISTER", "INTERNAL"}

    def execute(self, context):
        if not online_access():
            self.report({"ERROR"}, OFFLINE)
            return {"CANCELLED"}
        target = site_packages(create=True)
        if not target:
            self.report({"ERROR"}, "No user folder for this extension: install STRNN Motion as an extension "
                                   "(Get Extensions > Install from Disk) to install PyTorch from here")
            return {"CANCELLED"}
        cmd = install_command(target)
        try:
            result = _run(cmd)
        except OSError as e:
            self.report({"ERROR"}, f"Could not run pip ({e}): run '{' '.join(cmd)}' in a terminal")
            return {"CANCELLED"}
        if result.returncode != 0:
            lines = [ln for ln in (result.stderr or result.stdout or "").splitlines() if ln.strip()]
            detail = lines[-1] if lines else f"exit status {result.returncode}"
            self.report({"ERROR"}, f"Installing PyTorch failed: {detail}")
            return {"CANCELLED"}
        add_to_path()
        if torch_available():
            self.report({"INFO"}, f"Installed {TORCH_PIN} into {target}")
        else:
            self.report({"WARNING"}, f"pip installed {TORCH_PIN} into {target}; restart Blender to use it")
        return {"FINISHED"}


def draw_preferences(layout) -> None:
    """The PyTorch box of the add-on preferences."""
    box = layout.box()
    if torch_available():
        box.label(text="PyTorch is installed: Follow Curve can run", icon="CHECKMARK")
        return
    box.label(text="PyTorch is not installed: Follow Curve needs it (Extend, Denoise and Foot Lock do not)",
              icon="INFO")
    if online_access():
        box.operator(STRNN_OT_install_torch.bl_idname, icon="IMPORT")
    else:
        box.label(text="Online access is off: allow it in Preferences > System > Network to install it here",
                  icon="ERROR")


classes = (STRNN_OT_install_torch,)
