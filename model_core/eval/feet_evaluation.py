"""Feet of generated motion (``scripts/evaluate.py --feet``): each clip's first 20 frames are
extended as Extend Clip does it (:func:`extend.extend_positions`), then foot-locked with the
context frames fixed and the lock settled, as the Extend operator's Foot Lock option runs it. Reported beside the real
takes: foot skate on contact frames, how far contact feet go below the floor of the take, and how
often the lock leaves a knee fully straight where the generated leg was bent.

Contacts are detected on the motion itself by the rule that labels the training data
(:func:`features.detect_contacts`); the floor is each contact joint's height in contact over the
context (:func:`footlock.rest_heights`). Positions are metres, Y-up, 30 fps.
"""

from __future__ import annotations

import numpy as np

from ..motion.conventions import CONTACT_JOINTS, MODEL_FPS, UP_AXIS
from ..ops.extend import extend_positions
from ..ops.footlock import (
    SETTLE_PASSES,
    FootLockSettings,
    detect_foot_contacts,
    foot_lock,
    foot_skate_cm,
    knee_angles,
    rest_heights,
)

CONTEXT = 20
STRAIGHT_DEG = 1.0  # a knee bent less than this is fully straight
BENT_DEG = 5.0  # ... where the unlocked leg was bent more than this


def evaluate_feet(engine, clips, frames: int = 150, count: int = 60) -> dict:
    """Figures over up to ``count`` clips of at least ``CONTEXT + 10`` frames (evenly spread)."""
    usable = sorted((c for c in clips if len(c.positions) >= CONTEXT + 10), key=lambda c: c.name)
    picks = [usable[i] for i in np.linspace(0, len(usable) - 1, min(count, len(usable))).round().astype(int)]
    rows = [one_clip(engine, c.positions, frames) for c in picks]
    out = {"clips": len(rows), "frames": frames}
    for key in rows[0]:
        out[key] = float(np.nanmean([r[key] for r in rows]))
    return out


def one_clip(engine, pos: np.ndarray, frames: int) -> dict:
    ctx = np.asarray(pos[:CONTEXT], np.float64)
    new = extend_positions(engine, ctx, MODEL_FPS, frames)
    raw = np.concatenate([ctx, new])
    fixed = np.arange(len(raw)) < CONTEXT
    contacts = detect_foot_contacts(raw)
    locked = foot_lock(raw, MODEL_FPS, contacts, fixed=fixed, settings=FootLockSettings(passes=SETTLE_PASSES))
    after = detect_foot_contacts(locked)
    rest = rest_heights(raw, contacts, fixed)
    gen = ~fixed
    return {"skate_real_cm": foot_skate_cm(pos, detect_foot_contacts(pos)),
            "skate_raw_cm": foot_skate_cm(raw[gen], contacts[gen]),
            "skate_locked_cm": foot_skate_cm(locked[gen], contacts[gen]),
            "skate_locked_redetected_cm": foot_skate_cm(locked[gen], after[gen]),
            "sink_raw_cm": sink_cm(raw[gen], contacts[gen], rest),
            "sink_locked_cm": sink_cm(locked[gen], after[gen], rest),
            "straight_knees_locked": straightened(raw[gen], locked[gen])}


def sink_cm(pos: np.ndarray, contacts: np.ndarray, rest: np.ndarray | None) -> float:
    """The deepest a contact joint goes below its height in contact on the floor (cm, >= 0; nan
    when the context has no contact to measure the floor by)."""
    on = np.asarray(contacts) > 0.5
    if rest is None or not on.any():
        return float("nan") if rest is None else 0.0
    below = rest[None] - pos[:, CONTACT_JOINTS, UP_AXIS]
    return float(100.0 * max(0.0, below[on].max()))


def straightened(raw: np.ndarray, locked: np.ndarray) -> float:
    """Share of (frame, leg) whose knee the lock left fully straight where the raw leg was bent."""
    before, after = knee_angles(raw), knee_angles(locked)
    bent = before > BENT_DEG
    return float(((after < STRAIGHT_DEG) & bent).sum() / max(bent.sum(), 1))
