"""Path-following evaluation (``scripts/evaluate.py --paths``): walking seeds of the chosen
clips follow the fixed paths of :func:`paths.evaluation_paths`; path error, foot skate and
knee pops before and after foot lock, bone-length error, and the synthesis speed.

Contacts for skate and foot lock are detected on the generated motion by the rule that
labels the training data (:func:`features.detect_contacts`: heel or toe near its lowest
height and slower than 0.6 m/s), as the Foot Lock operator does in Blender; the skate on
the model's own contact channels is reported beside it (``foot_skate_model_contacts_cm``).
Positions are metres, Y-up, 30 fps.
"""

from __future__ import annotations

import time

import numpy as np

from ..motion.conventions import MODEL_FPS
from ..ops.follow import PathFollower, follow_path
from ..ops.footlock import contacts_from_features, detect_foot_contacts, foot_lock, foot_skate_cm, knee_pops
from ..ops.paths import Path, evaluation_paths, path_errors_cm
from .evaluation import pick_seed_windows
from .metrics import bone_lengths_of


def walking_seeds(clips, count: int) -> list[tuple[str, np.ndarray]]:
    """``count`` seed windows (name, positions ``[20, 21, 3]``) from clips named like walking."""
    walks = [c for c in clips if "walk" in c.name.lower()]
    return pick_seed_windows(walks or clips, count)


def bone_error(pos: np.ndarray, seed: np.ndarray) -> float:
    """Mean relative deviation of bone lengths of ``pos`` ``[F, J, 3]`` from the seed's (median)."""
    rest = np.median(bone_lengths_of(seed), 0)
    return float(np.abs(bone_lengths_of(pos) / rest - 1.0).mean())


def ground_speed(pos: np.ndarray) -> float:
    """Mean ground speed (m/s at 30 fps) of the root of positions ``[F, J, 3]``."""
    return float(np.linalg.norm(np.diff(pos[:, 0, [0, 2]], axis=0), axis=-1).mean() * MODEL_FPS)


def share_walked(root: np.ndarray, path: Path) -> float:
    """How much of ``path`` (its length, or one lap) a root trajectory ``[F, 3]`` covered: the arc length of
    its last frame's match, followed along the walk as :func:`paths.path_errors_cm` does, over the length."""
    s = path.project(root[0, [0, 2]], 0.0, 1.0)
    for p in root[:, [0, 2]]:
        s = path.project(p, s - 0.05, s + 1.0)
    return float(min(s / path.length, 1.0))


def one_run(follower: PathFollower, seed: np.ndarray, path: Path) -> dict:
    """All figures of one seed on one path."""
    pos, feats = follow_path(follower, seed, path)
    contacts, claimed = detect_foot_contacts(pos), contacts_from_features(feats)
    locked = foot_lock(pos, contacts=contacts)
    mean, worst = path_errors_cm(pos[:, 0], path)
    return {"mean_cm": mean, "max_cm": worst, "frames": len(pos),
            "speed_ratio": ground_speed(pos) / max(ground_speed(seed), 1e-6),
            "end_reached": share_walked(pos[:, 0], path),
            "skate_raw": foot_skate_cm(pos, contacts), "skate_locked": foot_skate_cm(locked, contacts),
            "claimed_raw": foot_skate_cm(pos, claimed),
            "claimed_locked": foot_skate_cm(foot_lock(pos, contacts=claimed), claimed),
            "bone_error": bone_error(locked, seed), "pops_raw": knee_pops(pos), "pops_locked": knee_pops(locked)}


def evaluate_paths(follower: PathFollower, clips, seeds: int = 3, log=print) -> dict:
    """The ``"paths"`` JSON section: per path, means over the seeds (max_cm: the worst seed;
    knee pops: summed over seeds), plus the seeds used and the synthesis speed."""
    chosen = walking_seeds(clips, seeds)
    out = {"names": [], "mean_cm": [], "max_cm": [], "foot_skate_cm": {"raw": [], "locked": []},
           "bone_error": [], "knee_pops": {"raw": [], "locked": []}, "speed_ratio": [], "end_reached": [],
           "foot_skate_model_contacts_cm": {"raw": [], "locked": []}}
    frames, seconds = 0, 0.0
    for name, (points, cyclic) in evaluation_paths().items():
        path = Path(points, cyclic)
        t0 = time.perf_counter()
        runs = [one_run(follower, seed, path) for _, seed in chosen]
        seconds += time.perf_counter() - t0
        frames += sum(r["frames"] for r in runs)
        out["names"].append(name)
        out["mean_cm"].append(float(np.mean([r["mean_cm"] for r in runs])))
        out["max_cm"].append(float(np.max([r["max_cm"] for r in runs])))
        out["foot_skate_cm"]["raw"].append(float(np.mean([r["skate_raw"] for r in runs])))
        out["foot_skate_cm"]["locked"].append(float(np.mean([r["skate_locked"] for r in runs])))
        for key in ("raw", "locked"):
            out["foot_skate_model_contacts_cm"][key].append(float(np.mean([r[f"claimed_{key}"] for r in runs])))
        out["bone_error"].append(float(np.mean([r["bone_error"] for r in runs])))
        out["speed_ratio"].append(float(np.mean([r["speed_ratio"] for r in runs])))
        out["end_reached"].append(float(np.min([r["end_reached"] for r in runs])))
        out["knee_pops"]["raw"].append(int(sum(r["pops_raw"] for r in runs)))
        out["knee_pops"]["locked"].append(int(sum(r["pops_locked"] for r in runs)))
        log(f"path {name}: {len(runs)} seeds, mean {out['mean_cm'][-1]:.1f} cm, max {out['max_cm'][-1]:.1f} cm")
    out["seed_clips"] = [name for name, _ in chosen]
    out["frames_per_second"] = frames / max(seconds, 1e-9)  # synthesis + foot lock + metrics, one thread
    return out


def synthesis_speed(follower: PathFollower, seed: np.ndarray, frames: int = 1000) -> float:
    """Generated frames per second of curve synthesis along a circle of radius 2 m for ``frames`` frames."""
    points, cyclic = evaluation_paths()["circle"]
    follow_path(follower, seed, Path(points, cyclic), frames=follower.n)  # warm up
    t0 = time.perf_counter()
    follow_path(follower, seed, Path(points, cyclic), frames=frames)
    return frames / (time.perf_counter() - t0)
