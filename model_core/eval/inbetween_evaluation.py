"""In-betweening evaluation (``scripts/evaluate.py --inbetween N ...``), in the spirit of the LaFAN1
benchmark (Harvey et al. 2020) but in centimetres on the 21 joints: windows of 20 context frames,
a gap of N frames and the frame after it as the target, stride 15. For each gap length: L2P (mean
global joint position error over the gap), the error at the target frame, and foot skate on the
gap's contact frames; beside linear interpolation of the root and of the root-relative joints (the
standard baseline), the same with the heading interpolated on the circle and the joints in the
body's frame, and the real takes' own foot skate. Positions are metres, Y-up, 30 fps.
"""

from __future__ import annotations

import numpy as np

from ..motion.conventions import MODEL_FPS
from ..motion.features import detect_contacts
from ..ops import inbetween as fill_gap
from ..ops.extend import MEMORY_S
from ..ops.familiarity import momentum_shares
from ..ops.footlock import SETTLE_PASSES, FootLockSettings, foot_lock, foot_skate_cm
from ..ops.inbetween import fill_from, interpolation
from .metrics import extend_batch, mpjpe_cm

CONTEXT = 20
STRIDE = 15


def windows(clips: list[np.ndarray], gap: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, list]:
    """(contexts ``[W, 20, J, 3]``, true gaps ``[W, gap, J, 3]``, targets ``[W, J, 3]``, and each window's take
    outside the gap as Fill Gap reads it: the frames up to the gap and from the target on, up to
    :data:`extend.MEMORY_S` seconds of each)."""
    ctx, mid, tgt, takes = [], [], [], []
    most = int(MEMORY_S * MODEL_FPS)
    for pos in clips:
        for s in range(0, len(pos) - CONTEXT - gap, STRIDE):
            ctx.append(pos[s:s + CONTEXT])
            mid.append(pos[s + CONTEXT:s + CONTEXT + gap])
            tgt.append(pos[s + CONTEXT + gap])
            takes.append([pos[max(0, s + CONTEXT - most):s + CONTEXT], pos[s + CONTEXT + gap:s + CONTEXT + gap + most]])
    if not ctx:
        raise ValueError(f"no clip has the {CONTEXT + gap + 1} frames an in-betweening window of {gap} needs")
    return np.stack(ctx), np.stack(mid), np.stack(tgt), takes


def interpolate(last: np.ndarray, target: np.ndarray, gap: int, heading: bool = False) -> np.ndarray:
    """Linear interpolation ``[gap, J, 3]`` from ``last`` to ``target`` ``[J, 3]``: of the root and the
    root-relative joints, or (``heading``) of the root, the heading on the circle and the joints in
    the body's frame."""
    s = (np.arange(1, gap + 1) / (gap + 1))[:, None, None]
    if not heading:
        r0, r1 = last[:1], target[:1]
        return (r0 + s * (r1 - r0)) + (last - r0) + s * ((target - r1) - (last - r0))
    return interpolation(last, target, gap)


def evaluate_inbetween(engine, clips, gaps=(15, 30, 60)) -> dict:
    out = {"gap_frames": list(gaps), "windows": [],
           "l2p_cm": {"strnn": [], "interpolation": [], "interpolation_heading": [], "strnn_without_take": []},
           "target_error_cm": {"strnn": []},
           "foot_skate_cm": {"strnn": [], "strnn_locked": [], "interpolation": [], "real": []},
           "foot_contact_share": {"strnn": [], "strnn_locked": [], "interpolation": [], "real": []}}
    positions = [c.positions for c in clips]
    for gap in gaps:
        ctx, true, tgt, takes = windows(positions, gap)
        pred = extend_batch(engine, ctx, gap + 1, paired_windows=fill_gap.PAIRED_WINDOWS)  # as Fill Gap
        shares = momentum_shares(engine, ctx)
        alone = np.stack([fill_gap.with_gap_model(engine, c, t[None], fill_from(c, p, t[None], k), k)
                          for p, c, t, k in zip(pred, ctx, tgt, shares)])
        bent = np.stack([fill_gap.with_take(c, t[None], a, take, k)
                         for a, c, t, take, k in zip(alone, ctx, tgt, takes, shares)])
        ours, arrive = bent[:, :-1], bent[:, -1]
        out["l2p_cm"]["strnn_without_take"].append(float(mpjpe_cm(alone[:, :-1], true).mean()))
        lerp = np.stack([interpolate(c[-1], t, gap) for c, t in zip(ctx, tgt)])
        turn = np.stack([interpolate(c[-1], t, gap, heading=True) for c, t in zip(ctx, tgt)])
        out["windows"].append(int(len(ctx)))
        for name, motion in (("strnn", ours), ("interpolation", lerp), ("interpolation_heading", turn)):
            out["l2p_cm"][name].append(float(mpjpe_cm(motion, true).mean()))
        out["target_error_cm"]["strnn"].append(float(mpjpe_cm(arrive, tgt).mean()))
        locked = np.stack([lock_gap(c, g, t) for c, g, t in zip(ctx, ours, tgt)])
        for name, motion in (("strnn", ours), ("strnn_locked", locked), ("interpolation", lerp), ("real", true)):
            skate, share = _skate(ctx, motion, tgt)
            out["foot_skate_cm"][name].append(skate)
            out["foot_contact_share"][name].append(share)
    return out


def lock_gap(ctx: np.ndarray, gap: np.ndarray, tgt: np.ndarray) -> np.ndarray:
    """The gap ``[N, J, 3]`` after a settled Foot Lock with the context and the target frame fixed, as Fill
    Gap's Foot Lock option runs it."""
    seq = np.concatenate([ctx, gap, tgt[None]])
    fixed = np.ones(len(seq), bool)
    fixed[len(ctx):len(ctx) + len(gap)] = False
    return foot_lock(seq, fixed=fixed, settings=FootLockSettings(passes=SETTLE_PASSES))[len(ctx):len(ctx) + len(gap)]


def _skate(ctx: np.ndarray, gap: np.ndarray, tgt: np.ndarray) -> tuple[float, float]:
    """(foot skate in cm / frame, share of contact frames): the mean horizontal motion of the contact joints
    over every step in the gaps where that joint is in contact at both ends (contacts detected on each
    window), and the share of the gaps' joint-steps that are such contact steps. Pooled over the steps, not
    averaged per window: a window whose feet never touch the floor (they float or slide fast) has no contact
    step to score; it shows in the share, not as a window of perfect feet."""
    moved, steps, total = 0.0, 0, 0
    for c, g, t in zip(ctx, gap, tgt):
        seq = np.concatenate([c[-1:], g, t[None]])
        contacts = detect_contacts(np.concatenate([c, g, t[None]]))[len(c) - 1:] > 0.5
        on = contacts[:-1] & contacts[1:]
        n = int(on.sum())
        moved += foot_skate_cm(seq, contacts) * n
        steps, total = steps + n, total + on.size
    return (moved / steps if steps else 0.0), steps / max(total, 1)
