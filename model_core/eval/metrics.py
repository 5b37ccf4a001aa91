"""The metrics of DESIGN.md, with their baselines. Positions are ``[..., 21, 3]`` metres
(Y-up); reported errors are centimetres."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import butter, filtfilt

from ..inference.engine import on_learnt_body
from ..motion.conventions import LAYOUT, MODEL_FPS, PARENTS, ROOT
from ..motion.features import (
    continue_positions,
    features_to_positions,
    lowest_foot,
    positions_to_features,
)
from ..motion.geometry import cubic_frames
from ..ops.familiarity import momentum_shares
from ..ops.footlock import foot_skate_cm
from ..ops.fusion import running_median
from ..ops.skeleton import join_clip

HORIZONS_MS = (80, 160, 320, 400, 560, 1000)
CONTEXT = 20
STRIDE = 15


def horizon_frames(ms=HORIZONS_MS, fps: float = MODEL_FPS) -> list[int]:
    """Frames after the context for each horizon: 80 ms -> 2, ..., 1000 ms -> 30."""
    return [int(round(t * fps / 1000.0)) for t in ms]


def mpjpe_cm(pred: np.ndarray, true: np.ndarray) -> np.ndarray:
    """Mean per-joint position error (cm) over the joint axis: ``[..., J, 3] -> [...]``."""
    return 100.0 * np.linalg.norm(pred - true, axis=-1).mean(-1)


def window_starts(clips: list[np.ndarray], frames: int, stride: int = STRIDE):
    """Every ``(clip, start)`` of a window of ``frames`` frames, stride ``stride``, clip by clip."""
    for pos in clips:
        for s in range(0, len(pos) - frames + 1, stride):
            yield pos, s


def prediction_windows(clips: list[np.ndarray], horizon: int, context: int = CONTEXT, stride: int = STRIDE):
    """Every (clip, start) with ``context + horizon`` frames, stride ``stride``: ``(contexts, futures)``
    as ``[W, context, J, 3]`` and ``[W, horizon, J, 3]``."""
    ctx, fut = [], []
    for pos, s in window_starts(clips, context + horizon, stride):
        ctx.append(pos[s:s + context])
        fut.append(pos[s + context:s + context + horizon])
    if not ctx:
        raise ValueError(f"no clip has the {context + horizon} frames a prediction window needs")
    return np.stack(ctx), np.stack(fut)


def reading_contexts(clips: list[np.ndarray], horizon: int, frames: int, context: int = CONTEXT,
                     stride: int = STRIDE) -> np.ndarray:
    """The contexts of :func:`prediction_windows`' windows as a model that reads ``frames`` frames gets them: the
    take's last ``frames`` frames up to each context's end ``[W, frames, J, 3]``, a window too near the take's
    start led in by the take's first frame (as a short clip is: :meth:`Engine.full_context`)."""
    out = []
    for pos, s in window_starts(clips, context + horizon, stride):
        end = s + context
        seen = pos[max(0, end - frames):end]
        out.append(np.concatenate([np.repeat(seen[:1], frames - len(seen), 0), seen]))
    return np.stack(out)


def _read(engine, clips: list[np.ndarray], ctx: np.ndarray, horizon: int) -> np.ndarray:
    """``ctx`` (the 20-frame contexts), or the longer ones of :func:`reading_contexts` for a model that reads more."""
    m = getattr(engine, "m", CONTEXT)
    return ctx if m <= ctx.shape[1] else reading_contexts(clips, horizon, m)


def extend_batch(engine, contexts: np.ndarray, frames: int, **kw) -> np.ndarray:
    """Continue each context ``[W, m, J, 3]`` by ``frames``: ``[W, frames, J, 3]``, as
    :meth:`Engine.extend` does one, in one batch (``kw``: :meth:`Engine.extrapolate`'s). Features are
    computed from the context alone (nothing of the future leaks in)."""
    seen, backs = zip(*(on_learnt_body(engine, c) for c in contexts))  # read on the model's body, as Extend does
    feats, starts = zip(*(positions_to_features(c) for c in seen))
    new = engine.extrapolate(np.stack(feats), frames, **kw)
    return np.stack([back(continue_positions(f, s, n)) for f, s, n, back in zip(feats, starts, new, backs)]
                    ).astype(np.float32)


def prediction_errors(engine, clips: list[np.ndarray], horizons_ms=HORIZONS_MS,
                      extra_engines: dict | None = None) -> tuple[dict, int]:
    """MPJPE (cm) at each horizon for STRNN, zero- and constant-velocity, each of ``extra_engines``
    ``{name: engine}`` (baselines, continued as STRNN is; a model that reads more than the windows' 20 context
    frames reads the take before them: :func:`reading_contexts`), and for STRNN with the seam blend Extend
    applies (``strnn_seam_blend``, :func:`seam.blend_seam`, with the clip's momentum where the motion is
    unfamiliar: :func:`familiarity.momentum_shares`, put back on the clip's bones: :func:`skeleton.join_clip`);
    and the window count. Each window's own errors: :func:`window_errors`."""
    errors = window_errors(engine, clips, horizons_ms, extra_engines)
    return {name: [float(v) for v in e.mean(0)] for name, e in errors.items()}, len(errors["strnn"])


def window_errors(engine, clips: list[np.ndarray], horizons_ms=HORIZONS_MS,
                  extra_engines: dict | None = None) -> dict[str, np.ndarray]:
    """The rows of :func:`prediction_errors` window by window: ``{name: [W, horizons]}`` (cm), the windows in
    the order :func:`window_takes` numbers their takes."""
    steps = horizon_frames(horizons_ms)
    ctx, fut = prediction_windows(clips, max(steps))
    last, prev = ctx[:, -1:], ctx[:, -2:-1]
    read = _read(engine, clips, ctx, max(steps))  # what STRNN reads of each window
    preds = {
        "strnn": extend_batch(engine, read, max(steps)),
        "zero_velocity": np.repeat(last, max(steps), 1),
        "constant_velocity": last + (last - prev) * np.arange(1, max(steps) + 1)[None, :, None, None],
    }
    preds |= {name: extend_batch(e, _read(e, clips, ctx, max(steps)), max(steps))
              for name, e in (extra_engines or {}).items()}
    shares = momentum_shares(engine, read)
    preds["strnn_seam_blend"] = np.stack([join_clip(c, p, k)[1:] for c, p, k in zip(ctx, preds["strnn"], shares)])
    idx = [s - 1 for s in steps]
    return {name: mpjpe_cm(p[:, idx], fut[:, idx]) for name, p in preds.items()}


def window_takes(clips: list[np.ndarray], frames: int, stride: int = STRIDE) -> np.ndarray:
    """Which of ``clips`` each window of :func:`window_starts` comes from ``[W]``: windows of one take err
    together, so a take is what an interval resamples (:func:`intervals.paired_gap`)."""
    return np.array([i for i, pos in enumerate(clips) for _ in window_starts([pos], frames, stride)], dtype=int)


# ------------------------------------------------------------------ long horizon
def joint_speed(pos: np.ndarray) -> np.ndarray:
    """Mean joint speed per frame (m / frame) ``[F - 1]`` of ``[F, J, 3]``."""
    return np.linalg.norm(np.diff(pos, axis=0), axis=-1).mean(-1)


def bone_lengths_of(pos: np.ndarray) -> np.ndarray:
    """Bone lengths ``[..., J - 1]`` of positions ``[..., J, 3]``."""
    return np.linalg.norm(pos[..., 1:, :] - pos[..., PARENTS[1:], :], axis=-1)


def longest_run(mask: np.ndarray) -> int:
    best = run = 0
    for v in mask:
        run = run + 1 if v else 0
        best = max(best, run)
    return best


@dataclass
class RolloutReport:
    exploded: bool
    frozen: bool  # still (:func:`still_frames`) for FREEZE_FRAMES frames or more
    speed_ratio_last_1000: float
    d1nn_per_block: list[float]
    feet: FeetReport | None = None
    still_frames: int = 0  # the longest run of frames held still (:func:`still_frames`)


# A rollout is still where its joints' mean speed is under FREEZE_SHARE of the data's median, frozen where it stays
# so for FREEZE_FRAMES frames (2 s) or more.
FREEZE_SHARE, FREEZE_FRAMES = 0.1, 60


def still_frames(pos: np.ndarray, median_speed: float) -> int:
    """The longest run of frames of ``pos`` ``[F, J, 3]`` whose joints' mean speed is under :data:`FREEZE_SHARE`
    of ``median_speed`` (m / frame): how long the motion holds still."""
    return longest_run(joint_speed(pos) < FREEZE_SHARE * median_speed) if len(pos) > 1 else 0


# Grounding of generated motion: in locomotion (the root faster than this) the lowest foot joint
# should come within FOOT_TOUCH_M of the floor at least once a second.
LOCOMOTION_SPEED = 0.3  # m / s
FOOT_TOUCH_M = 0.03
# Both feet at least this far above the floor: the body is in the air (a run's flight, a hop, a jump).
# Walks and standing takes of the data spend none of their frames so; runs about 30 %.
AIRBORNE_M = 0.05


@dataclass
class FeetReport:
    """How generated feet meet the floor (centimetres, relative to the floor of the seed's take)."""

    touch_fraction: float  # of the 1-second spans in locomotion, those where a foot touches the floor (nan: none)
    floor_offset_cm: float  # median height of the lowest foot joint over the floor: hovering > 0, sinking < 0
    sink_cm: float  # how far the lowest foot goes below the floor (99th percentile over frames, >= 0)
    airborne_fraction: float = float("nan")  # share of frames with both feet in the air
    # how far the heels and toes that the motion says are down (its contact channels) slide over the floor, cm a
    # frame (:func:`footlock.foot_skate_cm`): a stance that glides shows here (nan: no contact channels given)
    skate_cm: float = float("nan")


def airborne_fraction(pos: np.ndarray, floor: float) -> float:
    """Share of the frames of ``[F, J, 3]`` in which every heel and toe is more than :data:`AIRBORNE_M` above
    ``floor``: a walk that turns into hopping shows here while its speed and floor contacts look fine."""
    return float(np.mean(lowest_foot(pos) - floor > AIRBORNE_M))


def feet_report(pos: np.ndarray, floor: float, fps: float = MODEL_FPS,
                contacts: np.ndarray | None = None) -> FeetReport:
    """Grounding of positions ``[F, J, 3]`` against a ``floor`` height (metres); with the motion's own ``contacts``
    ``[F, 4]``, how far the feet it says are down slide."""
    height = lowest_foot(pos) - floor
    root = pos[:, ROOT][:, [0, 2]]
    speed = np.r_[np.linalg.norm(np.diff(root, axis=0), axis=-1) * fps, 0.0]
    second = int(round(fps))
    spans = [slice(a, a + second) for a in range(0, len(pos) - second + 1, second)]
    moving = [s for s in spans if speed[s].mean() > LOCOMOTION_SPEED]
    touch = float(np.mean([height[s].min() < FOOT_TOUCH_M for s in moving])) if moving else float("nan")
    skate = float("nan") if contacts is None else foot_skate_cm(pos, contacts)
    return FeetReport(touch, float(100 * np.median(height)), float(100 * max(0.0, np.percentile(-height, 99))),
                      airborne_fraction(pos, floor), skate)


def segments(local: np.ndarray, length: int = 40, stride: int = 10) -> np.ndarray:
    """Flattened segments ``[S, length * D]`` of per-frame pose vectors ``[F, D]``."""
    starts = range(0, len(local) - length + 1, stride)
    return np.stack([local[s:s + length].reshape(-1) for s in starts]) if len(local) >= length else \
        np.zeros((0, length * local.shape[1]), local.dtype)


def d1nn(gen: np.ndarray, ref: np.ndarray, length: int = 40) -> np.ndarray:
    """For each generated segment ``[S, L*D]``, the smallest mean per-frame squared L2 distance to a
    reference segment ``[R, L*D]``: ``[S]``."""
    g2 = (gen.astype(np.float64) ** 2).sum(1)[:, None]
    r2 = (ref.astype(np.float64) ** 2).sum(1)[None]
    best = np.full(len(gen), np.inf)
    for a in range(0, len(ref), 2048):
        d = g2 + r2[:, a:a + 2048] - 2.0 * gen.astype(np.float64) @ ref[a:a + 2048].T.astype(np.float64)
        best = np.minimum(best, d.min(1))
    return np.maximum(best, 0.0) / length


def pose_vectors(feats: np.ndarray) -> np.ndarray:
    """Root-local joint positions ``[F, 63]`` (the pose part of the features)."""
    return feats[:, LAYOUT.positions]


def rollout_report(feats: np.ndarray, seed_pos: np.ndarray, data_speed: float, ref_segments: np.ndarray,
                   block: int = 1000, median_speed: float | None = None, floor: float | None = None) -> RolloutReport:
    """Judge one open-loop rollout (raw features ``[N, C]``) against its seed positions ``[m, J, 3]``.

    ``data_speed``: the data's mean joint speed (m / frame), for the speed ratio; ``median_speed``
    (default: ``data_speed``): its median, for the freeze test (below :data:`FREEZE_SHARE` of it for
    :data:`FREEZE_FRAMES` frames);
    ``floor``: the floor height of the seed's take, for the grounding of the last ``block`` frames."""
    pos = features_to_positions(feats)
    finite = bool(np.isfinite(pos).all())
    rest = np.median(bone_lengths_of(seed_pos), 0)
    exploded = not finite or bool((np.abs(bone_lengths_of(pos) / rest - 1.0) > 0.10).any())
    speed = joint_speed(pos) if finite else np.zeros(len(pos) - 1)
    still = longest_run(speed < FREEZE_SHARE * (data_speed if median_speed is None else median_speed))
    ratio = float(speed[-block:].mean() / data_speed) if finite else float("nan")
    blocks = []
    for b in range(0, len(feats) - block + 1, block):
        seg = segments(pose_vectors(feats[b:b + block]))
        blocks.append(float(d1nn(seg, ref_segments).mean()) if finite and len(seg) else float("nan"))
    feet = feet_report(pos[-block:], floor, contacts=feats[-block:, LAYOUT.contacts]) \
        if finite and floor is not None else None
    return RolloutReport(exploded, still >= FREEZE_FRAMES, ratio, blocks, feet, int(still))


# ------------------------------------------------------------------ denoising
def add_noise(pos: np.ndarray, std_cm: float, rng: np.random.Generator) -> np.ndarray:
    return (pos + rng.normal(0.0, std_cm / 100.0, pos.shape)).astype(np.float32)


def add_pops(pos: np.ndarray, rate: float, rng: np.random.Generator, low_m: float = 0.1,
             high_m: float = 0.3) -> np.ndarray:
    """``pos`` ``[F, J, 3]`` with ``rate`` of its joint-frames moved ``low_m`` to ``high_m`` in a random
    direction for that one frame (single-frame pops, as from a marker swap)."""
    out = np.array(pos, np.float64)
    hit = rng.random(out.shape[:2]) < rate
    way = rng.normal(size=out.shape)
    way /= np.linalg.norm(way, axis=-1, keepdims=True)
    out[hit] += (way * rng.uniform(low_m, high_m, out.shape[:2])[..., None])[hit]
    return out.astype(np.float32)


def median_filter(pos: np.ndarray, size: int) -> np.ndarray:
    """Running median along time of ``[F, ...]`` over ``size`` (odd) frames, the ends repeated."""
    return running_median(np.asarray(pos), size // 2).astype(np.float32)


def best_median(clean: list[np.ndarray], noisy: list[np.ndarray], sizes=(3, 5, 7, 9)) -> tuple[float, int]:
    """(MPJPE cm, window in frames) of the median filter that is best on this data."""
    best = (np.inf, 0)
    for size in sizes:
        err = np.concatenate([mpjpe_cm(median_filter(n, size), c) for c, n in zip(clean, noisy)]).mean()
        best = min(best, (float(err), size))
    return best


def upsample(pos: np.ndarray, factor: float) -> np.ndarray:
    """``[F, ...]`` resampled at ``factor`` times the rate with a Catmull-Rom cubic (passes every frame)."""
    t = np.arange(int(np.floor((len(pos) - 1) * factor + 1e-9)) + 1) / factor
    return cubic_frames(pos, t).astype(np.float32)


def butterworth(pos: np.ndarray, cutoff_hz: float, fps: float = MODEL_FPS) -> np.ndarray:
    """4th-order zero-phase low-pass along time of ``[F, J, 3]``."""
    b, a = butter(4, cutoff_hz / (fps / 2.0))
    return filtfilt(b, a, pos, axis=0).astype(np.float32)


def best_butterworth(clean: list[np.ndarray], noisy: list[np.ndarray], cutoffs=(1, 1.5, 2, 2.5, 3, 3.5, 4, 5, 6, 7, 8,
                     10, 12), fps: float = MODEL_FPS) -> tuple[float, float]:
    """(MPJPE cm, cutoff Hz) of the Butterworth cutoff that is best on this data and noise."""
    best = (np.inf, 0.0)
    for fc in [c for c in cutoffs if c < 0.45 * fps]:
        err = np.concatenate([mpjpe_cm(butterworth(n, fc, fps), c) for c, n in zip(clean, noisy)]).mean()
        best = min(best, (float(err), float(fc)))
    return best
