"""Optional PyTorch for Follow Curve: pip-installed into the extension's own user folder.

Extend, Denoise and Foot Lock run on Blender's NumPy; Follow Curve needs torch. The add-on
preferences offer *Install PyTorch*, which runs ``pip install --target <folder> torch==2.13.0``
with Blender's own Python, only when Blender is allowed online (``bpy.app.online_access``).
The folder (``extensions/.user/<repository>/strnn_motion/site-packages``) survives extension
upgrades and is put on ``sys.path`` when the add-on registers.

pip runs in the background (:class:`PipInstall`): the preferences show its latest line, Blender
stays usable, and Esc or *Cancel* stops it. pip writes into a scratch folder beside the user
folder; only a finished install is moved in, so a cancelled or failed one leaves nothing behind.
"""

from __future__ import annotations

import collections
import importlib
import importlib.util
import os
import shutil
import subprocess
import sys
import tempfile
import threading

import bpy

from .props import ADDON_ID

TORCH_PIN = "torch==2.13.0"
CPU_INDEX = "https://download.pytorch.org/whl/cpu"  # PyPI's Linux and Windows wheels bring CUDA (gigabytes)
OFFLINE = ("Online access is off: allow it in Preferences > System > Network > Allow Online Access "
           "to install PyTorch from here")
NO_FOLDER = ("No user folder for this extension: install STRNN Motion as an extension "
             "(Get Extensions > Install from Disk) to install PyTorch from here")


def site_packages(create: bool = False) -> str:
    """The extension's user folder for Python packages; '' when Blender has none for this module
    (the add-on imported bare, outside an extension repository)."""
    try:
        return bpy.utils.extension_path_user(ADDON_ID, path="site-packages", create=create) or ""
    except (ValueError, AttributeError):
        return ""


def install_command(target: str, python: str | None = None, platform: str = sys.platform) -> list[str]:
    """The pip command that installs the pinned CPU build of torch into ``target`` with ``python``
    (default: the running interpreter, Blender's own Python). On Linux and Windows the CPU build
    comes from PyTorch's own index; macOS wheels on PyPI are CPU builds already."""
    cmd = [python or sys.executable, "-m", "pip", "install", "--target", str(target), TORCH_PIN]
    return cmd if platform == "darwin" else [*cmd, "--index-url", CPU_INDEX]


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


class PipInstall:
    """One ``pip install`` into a scratch folder beside ``target``, run in the background.

    :meth:`poll` says whether pip is still running, :attr:`status` is its latest output line,
    :meth:`finish` moves a successful install into ``target`` (and raises ``RuntimeError`` with
    pip's last line when it failed), :meth:`cancel` stops pip. Either way the scratch folder is
    removed, so ``target`` only ever receives a complete install."""

    def __init__(self, target: str):
        self.target = target
        os.makedirs(target, exist_ok=True)
        self.scratch = tempfile.mkdtemp(prefix=".installing-", dir=os.path.dirname(os.path.abspath(target)))
        self.command = install_command(self.scratch)
        self.lines: collections.deque[str] = collections.deque(maxlen=50)
        self.cancelled = False
        try:
            self._proc = subprocess.Popen(self.command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                          stdin=subprocess.DEVNULL, text=True, errors="replace")
        except OSError as e:
            shutil.rmtree(self.scratch, ignore_errors=True)
            raise RuntimeError(f"Could not run pip ({e}): run '{' '.join(install_command(target))}' "
                               "in a terminal") from e
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        for line in self._proc.stdout:
            if line.strip():
                self.lines.append(line.strip())

    @property
    def status(self) -> str:
        return self.lines[-1] if self.lines else "starting pip"

    def poll(self) -> bool:
        """True while pip runs."""
        return self._proc.poll() is None

    def wait(self) -> None:
        self._proc.wait()
        self._reader.join()

    def cancel(self) -> None:
        """Stop pip (if it still runs) and remove what it wrote."""
        self.cancelled = True
        if self.poll():
            self._proc.terminate()
            try:
                self._proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self._proc.kill()
        self.wait()
        shutil.rmtree(self.scratch, ignore_errors=True)

    def finish(self) -> None:
        """After pip ended: move its packages into ``target``, replacing older copies."""
        self.wait()
        try:
            if self._proc.returncode != 0:
                detail = self.lines[-1] if self.lines else f"exit status {self._proc.returncode}"
                if "No module named pip" in detail:
                    detail += f" (this Python has no pip: run '{self.command[0]} -m ensurepip' once, then try again)"
                raise RuntimeError(f"Installing PyTorch failed: {detail}")
            for name in sorted(os.listdir(self.scratch)):
                dest = os.path.join(self.target, name)
                if os.path.isdir(dest) and not os.path.islink(dest):
                    shutil.rmtree(dest)
                elif os.path.lexists(dest):
                    os.remove(dest)
                os.replace(os.path.join(self.scratch, name), dest)
        finally:
            shutil.rmtree(self.scratch, ignore_errors=True)


_running: PipInstall | None = None  # the install in progress, shown by the preferences


def _redraw_preferences() -> None:
    for window in getattr(bpy.context.window_manager, "windows", ()):
        for area in window.screen.areas:
            if area.type == "PREFERENCES":
                area.tag_redraw()


class STRNN_OT_install_torch(bpy.types.Operator):
    """Install the CPU build of PyTorch (needed by Follow Curve) into this extension's user folder with pip"""

    bl_idname = "strnn.install_torch"
    bl_label = "Install PyTorch"
    bl_options = {"REGISTER", "INTERNAL"}

    def _begin(self) -> PipInstall | None:
        if _running is not None:
            self.report({"ERROR"}, "PyTorch is already being installed: wait for it, or cancel it first")
            return None
        if not online_access():
            self.report({"ERROR"}, OFFLINE)
            return None
        target = site_packages(create=True)
        if not target:
            self.report({"ERROR"}, NO_FOLDER)
            return None
        try:
            return PipInstall(target)
        except RuntimeError as e:
            self.report({"ERROR"}, str(e))
            return None

    def _end(self, job: PipInstall) -> set:
        try:
            job.finish()
        except (RuntimeError, OSError) as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        add_to_path()
        if torch_available():
            self.report({"INFO"}, f"Installed {TORCH_PIN} into {job.target}")
        else:
            self.report({"WARNING"}, f"pip installed {TORCH_PIN} into {job.target}; restart Blender to use it")
        return {"FINISHED"}

    def execute(self, context):
        """Scripts: install and wait."""
        job = self._begin()
        if job is None:
            return {"CANCELLED"}
        return self._end(job)

    def invoke(self, context, event):
        """The preferences button: pip runs in the background, Blender stays usable, Esc cancels."""
        global _running
        if context.window is None:
            return self.execute(context)
        job = self._begin()
        if job is None:
            return {"CANCELLED"}
        _running = job
        wm = context.window_manager
        self._timer = wm.event_timer_add(0.25, window=context.window)
        wm.modal_handler_add(self)
        _redraw_preferences()
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        job = _running
        if event.type == "ESC" or job is None or job.cancelled:
            if job is not None:
                job.cancel()
            self._stop(context)
            self.report({"WARNING"}, "PyTorch install cancelled; nothing was installed")
            return {"CANCELLED"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        _redraw_preferences()
        if job.poll():
            return {"PASS_THROUGH"}
        self._stop(context)
        return self._end(job)

    def cancel(self, context):
        """Blender ends the operator (its window closed, another file loaded): stop pip too."""
        if _running is not None:
            _running.cancel()
        self._stop(context)

    def _stop(self, context) -> None:
        global _running
        _running = None
        context.window_manager.event_timer_remove(self._timer)
        _redraw_preferences()


class STRNN_OT_cancel_torch_install(bpy.types.Operator):
    """Stop the running PyTorch install; nothing is installed"""

    bl_idname = "strnn.cancel_torch_install"
    bl_label = "Cancel"
    bl_options = {"REGISTER", "INTERNAL"}

    def execute(self, context):
        if _running is None:
            self.report({"WARNING"}, "No PyTorch install is running")
            return {"CANCELLED"}
        _running.cancel()
        return {"FINISHED"}


def draw_preferences(layout) -> None:
    """The PyTorch box of the add-on preferences."""
    box = layout.box()
    if _running is not None:
        row = box.row()
        row.label(text=f"Installing {TORCH_PIN}: {_running.status[:90]}", icon="SORTTIME")
        row.operator(STRNN_OT_cancel_torch_install.bl_idname, icon="CANCEL")
        return
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


classes = (STRNN_OT_install_torch, STRNN_OT_cancel_torch_install)
