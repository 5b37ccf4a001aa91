"""The one place the add-on calls the model: load (cached) and run it on a clip.

:func:`run_extend`, :func:`run_inbetween`, :func:`run_loop`, :func:`run_familiarity`, :func:`run_denoise` and
:func:`run_follow_curve` (one verb per layer: ``run_*`` here) are the only model calls the operators
make, so a test can swap them for a stand-in.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
from collections import OrderedDict
from pathlib import Path

import bpy
import numpy as np

from ..model_core.inference.steps import drive
from ..model_core.io.checkpoint import DEFAULT_MODEL, default_denoiser
from ..model_core.ops.denoise import denoise_positions_steps, result_familiarity
from ..model_core.ops.extend import extend_positions, first_window, following
from ..model_core.ops.familiarity import clip_familiarity
from ..model_core.ops.follow import PathFollower, follow_curve_positions_steps
from ..model_core.ops.inbetween import inbetween_positions
from ..model_core.ops.loop import loop_positions

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


def load_engine(folder: str = "", engine: str = "NUMPY", setting: str = "Model Folder"):
    """The inference engine for ``folder`` ('' = bundled), kept loaded across calls (the main model and
    the denoiser; an older choice is let go); errors name the preference ``setting`` that picks the folder."""
    path = model_path(folder, setting)
    key = (str(path), engine, _stamp(path))
    if key not in _CACHE:
        try:
            if engine == "TORCH":
                from ..model_core.inference.torch_engine import TorchEngine as Engine
            else:
                from ..model_core.inference.engine import Engine
            if len(_CACHE) >= 2:
                _CACHE.pop(next(iter(_CACHE)))
            _CACHE[key] = Engine.load(path)
        except (ImportError, ValueError, OSError, KeyError) as e:
            raise EngineError(f"Could not load the model at {path} ({setting}): {e}") from e
    return _CACHE[key]


def _stamp(path: Path) -> int:
    """When the weights in ``path`` last changed (a model retrained into the same folder is reloaded)."""
    try:
        return (path / "model.safetensors").stat().st_mtime_ns
    except OSError:
        return 0


@contextlib.contextmanager
def threads(prefs):
    """The Threads preference for the length of one model call, the process's thread counts restored
    after (0: as Blender runs)."""
    count = prefs.threads if prefs is not None else 0
    with contextlib.ExitStack() as stack:
        if count > 0:
            if prefs.engine == "TORCH":
                import torch

                stack.callback(torch.set_num_threads, torch.get_num_threads())
                torch.set_num_threads(count)
            try:
                from threadpoolctl import threadpool_limits
            except ImportError:  # NumPy's BLAS keeps its own thread count
                pass
            else:
                stack.enter_context(threadpool_limits(count))
        yield


def engine_from_prefs(prefs, folder: str | None = None, setting: str = "Model Folder"):
    """The engine the add-on preferences ask for (defaults when ``prefs`` is None), for the
    Model Folder or for ``folder`` (picked by the preference ``setting``)."""
    if folder is None:
        folder = main_folder(prefs)
    return load_engine(folder, prefs.engine if prefs is not None else "NUMPY", setting)


def generator_from_prefs(prefs):
    """The main model's engine, refused with an :class:`EngineError` if it can only denoise."""
    engine = engine_from_prefs(prefs)
    try:
        engine.ckpt.require_generator("extend a clip")
    except ValueError as e:
        raise EngineError(f"{e} (Preferences > Add-ons > STRNN Motion > Model Folder)") from e
    return engine


# The last few model results, by what went in: a redo that changes only what comes after the model
# (Result, Simplify Keys, Foot Lock, Scene Range, ...) or a second run on the same frames does not run
# the model again. Results are returned as copies, so nothing downstream can change a kept one.
_RESULTS: OrderedDict[tuple, object] = OrderedDict()
KEEP_RESULTS = 4


def _fingerprint(value):
    """An array as its shape, type and a hash of its bytes (read in place, not copied); anything else as is."""
    if isinstance(value, np.ndarray):
        data = np.ascontiguousarray(value)
        return value.shape, str(value.dtype), hashlib.blake2b(data.data, digest_size=16).hexdigest()
    return value


def _key(operation: str, engine, *inputs) -> tuple:
    """What a result depends on: the operation, the model (folder, engine kind, weights' time) and the inputs."""
    model = next(key for key, loaded in _CACHE.items() if loaded is engine)
    return (operation, model, *(_fingerprint(v) for v in inputs))


def _copy(result):
    """Arrays copied (also inside tuples); other results (read-only records) as they are."""
    if isinstance(result, tuple):
        return tuple(_copy(r) for r in result)
    return np.array(result, copy=True) if isinstance(result, np.ndarray) else result


def forget_results() -> None:
    """Drop the kept model results, so the next call runs the model (a benchmark's repeated runs)."""
    _RESULTS.clear()


def _kept_steps(key: tuple, make_steps):
    """The result of the step generator ``make_steps()``, or the one kept for ``key`` without running it."""
    if key in _RESULTS:
        _RESULTS.move_to_end(key)
        return _copy(_RESULTS[key])
    result = yield from make_steps()
    _RESULTS[key] = _copy(result)
    while len(_RESULTS) > KEEP_RESULTS:
        _RESULTS.popitem(last=False)
    return result


def _kept(key: tuple, compute):
    """``compute()``, or the result kept for ``key``."""
    def steps():
        return compute()
        yield  # a generator with no steps

    return drive(_kept_steps(key, steps))


def bpy_path(path: str) -> str:
    """Resolve Blender's ``//`` relative paths."""
    if path.startswith("//"):
        return bpy.path.abspath(path)
    return path


def run_extend(prefs, positions: np.ndarray, fps: float, frames: int, memory: np.ndarray | None = None,
               floor: float | None = None) -> np.ndarray:
    """Continue ``positions`` ``[F, 21, 3]`` (Y-up scene units at ``fps``) by ``frames`` -> ``[frames, 21, 3]``;
    ``memory``: more of the clip, ending where ``positions`` ends, that long continuations lean on; ``floor``: the
    height the new frames' feet stay out of (:func:`extend.extend_positions`)."""
    engine = generator_from_prefs(prefs)
    with threads(prefs):
        return _kept(_key("extend", engine, positions, fps, frames, memory, floor),
                     lambda: extend_positions(engine, positions, fps, frames, memory, floor))


def run_first_window(prefs, positions: np.ndarray, fps: float, memory: np.ndarray | None = None):
    """How much of its motion Extend's first window after ``positions`` keeps (:func:`extend.first_window`)."""
    engine = generator_from_prefs(prefs)
    with threads(prefs):
        return _kept(_key("first_window", engine, positions, fps, memory),
                     lambda: first_window(engine, positions, fps, memory))


def run_following(prefs, memory: np.ndarray, fps: float, frames: int):
    """What *Follow the Clip* has to follow in ``memory`` for an extension of ``frames`` (:func:`extend.following`;
    None where the extension ends before it plays on through the clip)."""
    return following(generator_from_prefs(prefs), memory, fps, frames)


def run_inbetween(prefs, before: np.ndarray, after: np.ndarray, fps: float, frames: int,
                  follow_take: bool = True) -> np.ndarray:
    """The ``frames`` frames ``[frames, 21, 3]`` between ``before`` and ``after`` ``[F, 21, 3]`` (Y-up
    scene units at ``fps``), made by the main model; ``follow_take``: leaning on the rest of ``before`` and
    ``after`` where the take did what the gap must."""
    engine = generator_from_prefs(prefs)
    with threads(prefs):
        return _kept(_key("inbetween", engine, before, after, fps, frames, follow_take),
                     lambda: inbetween_positions(engine, before, after, fps, frames, follow_take))


def run_loop(prefs, positions: np.ndarray, fps: float, blend: int, match: bool = True,
             lead: np.ndarray | None = None):
    """The stretch ``positions`` ``[F, 21, 3]`` (Y-up scene units at ``fps``) made into a cycle by the main model
    (:func:`loop.loop_positions`: ``blend`` frames before its seam made again; ``match``: the seam where the pose
    comes round again; ``lead``: the take before the stretch)."""
    engine = generator_from_prefs(prefs)
    with threads(prefs):
        return _kept(_key("loop", engine, positions, fps, blend, match, lead),
                     lambda: loop_positions(engine, positions, fps, blend, match, lead=lead))


def run_familiarity(prefs, positions: np.ndarray, fps: float):
    """How familiar ``positions`` ``[F, 21, 3]`` (Y-up scene units at ``fps``) are to the main model."""
    engine = generator_from_prefs(prefs)
    with threads(prefs):
        return _kept(_key("familiarity", engine, positions, fps), lambda: clip_familiarity(engine, positions, fps))


def run_denoised_familiarity(prefs, positions: np.ndarray, denoised: np.ndarray, fps: float, strength: float):
    """How familiar the motion of ``positions`` is to the main model, judged on what Denoise made of it
    (``denoised``, blended by ``strength``: :func:`denoise.result_familiarity`); None for strength 0. The main
    model judges (it carries the calibration); one that can only denoise judges too, without a note. None where
    the Model Folder holds no model Denoise could load: the judgement is not worth failing a Denoise over."""
    try:
        engine = engine_from_prefs(prefs)
    except EngineError:
        return None
    with threads(prefs):
        return _kept(_key("denoised_familiarity", engine, positions, denoised, fps, strength),
                     lambda: result_familiarity(engine, positions, denoised, fps, strength))


def run_denoise(prefs, positions: np.ndarray, fps: float, strength: float):
    """Denoised ``positions`` ``[F, 21, 3]`` (same space and frames), blended by ``strength``.
    A step generator (``model_core.inference.steps``): yields the fraction of the clip done as it goes."""
    engine = engine_from_prefs(prefs, denoiser_folder(prefs), "Denoise Model Folder")
    with threads(prefs):
        return (yield from _kept_steps(_key("denoise", engine, positions, fps, strength),
                                       lambda: denoise_positions_steps(engine, positions, fps, strength)))


def run_follow_curve(prefs, points: np.ndarray, cyclic: bool, fps: float, frames: int | None,
                       speed: float | None, context: np.ndarray | None = None, rest: np.ndarray | None = None):
    """Positions ``[frames, 21, 3]`` (Y-up scene units at ``fps``) walking the curve ``points`` ``[P, 3]``
    (Y-up) after ``context`` ``[F, 21, 3]``, or from a shipped seed sized like ``rest`` ``[21, 3]``, by the
    main model. A step generator (``model_core.inference.steps``): yields the fraction done after each model
    window."""
    engine = generator_from_prefs(prefs)
    follower = PathFollower(engine)
    key = _key("follow", engine, points, cyclic, fps, frames, speed, context, rest)
    with threads(prefs):
        return (yield from _kept_steps(key, lambda: follow_curve_positions_steps(
            follower, points, cyclic, fps, frames, speed, context, rest)))
