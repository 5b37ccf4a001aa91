"""The README's main demo as reusable steps (``scripts/demo.py`` is the command-line front end).

seed -> open-loop continuation (NumPy engine) -> figure-eight walk (torch path follower; skipped
without torch) -> foot lock (detected contacts) -> BVH, contact sheet, plots, and a .blend
(the ``bpy`` module; skipped without it). Beside them, :func:`denoise_check` jitters the
result and denoises it with the denoising model.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..inference.engine import Engine
from ..io.checkpoint import DEFAULT_MODEL, CheckpointError, default_denoiser, walk_seed_index
from ..motion.conventions import MODEL_FPS
from ..motion.features import features_to_positions, floor_height, heading, yaw_matrix
from ..ops.denoise import denoise_positions
from ..ops.footlock import detect_foot_contacts, foot_lock, foot_skate_cm
from ..ops.paths import Path as CurvePath, evaluation_paths
from .metrics import add_noise, mpjpe_cm

BASELINES = {"strnn": "STRNN", "zero_velocity": "zero velocity", "constant_velocity": "constant velocity"}


@dataclass
class DemoMotion:
    """Positions ``[F, 21, 3]`` (metres, Y-up, 30 fps) of each stage, and what was skipped."""

    seed_name: str
    seed_frames: int
    extended: np.ndarray  # seed + continuation
    walked: np.ndarray  # extended + figure-eight walk (== extended when the walk was skipped)
    locked: np.ndarray
    skate_before_cm: float
    skate_after_cm: float
    notes: list[str] = field(default_factory=list)


def seed_continuation(model: str | Path | None, seed_index: int | None, frames: int):
    """(positions ``[m + frames, 21, 3]`` of the seed and its continuation, seed name, m, engine);
    ``seed_index`` None picks the first walk (:func:`checkpoint.walk_seed_index`). Raises
    ``CheckpointError`` / ``ValueError`` with a readable message."""
    eng = Engine.load(model)
    seeds = eng.seeds
    if len(seeds) == 0:
        raise CheckpointError("the model folder ships no seed windows (seeds.npz)")
    if seed_index is None:
        seed_index = walk_seed_index(list(eng.ckpt.seed_names))
    if not 0 <= seed_index < len(seeds):
        raise ValueError(f"--seed {seed_index} is out of range: this model ships {len(seeds)} seeds, "
                         f"0 to {len(seeds) - 1}")
    seed = features_to_positions(seeds[seed_index])
    names = eng.ckpt.seed_names
    name = names[seed_index] if seed_index < len(names) else f"seed {seed_index}"
    new = eng.extend(seed, frames, settle=True, floor=floor_height(seed)) if frames > 0 else seed[:0]  # as Extend
    extended = np.concatenate([seed, new])
    return extended.astype(np.float32), name, len(seed), eng


def path_at_character(points: np.ndarray, context: np.ndarray) -> np.ndarray:
    """Ground points ``[P, 2]`` (x, z) of a path starting at the origin heading +Z, turned and moved
    so that it starts under the last frame's root of ``context`` ``[T, 21, 3]``, along its heading.
    The motion is left where it is (``follow_path(..., align=False)``): no jump at the seam."""
    pts = np.asarray(points, np.float64)
    turn = float(heading(np.asarray(context, np.float64))[-1] - CurvePath(pts).heading(0.0))
    p3 = np.stack([pts[:, 0], np.zeros(len(pts)), pts[:, 1]], -1)
    moved = np.einsum("ij,pj->pi", yaw_matrix(np.array(turn)), p3)
    root = np.asarray(context, np.float64)[-1, 0]
    return np.stack([moved[:, 0] + root[0], moved[:, 2] + root[2]], -1)


def figure_eight_walk(model: str | Path | None, context: np.ndarray, frames: int | None):
    """Positions ``[frames, 21, 3]`` walking the evaluation figure-eight after ``context`` (its last
    frames are the seed), and the path ``[P, 2]`` walked (the NumPy follower, as Follow Curve)."""
    from ..ops.follow import PathFollower, follow_path

    follower = PathFollower.load(model)
    points, cyclic = evaluation_paths()["figure_eight"]
    seed = np.asarray(context)[-follower.m:]
    points = path_at_character(points, seed)
    walked, _ = follow_path(follower, seed, CurvePath(points, cyclic), frames=frames, align=False)
    return walked, points


def build_motion(model: str | Path | None, seed_index: int | None, frames: int, path_frames: int | None,
                 walk: bool = True, log=print) -> DemoMotion:
    """Run the motion stages. ``path_frames`` None: one lap of the figure-eight; 0 or ``walk``
    False: no walk."""
    extended, name, m, _ = seed_continuation(model, seed_index, frames)
    walked, notes = extended, []
    if walk and path_frames != 0:
        new, _ = figure_eight_walk(model, extended, path_frames)
        walked = np.concatenate([extended, new]).astype(np.float32)
    contacts = detect_foot_contacts(walked)
    locked = foot_lock(walked, contacts=contacts)
    return DemoMotion(name, m, extended, walked, locked, foot_skate_cm(walked, contacts),
                      foot_skate_cm(locked, contacts), notes)


def denoise_check(positions: np.ndarray, std_cm: float = 3.0, model: str | Path | None = None,
                  seed: int = 0) -> tuple[float, float, str]:
    """Gaussian jitter of ``std_cm`` on every joint of ``positions`` ``[F, 21, 3]`` (metres, 30 fps),
    then the call Denoise makes on it (scale normalised to the model's, as for a user's rig):
    (mean joint error of the jittered, of the denoised motion, in cm; the model folder).
    ``model`` None: the bundled denoising model, else the default model."""
    folder = model or default_denoiser()
    engine = Engine.load(folder)
    noisy = add_noise(positions, std_cm, np.random.default_rng(seed))
    clean = denoise_positions(engine, noisy, MODEL_FPS)
    return float(mpjpe_cm(noisy, positions).mean()), float(mpjpe_cm(clean, positions).mean()), str(folder or "")


def plot_demo(path: str | Path, evaluation: dict | None, skate_before: float, skate_after: float) -> Path:
    """PNG with two panels: prediction MPJPE (cm) against horizon (ms) for STRNN and the baselines
    (``evaluation["prediction"]``, from the model's evaluation.json; a note when absent), and this
    demo's foot skate (cm / frame) before and after the foot lock. Returns the path."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, 4), dpi=110)
    FigureCanvasAgg(fig)
    ax1, ax2 = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.6, 1]})
    pred = (evaluation or {}).get("prediction") or {}
    horizons, curves = pred.get("horizons_ms"), pred.get("mpjpe_cm") or {}
    if horizons and curves:
        for key, values in curves.items():
            ax1.plot(horizons, values, marker="o", lw=2 if key == "strnn" else 1.2, label=BASELINES.get(key, key))
        ax1.legend()
    else:
        ax1.text(0.5, 0.5, "no prediction results\n(evaluation.json missing)", ha="center", va="center",
                 transform=ax1.transAxes)
    ax1.set(xlabel="prediction horizon (ms)", ylabel="MPJPE (cm)", title="Prediction error against horizon")
    ax1.grid(alpha=0.3)
    bars = ax2.bar(["before lock", "after lock"], [skate_before, skate_after], color=["tab:red", "tab:green"])
    ax2.bar_label(bars, fmt="%.2f")
    ax2.set(ylabel="foot skate (cm / frame)", title="Foot skate of this demo")
    ax2.grid(alpha=0.3, axis="y")
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp.png")
    fig.savefig(tmp)
    tmp.replace(path)
    return path


def load_evaluation(model: str | Path | None) -> dict | None:
    """The model folder's evaluation.json, or None."""
    folder = Path(model) if model else DEFAULT_MODEL
    try:
        return json.loads((folder / "evaluation.json").read_text())
    except (OSError, ValueError):
        return None
