"""The one place the add-on calls the model: load (cached) and run it on a clip.

:func:`extend`, :func:`denoise_steps` and :func:`follow_curve_steps` are the only model calls
the operators make, so a test can swap them for a stand-in.
"""

from __future__ import annotations

import json
from pathlib import Path

import bpy
import numpy as np

from ..model_core.io.checkpoint import DEFAULT_MODEL, default_denoiser
from ..model_core.ops.denoise import denoise_positions_steps
from ..model_core.ops.extend import extend_positions
from ..model_core.ops.familiarity import clip_familiarity
from ..model_core.ops.follow import PathFollower, follow_curve_steps as follow_curve_model_steps
from ..model_core.ops.inbetween import inbetween_positions

_CACHE: dict[tuple, object] = {}


class EngineError(RuntimeError):
    """The model could not be loaded; the message says where it looked and what to do."""


def main_folder(prefs) -> str:
    """The Model Folder preference as a path ('' = the bundled model; also without preferences)."""
    return bpy_path(prefs.model_folder) if prefs is not None else ""


def denoiser_folder(prefs) -> str:
    """The model Denoise uses: the Denoise Model Folder preference, else the bundled denoising
    model, else the main model ('' = the bundled one)."""
    if prefs is not None and prefs.denoise_model_folder:
        return bpy_path(prefs.denoise_model_folder)
    return str(default_denoiser(main_folder(prefs)))


def model_path(folder: str, setting: str = "Model Folder") -> Path:
    """The model folder ``folder`` ('' = the bundled model); :class:`EngineError` naming the preference
    ``setting`` that picks it when it holds no model."""
    path = Path(folder) if folder else DEFAULT_MODEL
    if not (path / "model.json").exists():
        raise EngineError(f"No model at {path}: set a folder holding model.json and model.safetensors "
                          f"in Preferences > Add-ons > STRNN Motion > {setting}")
    return path


def model_used(prefs, purpose: str = "generate") -> str:
    """The folder of the model an operation uses: the Model Folder's (``generate``) or the one
    Denoise uses (``denoise``); '' when there is none."""
    try:
        return str(model_path(denoiser_folder(prefs) if purpose == "denoise" else main_folder(prefs)))
    except EngineError:
        return ""


def model_card(folder: str) -> dict:
    """What the preferences show of the model in ``folder``: its ``name`` and ``licence`` (from
    model.json), and whether that licence allows only ``non_commercial`` use."""
    path = Path(folder)
    try:
        doc = json.loads((path / "model.json").read_text())
    except (OSError, ValueError):
        return {"name": path.name, "licence": "unknown (model.json unreadable)", "non_commercial": False}
    licence = str(doc.get("licence") or "not stated in model.json")
    return {"name": path.name, "licence": licence, "non_commercial": "-NC" in licence or "NonCommercial" in licence}


def load_engine(folder: str = "", engine: str = "NUMPY", threads: int = 0, setting: str = "Model Folder"):
    """The inference engine for ``folder`` ('' = bundled), cached across calls; errors name the
    preference ``setting`` that picks the folder."""
    path = model_path(folder, setting)
    key = (str(path), engine, threads)
    if key not in _CACHE:
        _set_threads(engine, threads)
        try:
            if engine == "TORCH":
                from ..model_core.inference.torch_engine import TorchEngine as Engine
            else:
                from ..model_core.inference.engine import Engine
            if len(_CACHE) >= 2:  # the main model and the denoiser stay loaded; older choices go
                _CACHE.pop(next(iter(_CACHE)))
            _CACHE[key] = Engine.load(path)
        except (ImportError, ValueError, OSError, KeyError) as e:
            raise EngineError(f"Could not load the model at {path} ({setting}): {e}") from e
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


def engine_from_prefs(prefs, folder: str | None = None, setting: str = "Model Folder"):
    """The engine the add-on preferences ask for (defaults when ``prefs`` is None), for the
    Model Folder or for ``folder`` (picked by the preference ``setting``)."""
    if folder is None:
        folder = main_folder(prefs)
    if prefs is None:
        return load_engine(folder, setting=setting)
    return load_engine(folder, prefs.engine, prefs.threads, setting)


def generator_from_prefs(prefs):
    """The main model's engine, refused with an :class:`EngineError` if it can only denoise."""
    engine = engine_from_prefs(prefs)
    try:
        engine.ckpt.require_generator("extend a clip")
    except ValueError as e:
        raise EngineError(f"{e} (Preferences > Add-ons > STRNN Motion > Model Folder)") from e
    return engine


def bpy_path(path: str) -> str:
    """Resolve Blender's ``//`` relative paths."""
    if path.startswith("//"):
        return bpy.path.abspath(path)
    return path


def extend(prefs, positions: np.ndarray, fps: float, frames: int) -> np.ndarray:
    """Continue ``positions`` ``[F, 21, 3]`` (Y-up scene units at ``fps``) by ``frames`` -> ``[frames, 21, 3]``."""
    return extend_positions(generator_from_prefs(prefs), positions, fps, frames)


def inbetween(prefs, before: np.ndarray, after: np.ndarray, fps: float, frames: int) -> np.ndarray:
    """The ``frames`` frames ``[frames, 21, 3]`` between ``before`` and ``after`` ``[F, 21, 3]`` (Y-up
    scene units at ``fps``), made by the main model."""
    return inbetween_positions(generator_from_prefs(prefs), before, after, fps, frames)


def familiarity(prefs, positions: np.ndarray, fps: float):
    """How familiar ``positions`` ``[F, 21, 3]`` (Y-up scene units at ``fps``) are to the main model."""
    return clip_familiarity(generator_from_prefs(prefs), positions, fps)


def denoise_steps(prefs, positions: np.ndarray, fps: float, strength: float):
    """Denoised ``positions`` ``[F, 21, 3]`` (same space and frames), blended by ``strength``.
    A step generator (``model_core.inference.steps``): yields the fraction of the clip done as it goes."""
    engine = engine_from_prefs(prefs, denoiser_folder(prefs), "Denoise Model Folder")
    return (yield from denoise_positions_steps(engine, positions, fps, strength))


def follow_curve_steps(prefs, points: np.ndarray, cyclic: bool, fps: float, frames: int | None,
                       speed: float | None, context: np.ndarray | None = None, rest: np.ndarray | None = None):
    """Positions ``[frames, 21, 3]`` (Y-up scene units at ``fps``) walking the curve ``points`` ``[P, 3]``
    (Y-up) after ``context`` ``[F, 21, 3]``, or from a shipped seed sized like ``rest`` ``[21, 3]``, by the
    main model. A step generator (``model_core.inference.steps``): yields the fraction done after each model
    window."""
    follower = PathFollower(generator_from_prefs(prefs))
    return (yield from follow_curve_model_steps(follower, points, cyclic, fps, frames, speed, context, rest))
