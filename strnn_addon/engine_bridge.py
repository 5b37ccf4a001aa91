"""The one place the add-on calls the model: load (cached) and run it on a clip.

:func:`extend` and :func:`denoise` are the only model calls the operators make, so a
test can swap them for a stand-in.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..model_core import motion_ops

_CACHE: dict[tuple, object] = {}


class EngineError(RuntimeError):
    """The model could not be loaded; the message says where it looked and what to do."""


def bundled_model() -> Path:
    """The model folder shipped inside the extension."""
    return Path(__file__).resolve().parent.parent / "models" / "strnn_default"


def load_engine(folder: str = "", engine: str = "NUMPY", threads: int = 0):
    """The inference engine for ``folder`` ('' = bundled), cached across calls."""
    path = Path(folder) if folder else bundled_model()
    key = (str(path), engine, threads)
    if key not in _CACHE:
        if not (path / "model.json").exists():
            raise EngineError(f"No model at {path}: set a folder holding model.json and model.safetensors "
                              "in Preferences > Add-ons > STRNN Motion > Model Folder")
        _set_threads(engine, threads)
        try:
            if engine == "TORCH":
                from ..model_core.torch_engine import TorchEngine as Engine
            else:
                from ..model_core.engine import Engine
            _CACHE.clear()
            _CACHE[key] = Engine.load(path)
        except (ImportError, ValueError, OSError, KeyError) as e:
            raise EngineError(f"Could not load the model at {path}: {e}") from e
    return _CACHE[key]


def _set_threads(engine: str, threads: int) -> None:
    if threads <= 0:
        return
    if engine == "TORCH":
        import torch

        torch.set_num_threads(threads)
    try:
        from threadpoolctl import threadpool_limits

        threadpool_limits(threads)
    except ImportError:
        pass  # NumPy's BLAS keeps its own thread count


def engine_from_prefs(prefs):
    """The engine the add-on preferences ask for (defaults when ``prefs`` is None)."""
    if prefs is None:
        return load_engine()
    return load_engine(bpy_path(prefs.model_folder), prefs.engine, prefs.threads)


def bpy_path(path: str) -> str:
    """Resolve Blender's ``//`` relative paths."""
    if path.startswith("//"):
        import bpy

        return bpy.path.abspath(path)
    return path


def extend(prefs, positions: np.ndarray, fps: float, frames: int) -> np.ndarray:
    """Continue ``positions`` ``[F, 21, 3]`` (Y-up scene units at ``fps``) by ``frames`` -> ``[frames, 21, 3]``."""
    return motion_ops.extend_positions(engine_from_prefs(prefs), positions, fps, frames)


def denoise(prefs, positions: np.ndarray, fps: float, strength: float) -> np.ndarray:
    """Denoised ``positions`` ``[F, 21, 3]`` (same space and frames), blended by ``strength``."""
    return motion_ops.denoise_positions(engine_from_prefs(prefs), positions, fps, strength)
