"""The take's own motion for Fill Gap (no torch needed).

A take often does again what it did elsewhere: a walk's next steps are like its last ones, a drill kicks the
same kick again. A gap in such a take is best filled with what the take did the other time, and no model that
has not seen this person or this motion does as well. So Fill Gap looks through the rest of the action
(outside the gap, up to :data:`extend.MEMORY_S` seconds either side, as much as Extend reads) for the stretch
that fits both ends of the gap: its last :data:`MATCH_FRAMES` frames before are most like the context's last
ones (the pose in the body's frame, the hips' velocity in it, the turn rate), and its frame ``N + 1`` later
stands to it as the target stands to the context's last frame (how far the body went, in its own frame, how
far it turned, the target's pose). Moved to start where the context ends, that stretch is a second
continuation of the context, which Fill Gap bends onto the target as it bends the model's. The stretch is
looked for in the take as it is and mirrored (the other foot's steps).

How much Fill Gap leans on it (:func:`share`) falls with the fit's distance: all the way where the take
did exactly this elsewhere, nothing where it never did (a single bow); less in long gaps and in motion the
model knows. Positions are ``[F, J, 3]`` metres, Y-up, at the model's rate. Chosen on the held-out groups and
the validation split (model card, "Fill Gap follows the take").
"""

from __future__ import annotations

import numpy as np

from ..motion.features import mirror_positions, root_and_local, wrap_angle, yaw_matrix

MATCH_FRAMES = 10  # how many of the context's last frames a stretch is compared with
TARGET_WEIGHT = 1.0  # the weight of the fit at the target beside the fit before the gap
# Weights of the hips' velocity in the body's frame (m per frame) and of the turn rate (radians per frame)
# beside the pose (m) in a frame's descriptor: a step of a walk weighs about as much as its pose.
VELOCITY_WEIGHT, TURN_WEIGHT = 3.0, 0.3
# The take's share is exp(-distance / scale): the scale is SCALE for a gap of SCALE_FRAMES frames at 30 fps and
# falls as the gap grows (a longer stretch must fit better to be trusted), and it is FAMILIAR_SCALE x as large
# where the model knows the context's motion (momentum share 0) as where it does not (1): the models fill
# familiar motion well themselves, and only a take that did exactly this does better.
SCALE, SCALE_FRAMES, FAMILIAR_SCALE = 0.016, 30, 0.1


def descriptors(pos: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(per-frame descriptors ``[F, D]``, the hips' ground position ``[F, 3]``, heading ``[F]``, the joints in
    the body's frame ``[F, J, 3]``) of positions ``[F, J, 3]``."""
    root, yaw, local = root_and_local(pos)
    step = np.diff(root, axis=0, prepend=root[:1])
    velocity = np.einsum("fij,fj->fi", yaw_matrix(-yaw), step)
    turn = wrap_angle(np.diff(yaw, prepend=yaw[:1]))
    desc = np.concatenate([local.reshape(len(local), -1), VELOCITY_WEIGHT * velocity, TURN_WEIGHT * turn[:, None]], 1)
    return desc, root, yaw, local


def relation(root: np.ndarray, yaw: np.ndarray, local: np.ndarray, a, b) -> np.ndarray:
    """How frame(s) ``b`` stand to frame(s) ``a``: the hips' ground step in ``a``'s body frame, the turn, and
    ``b``'s pose in its own frame: ``[..., 4 + 3 J]``."""
    a, b = np.atleast_1d(a), np.atleast_1d(b)
    step = np.einsum("fij,fj->fi", yaw_matrix(-yaw[a]), root[b] - root[a])
    return np.concatenate([step, wrap_angle(yaw[b] - yaw[a])[:, None], local[b].reshape(len(b), -1)], 1)


def best_stretch(segments: list[np.ndarray], context: np.ndarray, target: np.ndarray,
                 frames: int) -> tuple[float, np.ndarray | None]:
    """(the fit's distance, the stretch ``[frames + 1, J, 3]``) of the take's ``segments`` (each ``[S, J, 3]``,
    a run of frames outside the gap) that best continues ``context`` ``[C, J, 3]`` across a gap of ``frames``
    frames to ``target`` ``[T, J, 3]``: the ``frames`` frames after the stretch's start and the one at the
    target's time, moved so that the start stands where the context's last frame stands and faces its way.
    ``(inf, None)`` where no segment holds a stretch that long."""
    if len(context) < MATCH_FRAMES:
        return float("inf"), None
    probe, root, yaw, local = descriptors(np.concatenate([context[-MATCH_FRAMES:], target[:1]]))
    want = relation(root, yaw, local, MATCH_FRAMES - 1, MATCH_FRAMES)[0]
    probe = probe[:MATCH_FRAMES]
    best, found = float("inf"), None
    for seg in [s for s in segments for s in (s, mirror_positions(s))]:
        seg = np.asarray(seg, np.float64)
        ends = np.arange(MATCH_FRAMES, len(seg) - frames)  # the stretch starts after frame e - 1
        if not len(ends):
            continue
        desc, s_root, s_yaw, s_local = descriptors(seg)
        windows = np.lib.stride_tricks.sliding_window_view(desc, MATCH_FRAMES, axis=0)[ends - MATCH_FRAMES]
        distance = ((windows - probe.T[None]) ** 2).mean((1, 2)) \
            + TARGET_WEIGHT * ((relation(s_root, s_yaw, s_local, ends - 1, ends + frames) - want) ** 2).mean(1)
        i = int(np.argmin(distance))
        if distance[i] < best:
            best, found = float(distance[i]), (seg, int(ends[i]))
    if found is None:
        return best, None
    seg, end = found
    return best, place(seg[end - 1:end + frames + 1], context[-1])[1:]


def place(stretch: np.ndarray, start: np.ndarray) -> np.ndarray:
    """``stretch`` ``[F, J, 3]`` turned about the vertical and moved over the ground so that its first frame's
    hips stand where ``start``'s ``[J, 3]`` stand, facing the same way (heights kept)."""
    (r0, y0, _), (r1, y1, _) = root_and_local(stretch[:1]), root_and_local(start[None])
    return np.einsum("ij,fkj->fki", yaw_matrix(y1 - y0)[0], stretch - r0[0]) + r1[0]


def share(distance: float, frames: int, momentum: float) -> float:
    """How far Fill Gap leans on a stretch whose fit is ``distance`` away across a gap of ``frames`` frames at
    30 fps, for a context whose momentum share is ``momentum`` (:func:`familiarity.momentum_shares`; 1: the
    model does not know the motion): :data:`SCALE`."""
    if not np.isfinite(distance):
        return 0.0
    familiar = FAMILIAR_SCALE + (1.0 - FAMILIAR_SCALE) * float(np.clip(momentum, 0.0, 1.0))
    return float(np.exp(-distance / (SCALE * SCALE_FRAMES / max(frames, 1) * familiar)))
