"""One evaluation run over a data folder: prediction, long horizon and denoising,
each beside its baselines, as the JSON document ``scripts/evaluate.py`` writes."""

from __future__ import annotations

import time

import numpy as np

from .dataset import MotionData
from .features import positions_to_features
from .metrics import (
    HORIZONS_MS,
    add_noise,
    best_butterworth,
    floor_height,
    joint_speed,
    mpjpe_cm,
    pose_vectors,
    prediction_errors,
    rollout_report,
    segments,
)


def select_clips(data: MotionData, split: str) -> list:
    clips = data.clips if split == "all" else data.split(split)
    if not clips:
        raise ValueError(f"{data.root}: no clips in the {split!r} split (use --split all for a foreign folder)")
    return clips


def evaluate_prediction(engine, clips) -> dict:
    errors, windows = prediction_errors(engine, [c.positions for c in clips])
    seam = errors.pop("strnn_seam_blend")  # printed beside the table, not a key of the JSON document
    return {"horizons_ms": list(HORIZONS_MS), "mpjpe_cm": errors, "windows": windows, "strnn_seam_blend": seam}


def data_speed(clips, statistic=np.mean) -> float:
    """Mean (or another ``statistic`` of the) joint speed (m / frame) over the clips' frames."""
    return float(statistic(np.concatenate([joint_speed(c.positions) for c in clips])))


def pick_seed_windows(clips, count: int, length: int = 20) -> list[tuple[str, np.ndarray]]:
    """``count`` seeds spread evenly over the clips (sorted by name): (name, positions ``[length, J, 3]``)."""
    usable = sorted((c for c in clips if len(c.positions) >= 2 * length), key=lambda c: c.name)
    if not usable:
        raise ValueError(f"no clip has the {2 * length} frames a seed needs")
    picks = np.linspace(0, len(usable) - 1, count).round().astype(int)
    return [(usable[i].name, usable[i].positions[length:2 * length]) for i in picks]


def evaluate_long_horizon(engine, clips, frames: int, seeds: int, reference=None, log=print) -> dict:
    ref_clips = reference or clips
    speed, median = data_speed(ref_clips), data_speed(ref_clips, np.median)
    ref = np.concatenate([segments(pose_vectors(c.features)) for c in ref_clips if len(c.features) >= 40])
    chosen = pick_seed_windows(clips, seeds)
    by_name = {c.name: c.positions for c in clips}
    seed_feats = np.stack([positions_to_features(p)[0] for _, p in chosen])
    log(f"long horizon: {seeds} seeds x {frames} frames open loop")
    rollouts = engine.extrapolate(seed_feats, frames)
    block = min(1000, frames)
    reports = [rollout_report(r, p, speed, ref, block=block, median_speed=median, floor=floor_height(by_name[name]))
               for r, (name, p) in zip(rollouts, chosen)]
    take_speed = [float(joint_speed(by_name[name]).mean()) for name, _ in chosen]
    return {
        "frames": frames, "seeds": seeds,
        "exploded": int(sum(r.exploded for r in reports)),
        "frozen": int(sum(r.frozen for r in reports)),
        "speed_ratio_last_1000": [r.speed_ratio_last_1000 for r in reports],
        "d1nn_per_block": [r.d1nn_per_block for r in reports],
        "seed_clips": [name for name, _ in chosen],
        # each rollout's last-block speed against its seed's own take's mean joint speed
        "seed_take_speed_ratio": [r.speed_ratio_last_1000 * speed / t for r, t in zip(reports, take_speed)],
        "d1nn_drift": [_drift(r.d1nn_per_block) for r in reports],
        "feet": {key: [getattr(r.feet, key) if r.feet else float("nan") for r in reports]
                 for key in ("touch_fraction", "floor_offset_cm", "sink_cm")},
    }


def _drift(blocks: list[float]) -> float:
    """D_1nn of the last block over the first (nan with one block)."""
    return float(blocks[-1] / blocks[0]) if len(blocks) > 1 and blocks[0] > 0 else float("nan")


def evaluate_denoise(engine, clips, stds_cm, seed: int = 0) -> dict:
    usable = [c.positions for c in clips if len(c.positions) >= 2 * engine.m]
    out = {"std_cm": list(stds_cm), "mpjpe_cm": {"strnn": [], "butterworth_best": [], "noisy": []},
           "butterworth_cutoff_hz": [], "strnn_frames_per_s": []}
    for std in stds_cm:
        rng = np.random.default_rng(seed)
        noisy = [add_noise(p, std, rng) for p in usable]
        started = time.perf_counter()
        denoised = [engine.denoise_positions(n) for n in noisy]
        out["strnn_frames_per_s"].append(sum(map(len, noisy)) / (time.perf_counter() - started))
        strnn = np.concatenate([mpjpe_cm(d, c) for c, d in zip(usable, denoised)]).mean()
        bw, fc = best_butterworth(usable, noisy)
        raw = np.concatenate([mpjpe_cm(n, c) for c, n in zip(usable, noisy)]).mean()
        out["mpjpe_cm"]["strnn"].append(float(strnn))
        out["mpjpe_cm"]["butterworth_best"].append(bw)
        out["mpjpe_cm"]["noisy"].append(float(raw))
        out["butterworth_cutoff_hz"].append(fc)
    return out
