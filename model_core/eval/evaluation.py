"""One evaluation run over a data folder: prediction, long horizon and denoising,
each beside its baselines, as the JSON document ``scripts/evaluate.py`` writes."""

from __future__ import annotations

import functools
import time
from pathlib import Path

import numpy as np

from ..io.bvh import read_bvh
from ..model.dataset import MotionData, fps_override
from ..motion.conventions import GROUND_AXES, MODEL_FPS
from ..motion.features import floor_height, positions_to_features
from ..motion.noise import add_rotation_jitter
from ..ops.denoise import denoise_positions
from ..ops.extend import MEMORY_S, clip_floor, extend_positions
from ..rig.rigs import canonical_clip
from .intervals import DRAWS, LEVEL, paired_gap
from .metrics import (
    CONTEXT,
    HORIZONS_MS,
    add_noise,
    add_pops,
    airborne_fraction,
    best_butterworth,
    best_median,
    horizon_frames,
    joint_speed,
    mpjpe_cm,
    pose_vectors,
    rollout_report,
    segments,
    still_frames,
    upsample,
    window_errors,
    window_starts,
    window_takes,
)


def select_clips(data: MotionData, split: str, group: str | None = None) -> list:
    """The clips of a split (``all``: every clip), or of a held-out ``group`` when one is named."""
    if group:
        clips = data.group(group)
        if not clips:
            raise ValueError(f"{data.root}: no clips of the held-out group {group!r}")
        return clips
    clips = data.clips if split == "all" else data.split(split)
    if not clips:
        raise ValueError(f"{data.root}: no clips in the {split!r} split (use --split all for a foreign folder)")
    return clips


def evaluate_prediction(engine, clips, baselines: dict | None = None) -> dict:
    """Prediction MPJPE (cm) per horizon of STRNN, the simple baselines, the ``baselines``
    ``{name: engine}`` models and STRNN as Extend delivers it: ``strnn_as_extend``, each window's take up to
    the context's end as the clip (:func:`as_extend_predictions`), and ``strnn_as_extend_context_only``, a clip of
    the 20 context frames alone (the seam blend on the model's own continuation); what the first is made of
    (``as_extend_parts``, :func:`error_parts`); and how sure its lead or lag on every other row is
    (``as_extend_against``: :func:`intervals.paired_gap` over the same windows, whole takes resampled)."""
    positions = [c.positions for c in clips]
    errors = window_errors(engine, positions, extra_engines=baselines)
    errors["strnn_as_extend_context_only"] = errors.pop("strnn_seam_blend")
    last, new, truth = as_extend_predictions(engine, positions)
    idx = [k - 1 for k in horizon_frames(HORIZONS_MS)]
    errors["strnn_as_extend"] = mpjpe_cm(new[:, idx], truth[:, idx])
    takes = window_takes([np.asarray(p) for p in positions], CONTEXT + max(horizon_frames(HORIZONS_MS)))
    against = {name: paired_gap(errors["strnn_as_extend"], e, takes)
               for name, e in errors.items() if name != "strnn_as_extend"}
    return {"horizons_ms": list(HORIZONS_MS), "mpjpe_cm": {name: [float(v) for v in e.mean(0)]
                                                          for name, e in errors.items()},
            "windows": len(takes), "as_extend_parts": error_parts(last, new, truth),
            "as_extend_against": against,
            "intervals": {"level": LEVEL, "draws": DRAWS, "takes": int(len(np.unique(takes))),
                          "resampled": "whole takes, each window weighed by how often its take is drawn"}}


def as_extend_predictions(engine, clips: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Extend Clip (:func:`extend.extend_positions`, *Follow the Clip* on) on the windows
    :func:`metrics.prediction_windows` makes, each clip being the take up to the context's end (at most
    :data:`extend.MEMORY_S` seconds of it): what an animator gets extending the take from that frame. Returns
    each window's last context frame ``[W, J, 3]``, its continuation and the take's ``[W, horizon, J, 3]``."""
    horizon, most = max(horizon_frames(HORIZONS_MS)), int(MEMORY_S * MODEL_FPS)
    last, new, truth = [], [], []
    for pos, s in window_starts([np.asarray(p, np.float64) for p in clips], CONTEXT + horizon):
        end = s + CONTEXT
        clip = pos[max(0, end - most):end]
        new.append(extend_positions(engine, clip[-CONTEXT:], MODEL_FPS, horizon,
                                    memory=clip if len(clip) > CONTEXT else None))
        last.append(pos[end - 1])
        truth.append(pos[end:end + horizon])
    return np.stack(last), np.stack(new), np.stack(truth)


def horizon_errors(new: np.ndarray, truth: np.ndarray) -> list[float]:
    """MPJPE (cm) at each of :data:`HORIZONS_MS` of continuations ``[W, F, J, 3]`` against the take's."""
    idx = [k - 1 for k in horizon_frames(HORIZONS_MS)]
    return [float(v) for v in mpjpe_cm(new[:, idx], truth[:, idx]).mean(0)]


# A window *moves* when the take's hips travel this far over the ground in the horizon (20 cm in a second).
MOVING_M = 0.2


def error_parts(last: np.ndarray, new: np.ndarray, truth: np.ndarray) -> dict:
    """What Extend's error (:func:`as_extend_predictions`) is made of: the MPJPE per horizon with the take's own
    track of the hips over the floor under the continuation's pose (``true_track_cm``: the error of the pose
    alone) and with the take's pose on the continuation's track (``true_pose_cm``: of the track alone); over the
    windows that move (the hips travel :data:`MOVING_M` or more), the median of how far the continuation travels
    along the take's way over the horizon against the take (``travel_ratio``: under 1, it slows down)."""
    ground = list(GROUND_AXES)
    on_ground = np.isin(np.arange(3), ground)
    track = lambda p: p[:, :, :1] * on_ground  # the hips' place on the ground, under every joint
    way = truth[:, -1, 0, ground] - last[:, 0, ground]
    moving = np.linalg.norm(way, axis=-1) >= MOVING_M
    along = ((new[moving, -1, 0][:, ground] - last[moving, 0][:, ground]) * way[moving]).sum(-1)
    return {"true_track_cm": horizon_errors(new - track(new) + track(truth), truth),
            "true_pose_cm": horizon_errors(truth - track(truth) + track(new), truth),
            "moving_windows": int(moving.sum()),
            "travel_ratio": float(np.median(along / (way[moving] ** 2).sum(-1))) if moving.any() else None}


def data_speed(clips, statistic=np.mean) -> float:
    """Mean (or another ``statistic`` of the) joint speed (m / frame) over the clips' frames."""
    return float(statistic(np.concatenate([joint_speed(c.positions) for c in clips])))


def pick_seed_windows(clips, count: int, length: int = 20) -> list[tuple[str, np.ndarray]]:
    """``count`` seeds spread evenly over the clips (sorted by name), each clip at most once (so fewer than
    ``count`` where there are fewer clips: a seed twice is the same rollout twice): (name, positions
    ``[length, J, 3]``)."""
    usable = sorted((c for c in clips if len(c.positions) >= 2 * length), key=lambda c: c.name)
    if not usable:
        raise ValueError(f"no clip has the {2 * length} frames a seed needs")
    picks = np.unique(np.linspace(0, len(usable) - 1, count).round().astype(int))
    return [(usable[i].name, usable[i].positions[length:2 * length]) for i in picks]


def evaluate_long_horizon(engine, clips, frames: int, seeds: int, reference=None, log=print) -> dict:
    """Long rollouts of ``frames`` frames from ``seeds`` seeds spread over the clips, judged seed by seed
    (:func:`metrics.rollout_report`): the model's own open loop from each seed's 20 frames (the top-level keys),
    and under ``as_extend`` Extend Clip as it ships (:func:`extend.extend_positions`, *Follow the Clip* on), each
    seed's take, its first :data:`extend.MEMORY_S` seconds at most, the clip it extends: what an animator gets
    extending the take. Speeds are against the seed's whole take (``seed_take_speed_ratio``); ``as_extend`` also
    gives the clip's last second against it (``clip_end_speed_ratio``: under 1, the clip comes to rest), and judges
    the feet over the floor Extend keeps them out of, the clip's own where it ends (:func:`extend.clip_floor`).
    ``frozen`` counts the rollouts that hold still (:func:`metrics.still_frames`) for 2 s or more and longer than
    their seed's take ever does; ``still_frames`` and ``take_still_frames`` give both runs seed by seed."""
    ref_clips = reference or clips
    speed, median = data_speed(ref_clips), data_speed(ref_clips, np.median)
    ref = np.concatenate([segments(pose_vectors(c.features)) for c in ref_clips if len(c.features) >= 40])
    chosen = pick_seed_windows(clips, seeds, length=max(20, engine.m))  # as many frames as the model reads
    by_name = {c.name: c.positions for c in clips}
    seed_feats = np.stack([positions_to_features(p)[0] for _, p in chosen])
    log(f"long horizon: {len(chosen)} seeds x {frames} frames open loop")
    # as Extend continues a clip: stances settled, the feet kept out of the floor the seed stands on
    rollouts = engine.extrapolate(seed_feats, frames, settle=True, floor=np.array([floor_height(p) for _, p in chosen]))
    judge = functools.partial(_judge_rollouts, by_name=by_name, speed=speed, median=median, ref=ref)
    take_floors = [floor_height(by_name[name]) for name, _ in chosen]
    out = {"frames": frames, "seeds": len(chosen)} | judge(rollouts, chosen, take_floors)
    log(f"long horizon: {len(chosen)} seeds x {frames} frames as Extend, following the clip")
    most, second = int(MEMORY_S * MODEL_FPS), int(MODEL_FPS)
    takes = [(name, np.asarray(by_name[name][:most], np.float64)) for name, _ in chosen]
    extended = [positions_to_features(extend_positions(engine, take[-CONTEXT:], MODEL_FPS, frames, memory=take))[0]
                for _, take in takes]
    # judged on the floor Extend keeps the feet out of: the clip's own where it ends (a capture's floor can drift)
    out["as_extend"] = judge(extended, [(name, take[-CONTEXT:]) for name, take in takes],
                             [clip_floor(take, MODEL_FPS) for _, take in takes]) | {
        "clip_frames": [len(take) for _, take in takes],
        "clip_end_speed_ratio": [float(joint_speed(take[-second - 1:]).mean() / joint_speed(by_name[name]).mean())
                                 for name, take in takes]}
    return out


def _judge_rollouts(rollouts, chosen, floors: list[float], by_name: dict, speed: float, median: float,
                    ref: np.ndarray) -> dict:
    """The per-seed figures of :func:`evaluate_long_horizon` for rollouts (raw features ``[N, C]`` each) from the
    seeds ``chosen`` ((take name, seed positions) each) over their ``floors`` (heights), against the data's mean and
    ``median`` joint ``speed`` and its D_1nn reference segments ``ref``; the share of frames with both feet in the
    air is given beside the seed's take's over the same floor."""
    block = min(1000, min(len(r) for r in rollouts))
    reports = [rollout_report(r, p, speed, ref, block=block, median_speed=median, floor=floor)
               for r, (name, p), floor in zip(rollouts, chosen, floors)]
    take_speed = [float(joint_speed(by_name[name]).mean()) for name, _ in chosen]
    # a rollout is frozen where it holds still for 2 s or more and longer than its seed's take ever does (a raised
    # hand the take holds up for 2.4 s, held as long, is the take's motion, not a rollout that died)
    take_still = [still_frames(by_name[name], median) for name, _ in chosen]
    return {
        "exploded": int(sum(r.exploded for r in reports)),
        "frozen": int(sum(r.frozen and r.still_frames > t for r, t in zip(reports, take_still))),
        "still_frames": [r.still_frames for r in reports],
        "take_still_frames": take_still,
        "speed_ratio_last_1000": [r.speed_ratio_last_1000 for r in reports],
        "d1nn_per_block": [r.d1nn_per_block for r in reports],
        "seed_clips": [name for name, _ in chosen],
        # each rollout's last-block speed against its seed's own take's mean joint speed
        "seed_take_speed_ratio": [r.speed_ratio_last_1000 * speed / t for r, t in zip(reports, take_speed)],
        "d1nn_drift": [_drift(r.d1nn_per_block) for r in reports],
        "feet": {key: [getattr(r.feet, key) if r.feet else float("nan") for r in reports]
                 for key in ("touch_fraction", "floor_offset_cm", "sink_cm", "airborne_fraction", "skate_cm")}
        # the seed's own take in the air as often: a run's flight is not a walk turned into hops
        | {"take_airborne_fraction": [airborne_fraction(by_name[name], f) for (name, _), f in zip(chosen, floors)]},
    }


def _drift(blocks: list[float]) -> float:
    """D_1nn of the last block over the first (nan with one block)."""
    return float(blocks[-1] / blocks[0]) if len(blocks) > 1 and blocks[0] > 0 else float("nan")


def evaluate_denoise(engine, clips, stds_cm, seed: int = 0, fps: float = MODEL_FPS, root=None) -> dict:
    """Denoise as the product runs it (:func:`denoise.denoise_positions`, at ``fps``: clips are
    brought to it by :func:`_at_rate`, from their files under ``root`` where they were captured that
    fast) against the best Butterworth filter, at each Gaussian noise std in cm (0: the clean take,
    how much Denoise changes it)."""
    return _noise_levels(engine, clips, "std_cm", stds_cm, add_noise, seed, fps, root)


def evaluate_rotation_jitter(engine, clips, degrees, seed: int = 0, fps: float = MODEL_FPS, root=None) -> dict:
    """:func:`evaluate_denoise` with Gaussian jitter of each of ``degrees`` on every joint's rotation
    channels (:func:`motion.noise.add_rotation_jitter`) instead of on its position."""
    return _noise_levels(engine, clips, "deg", degrees, add_rotation_jitter, seed, fps, root)


def _noise_levels(engine, clips, key: str, levels, corrupt, seed: int, fps: float, root) -> dict:
    """Denoise, the best Butterworth and the input, scored at each level of ``corrupt(pos, level, rng)``."""
    usable, captured = _at_rate([c for c in clips if len(c.positions) >= 2 * engine.m], fps, root)
    out = {key: list(levels), "mpjpe_cm": {"strnn": [], "butterworth_best": [], "noisy": []},
           "butterworth_cutoff_hz": [], "strnn_frames_per_s": [], "fps": fps, "clips": len(usable),
           "clips_captured_at_fps": captured}
    for level in levels:
        rng = np.random.default_rng(seed)
        noisy = [corrupt(p, level, rng) for p in usable]
        _score(out, engine, usable, noisy, fps)
    return out


def evaluate_pops(engine, clips, rate: float, seed: int = 0, fps: float = MODEL_FPS, root=None) -> dict:
    """Denoise against the best Butterworth and the best median filter on clips where ``rate`` of
    the joint-frames jump 10 to 30 cm for one frame (as from a marker swap)."""
    usable, captured = _at_rate([c for c in clips if len(c.positions) >= 2 * engine.m], fps, root)
    rng = np.random.default_rng(seed)
    noisy = [add_pops(p, rate, rng) for p in usable]
    out = {"rate": rate, "mpjpe_cm": {"strnn": [], "butterworth_best": [], "median_best": [], "noisy": []},
           "butterworth_cutoff_hz": [], "median_frames": [], "strnn_frames_per_s": [], "fps": fps,
           "clips": len(usable), "clips_captured_at_fps": captured}
    _score(out, engine, usable, noisy, fps)
    err, size = best_median(usable, noisy)
    out["mpjpe_cm"]["median_best"].append(err)
    out["median_frames"].append(size)
    out["mpjpe_cm"] = {k: v[0] for k, v in out["mpjpe_cm"].items()}
    return out


def _score(out: dict, engine, clean: list, noisy: list, fps: float) -> None:
    """Append Denoise's, the best Butterworth's and the input's MPJPE (cm) to ``out``."""
    started = time.perf_counter()
    denoised = [denoise_positions(engine, n, fps) for n in noisy]
    out["strnn_frames_per_s"].append(sum(map(len, noisy)) / (time.perf_counter() - started))
    bw, fc = best_butterworth(clean, noisy, fps=fps)
    for key, value in (("strnn", _mpjpe(denoised, clean)), ("butterworth_best", bw), ("noisy", _mpjpe(noisy, clean))):
        out["mpjpe_cm"][key].append(float(value))
    out["butterworth_cutoff_hz"].append(fc)


def _mpjpe(pred: list, true: list) -> float:
    return float(np.concatenate([mpjpe_cm(p, t) for p, t in zip(pred, true)]).mean())


def _at_rate(clips: list, fps: float, root=None) -> tuple[list, int]:
    """(positions, how many were captured at that rate or faster): the positions of ``clips`` (read at
    the model's rate) brought to ``fps``. A clip captured at least that fast is re-read from its file
    under ``root`` at that rate (real capture, with its own detail and jitter); the others are
    upsampled by a Catmull-Rom cubic between their frames (smoother than any capture)."""
    if fps == MODEL_FPS:
        return [c.positions for c in clips], len(clips)
    out, captured = [], 0
    for clip in clips:
        native = _native(Path(root) / clip.name, fps) if root is not None else None
        captured += native is not None
        out.append(native if native is not None else upsample(clip.positions, fps / MODEL_FPS))
    return out, captured


@functools.cache
def _native(path: Path, fps: float) -> np.ndarray | None:
    """The take at ``path`` read at ``fps`` (read-only), or None when it was captured slower than that.
    Kept for the process: one evaluation scores noise, rotation jitter and pops on the same clips."""
    bvh = read_bvh(path, fps=fps_override(path))
    if bvh.fps < fps * 0.995:  # headers round: 0.016667 s is 60 fps
        return None
    pos = canonical_clip(bvh, fps)
    pos.setflags(write=False)
    return pos
