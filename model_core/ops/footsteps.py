"""Footsteps on uneven ground: each step of motion made on a flat floor moved along its foot so that the foot lands
on even ground, a stair's tread rather than its edge.

Motion the model makes on a flat floor and carries over stairs (``strnn_addon/scene/ground.carried``) puts its
steps where the flat walk put them: a heel on one step and the toe on the next, which Foot Lock then pins pitched
up the edge. Here each stance (a foot's heel or toe in contact, contact flicker filled) is looked at once: the
surface's height is read under its footprint, from behind the ankle to past the ball of the foot, and a margin
beyond both. Where those heights stray further than ``tolerance`` from a straight line (an edge under the foot; a
slope, which the foot pitches with, is no edge), the stance is moved along the foot's own direction by the smallest
shift that finds them even (without the margin where no shift does), at most ``max_shift``. Between two stances the
shift passes from one to the next over the swing (a cosine), so the foot is carried there in the air; the knee
follows by two-bone IK from the unmoved hip (:func:`footlock.two_bone_ik`), every bone keeping its length.
``fixed`` frames (a clip already in the scene) and stances that reach into them stay where they are.

The surface is given as a function, ``height_at(points [N, 3]) -> [N]`` (Y-up, NaN where there is none), so
Blender's ray casts and a test's analytic stairs serve alike.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..motion.conventions import CONTACT_JOINTS, GROUND_AXES, STANDARD_LEG_LENGTH, UP_AXIS
from ..motion.stance import held_and_eased
from ..rig.rigs import leg_length
from .footlock import (
    _ANKLE,
    _HEEL_CHANNELS,
    _HIP,
    _KNEE,
    _TOE,
    _TOE_CHANNELS,
    FootLockSettings,
    body_forward,
    fill_gaps,
    two_bone_ik,
)

# Where the footprint is read, as shares of the ankle-to-toe vector from the ankle: from behind the ankle (which
# stands over the heel, in front of its back) to just past the toe joint, the ball of the foot. The toes' tips may
# reach over a tread's edge, as people's do going up stairs.
FOOTPRINT = np.linspace(-0.25, 1.1, 7)
TOLERANCE = 0.015  # legs' lengths over a standard leg of 0.87 m: a footprint's surface this near a line has no edge
MARGIN = 0.03  # legs' lengths: how far past the heel and the ball even ground should reach, where it can
MAX_SHIFT = 0.35  # legs' lengths: no step is moved further than this (30 cm for a standard leg)
_SEARCH_STEP = 0.005  # legs' lengths between the shifts tried


def stances(contacts: np.ndarray, min_gap: int) -> list[tuple[int, int, int]]:
    """Each foot's stances: ``(leg, first frame, last frame)`` of the runs where its heel or toe is in contact
    (``contacts`` ``[F, 4]``, gaps of at most ``min_gap`` frames filled), leg 0 left, 1 right, in frame order per
    leg."""
    on = fill_gaps(np.asarray(contacts) > 0.5, min_gap)
    out = []
    for leg in (0, 1):
        down = on[:, _HEEL_CHANNELS[leg]] | on[:, _TOE_CHANNELS[leg]]
        edges = np.flatnonzero(np.diff(np.r_[0, down.astype(np.int8), 0]))
        out += [(leg, int(a), int(b) - 1) for a, b in zip(edges[0::2], edges[1::2])]
    return out


def _even_shift(height_at: Callable, ankle: np.ndarray, toe: np.ndarray, tolerance: float, margin: float,
                 max_shift: float, step: float) -> float | None:
    """How far along the foot (its ground direction; + towards the toe) to move a footprint at ``ankle``, ``toe``
    ``[3]`` so that the surface under it is even (:func:`_even`): the smallest shift (0 where it already is) that finds
    it even with ``margin`` to spare at both ends, so that neither heel nor ball stands on an edge; else the smallest
    that finds it even; None where none within ``max_shift`` does."""
    foot = toe - ankle
    foot[UP_AXIS] = 0.0
    length = np.linalg.norm(foot)
    if length < 1e-9:
        return 0.0
    way = foot / length
    shifts = np.arange(0.0, max_shift + step / 2, step)
    shifts = np.stack([shifts, -shifts], 1).reshape(-1)[1:]  # 0, +s, -s, +2s, -2s, ...
    spare = margin / length
    reach = np.r_[FOOTPRINT[0] - spare, FOOTPRINT, FOOTPRINT[-1] + spare]
    points = ankle + reach[:, None] * foot  # [P, 3], at the sole's height (a ray is cast down from above it)
    points[:, UP_AXIS] = min(ankle[UP_AXIS], toe[UP_AXIS])
    tried = points[None] + shifts[:, None, None] * way  # [S, P, 3]
    heights = np.asarray(height_at(tried.reshape(-1, 3)), np.float64).reshape(len(shifts), len(reach))
    for part in (slice(None), slice(1, -1)):  # with the margin, then without it
        even = _even(reach[part], heights[:, part], tolerance)
        if even.any():
            return float(shifts[int(np.argmax(even))])
    return None


def _even(at: np.ndarray, heights: np.ndarray, tolerance: float) -> np.ndarray:
    """Whether each row of ``heights`` ``[S, P]``, read at ``at`` ``[P]`` along a foot, lies within ``tolerance`` of
    a straight line (a floor, or a slope the foot can pitch with: no edge under it), with a surface under every
    point."""
    found = np.isfinite(heights).all(1)
    basis = np.stack([np.ones_like(at), at], 1)  # [P, 2]
    h = np.where(np.isfinite(heights), heights, 0.0)
    coef = np.linalg.lstsq(basis, h.T, rcond=None)[0]  # [2, S]
    return found & (np.abs(h - (basis @ coef).T).max(1) <= tolerance)


def even_steps(pos: np.ndarray, contacts: np.ndarray, height_at: Callable, min_gap: int = 2,
                fixed: np.ndarray | None = None, tolerance: float = TOLERANCE, margin: float = MARGIN,
                max_shift: float = MAX_SHIFT, softness: float = 0.03) -> tuple[np.ndarray, dict]:
    """Positions ``[F, 21, 3]`` (Y-up, any unit) with each stance of ``contacts`` ``[F, 4]`` moved along its foot
    onto even ground (see the module's docstring; ``tolerance``, ``margin`` and ``max_shift`` in legs' lengths
    of a standard leg), and what was done: ``{"steps": stances looked at, "moved": stances moved, "on_edges":
    stances left on an edge where no even ground was near, "largest": the largest shift (``pos``'s units)}``."""
    pos = np.asarray(pos, np.float64)
    n = len(pos)
    fixed = np.zeros(n, bool) if fixed is None else np.asarray(fixed, bool)
    unit = leg_length(pos) / STANDARD_LEG_LENGTH
    found = stances(contacts, min_gap)
    way_of = np.zeros((n, 2, 3))  # each leg's shift, frame by frame
    report = {"steps": 0, "moved": 0, "on_edges": 0, "largest": 0.0}
    for leg in (0, 1):
        spans = [(a, b) for lg, a, b in found if lg == leg]
        keys: list[tuple[int, int, np.ndarray]] = []  # (first, last, shift vector) of each stance
        for a, b in spans:
            if fixed[a:b + 1].any():
                keys.append((a, b, np.zeros(3)))
                continue
            mid = (a + b) // 2
            ankle, toe = pos[mid, _ANKLE[leg]], pos[mid, _TOE[leg]]
            report["steps"] += 1
            shift = _even_shift(height_at, ankle, toe, tolerance * unit, margin * unit, max_shift * unit,
                                 _SEARCH_STEP * unit)
            if shift is None:
                report["on_edges"] += 1
                shift = 0.0
            foot = (toe - ankle) * np.isin(np.arange(3), GROUND_AXES)
            vec = shift * foot / max(np.linalg.norm(foot), 1e-12)
            if shift:
                report["moved"] += 1
                report["largest"] = max(report["largest"], abs(shift))
            keys.append((a, b, vec))
        way_of[:, leg] = _carried_between(keys, n, fixed)
    if not report["moved"]:
        return pos.copy(), report
    out = pos.copy()
    target = pos[:, _ANKLE] + way_of
    fwd = body_forward(pos)[:, None].repeat(2, 1)
    knee, ankle = two_bone_ik(pos[:, _HIP], pos[:, _KNEE], pos[:, _ANKLE], target, softness, fwd)
    out[:, _KNEE], out[:, _ANKLE] = knee, ankle
    out[:, _TOE] = ankle + (pos[:, _TOE] - pos[:, _ANKLE])  # the foot keeps its orientation
    out[fixed] = pos[fixed]
    return out, report


def _carried_between(keys: list[tuple[int, int, np.ndarray]], frames: int, fixed: np.ndarray) -> np.ndarray:
    """A shift ``[F, 3]`` that is each key's ``(first, last, vector)`` over its frames and passes from one to the
    next between them (a cosine); 0 on ``fixed`` frames, eased in from the last fixed frame before the first key; the
    last key's after it, and the first key's before it where nothing is fixed."""
    out = np.zeros((frames, 3))
    if not keys:
        return out
    ground = list(GROUND_AXES)
    start = int(np.flatnonzero(fixed).max()) + 1 if fixed.any() else None
    points = ([(start - 1, start - 1, np.zeros(3))] if start is not None and start <= keys[0][0] else []) + keys
    for a, b, vec in points:
        out[max(a, 0):b + 1, ground] = vec[ground]
    for (_, b0, v0), (a1, _, v1) in zip(points[:-1], points[1:]):
        if a1 - b0 > 1:
            t = (np.arange(b0 + 1, a1) - b0) / (a1 - b0)
            s = 0.5 - 0.5 * np.cos(np.pi * t)
            out[b0 + 1:a1, ground] = ((1 - s)[:, None] * v0 + s[:, None] * v1)[:, ground]
    first = points[0]
    if start is None:
        out[:first[0], ground] = first[2][ground]
    last = points[-1]
    out[last[1] + 1:, ground] = last[2][ground]
    out[fixed] = 0.0
    return out


FLOOR_TOLERANCE = FootLockSettings.floor_tolerance  # metres for a standard leg: Foot Lock's (1 cm)
CLEAR_S = 0.1  # seconds: a foot raised clear of the surface rises and comes down again over this much either side


def clear_of_surface(pos: np.ndarray, heights: np.ndarray, standing: np.ndarray, fps: float,
                     fixed: np.ndarray | None = None, tolerance: float = FLOOR_TOLERANCE,
                     softness: float = 0.03) -> tuple[np.ndarray, int]:
    """Positions ``[F, 21, 3]`` (Y-up) with each foot raised where its heel or toe would be under the surface: lower
    than ``heights`` ``[F, 4]`` (the surface under each heel and toe, NaN where there is none) plus ``standing``
    ``[4]`` (how high each stands over the floor when down), by more than ``tolerance`` (metres for a standard leg:
    Foot Lock's, within which a planted foot counts as on the floor; a straight leg raised even a millimetre must
    bend its knee by centimetres), to that tolerance. Motion made on a flat floor and carried with the surface under
    the hips drops its feet with the hips: a foot leaving a stair's tread on the way down, or one reaching over a
    step's nose, passes through the tread. The rise is eased in and out over :data:`CLEAR_S`
    (:func:`stance.held_and_eased`, never less than the shortfall), the foot keeps its orientation, the knee
    follows by two-bone IK from the hip; ``fixed`` frames stay. Also on how many frames a foot was raised."""
    pos = np.asarray(pos, np.float64)
    n = len(pos)
    fixed = np.zeros(n, bool) if fixed is None else np.asarray(fixed, bool)
    tolerance = tolerance * leg_length(pos) / STANDARD_LEG_LENGTH
    under = np.nan_to_num(np.asarray(heights, np.float64) + np.asarray(standing, np.float64)
                          - pos[:, CONTACT_JOINTS, UP_AXIS], nan=0.0) - tolerance  # [F, 4]: each heel and toe
    short = np.maximum(np.stack([under[:, [_HEEL_CHANNELS[leg], _TOE_CHANNELS[leg]]].max(1) for leg in (0, 1)], 1), 0)
    short[fixed] = 0.0
    rise = held_and_eased(short.T, max(1, int(round(CLEAR_S * fps)))).T  # [F, 2]
    rise[fixed] = 0.0
    raised = rise > 0.0
    if not raised.any():
        return pos.copy(), 0
    out = pos.copy()
    target = pos[:, _ANKLE].copy()
    target[..., UP_AXIS] += rise
    fwd = body_forward(pos)[:, None].repeat(2, 1)
    knee, ankle = two_bone_ik(pos[:, _HIP], pos[:, _KNEE], pos[:, _ANKLE], target, softness, fwd)
    keep = ~raised[..., None]
    out[:, _KNEE] = np.where(keep, pos[:, _KNEE], knee)
    out[:, _ANKLE] = np.where(keep, pos[:, _ANKLE], ankle)
    out[:, _TOE] = out[:, _ANKLE] + (pos[:, _TOE] - pos[:, _ANKLE])
    out[fixed] = pos[fixed]
    return out, int(raised.any(1).sum())
