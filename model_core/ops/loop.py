"""Make Loop: a stretch of a clip made into a cycle that repeats without a seam (a walk, a run, an idle, a dance
loop).

The cycle is the stretch's frames from its first up to the one before its *seam*: the frame that starts the next
cycle. With ``match`` the seam is the frame of the stretch's second half whose pose, in the body's own frame, with
its joints' velocities, is nearest the first frame's (:func:`find_seam`); otherwise the stretch's last frame, as
given. The next cycle starts where the seam frame stands: the first pose moved over the ground by the cycle's travel
(the hips' ground path from the first frame to the seam) and not turned, so that the cycle repeats along a straight
line, as a Cycles modifier repeats it (it adds the travel to the location, and cannot turn it). A stretch that turns
(a walk that curves, a walk-turn) is unwound first (:func:`unwound`): each frame turned back about the vertical by its
share of the cycle's net turn, its path with it, so that the seam faces as the first frame does and the blend need
not turn the body back (left in, a 100 degree turn came back within the 0.4 s blend at up to 350 degrees a second).

The last ``blend`` frames before the seam are made again by the in-betweener (:func:`inbetween.inbetween_positions`)
from the cycle before them to the next cycle's start, so the motion flows on into it: a pose that does not quite
match, or a body that turned a little over the cycle, is carried back on to it without a pop. Where the take goes on
before the stretch, those frames are half the in-between and half the cycle's end cross-faded into the take's own
frames that lead into its first (moved by the travel): on held-out takes that mix came nearer the take's own
smoothness at the seams than either alone (``runs/s61/loop_eval.py``, README "Make Loop").

``in_place``: the travel is taken off (the hips' ground path less its straight line from the first frame to the
seam), so that the cycle repeats on the spot with its sway kept, as game engines take a cycle apart from its root
motion.

Positions are ``[F, 21, 3]``, Y-up, in any unit, at any rate (``fps``), as the operations take a user's clip.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ..motion.conventions import GROUND_AXES, ROOT, UP_AXIS
from ..motion.features import heading, root_and_local, yaw_matrix
from .inbetween import inbetween_positions
from .normalise import fit_normalisation

MIN_CYCLE_S = 0.5  # the shortest cycle made (a run's stride is about 0.7 s)
# A cycle unwound by more than this many degrees has its feet locked over the whole cycle, not only the blend: the
# unwinding turns each frame about the hips, which slides a planted foot (a 45 degree turn over 1.2 s: 0.2 -> 0.6 cm
# a frame), and the lock plants it again.
UNWOUND_LOCK_DEG = 5.0
BLEND_S = 0.4  # seconds before the seam made again by default
VELOCITY_WEIGHT_S = 0.1  # the pose match weighs the joints' velocities (m/s) by this, beside their places (m)


@dataclass(frozen=True)
class Loop:
    """A cycle made by :func:`loop_positions`."""

    positions: np.ndarray  # [L + 1, 21, 3]: the cycle's L frames, then the seam frame (the next cycle's first)
    seam: int  # the seam's index in the stretch: the cycle is its frames 0 to seam - 1 (L = seam)
    travel: np.ndarray  # [3] the ground travel of one cycle (zero in place)
    match_cm: float  # how far the seam's pose was from the first's before the blend (cm a joint, standard body)
    blend: int  # frames before the seam made again
    turn: float = 0.0  # the stretch's net turn from the first frame to the seam, unwound (radians about the up axis)

    def fixed(self) -> np.ndarray:
        """bool ``[L + 1]``: the cycle's frames a foot lock leaves as they are: all but the blend's; where the stretch
        was unwound by more than :data:`UNWOUND_LOCK_DEG`, only the first and the seam (kept, so that the cycle
        still repeats without a seam)."""
        fixed = np.ones(self.seam + 1, bool)
        if abs(math.degrees(self.turn)) > UNWOUND_LOCK_DEG:
            fixed[1:-1] = False
        else:
            fixed[self.seam - self.blend:self.seam] = False
        return fixed

    def on_the_spot(self, positions: np.ndarray | None = None) -> Loop:
        """The cycle (or ``positions`` ``[L + 1, 21, 3]`` in its place: the cycle with its feet locked) with its
        travel taken off: the hips' ground path less its straight line from the first frame to the seam, so that
        it repeats on the spot, its sway kept."""
        cycle = self.positions if positions is None else np.asarray(positions, np.float64)
        cycle = cycle - self.travel * (np.arange(self.seam + 1) / self.seam)[:, None, None]
        return replace(self, positions=cycle, travel=np.zeros(3))


def least_cycle(fps: float) -> int:
    """The fewest frames a cycle at ``fps`` has (:data:`MIN_CYCLE_S`)."""
    return max(2, int(math.ceil(MIN_CYCLE_S * fps)))


def pose_distance(pos: np.ndarray, fps: float, frames: np.ndarray) -> np.ndarray:
    """How far the pose of each of ``frames`` ``[C]`` of ``pos`` ``[F, 21, 3]`` is from the first frame's: the
    joints in the body's own frame (hips over the ground, facing one way) and their velocities (weighed by
    :data:`VELOCITY_WEIGHT_S`), mean over the joints, cm on the standard body."""
    norm = fit_normalisation(pos)
    _, _, local = root_and_local(norm.to_model(np.asarray(pos, np.float64)))
    vel = np.gradient(local, axis=0) * fps if len(local) > 1 else np.zeros_like(local)
    frames = np.asarray(frames, int)
    place = np.linalg.norm(local[frames] - local[0], axis=-1).mean(-1)
    speed = np.linalg.norm(vel[frames] - vel[0], axis=-1).mean(-1)
    return 100.0 * (place + VELOCITY_WEIGHT_S * speed)


def find_seam(pos: np.ndarray, fps: float, match: bool = True) -> int:
    """The seam (index of the frame that starts the next cycle) of the stretch ``pos`` ``[F, 21, 3]``: with
    ``match`` the frame of its second half (the cycle at least :data:`MIN_CYCLE_S`) whose pose is nearest the first
    frame's (:func:`pose_distance`); else its last frame."""
    n, least = len(pos), least_cycle(fps)
    if n - 1 < least:
        raise ValueError(f"the stretch has {n} frames ({(n - 1) / fps:.2f} s of motion); a loop needs at least "
                         f"{least + 1} ({MIN_CYCLE_S:g} s): widen the frame range")
    if not match:
        return n - 1
    candidates = np.arange(max(n // 2, least), n)
    return int(candidates[int(np.argmin(pose_distance(pos, fps, candidates)))])


def unwound(pos: np.ndarray, seam: int) -> tuple[np.ndarray, float]:
    """The stretch ``pos`` ``[F, 21, 3]`` with its net turn from the first frame to the ``seam`` taken off, and that
    turn (radians about the up axis): frame t turned back about the vertical through its hips by t / seam of it, the
    hips' ground path turned step by step with it (the first frame as it is), so that the body walks the same steps
    along a path that no longer turns overall."""
    yaw = heading(pos)
    turn = float(yaw[seam] - yaw[0])
    if abs(turn) < 1e-6:
        return pos, 0.0
    ground = list(GROUND_AXES)
    root = np.zeros((len(pos), 3))
    root[:, ground] = pos[:, ROOT][:, ground]
    back = yaw_matrix(-turn * np.arange(len(pos)) / seam)  # [F, 3, 3]
    path = np.concatenate([root[:1], root[0] + np.cumsum(np.einsum("fij,fj->fi", back[:-1], np.diff(root, axis=0)),
                                                         axis=0)])
    out = np.einsum("fij,fkj->fki", back, pos - root[:, None]) + path[:, None]
    out[..., UP_AXIS] = pos[..., UP_AXIS]
    return out, turn


def cross_fade(end: np.ndarray, into: np.ndarray) -> np.ndarray:
    """The frames ``end`` ``[B, 21, 3]`` cross-faded (smoothstep) into ``into`` (as many frames), ``into``'s weight
    rising from its first frame to 1 after its last."""
    s = (np.arange(len(end)) + 1.0) / len(end)
    w = (s * s * (3.0 - 2.0 * s))[:, None, None]
    return (1.0 - w) * end + w * into


def loop_positions(engine, pos: np.ndarray, fps: float, blend: int, match: bool = True, in_place: bool = False,
                   lead: np.ndarray | None = None, follow_take: bool = True) -> Loop:
    """The stretch ``pos`` ``[F, 21, 3]`` at ``fps`` made into a cycle (see the module). ``blend``: frames before
    the seam made again (at most half the cycle; 0: none, the seam left as it is). ``lead`` ``[P, 21, 3]``: the
    take's frames before the stretch (the in-betweener reads them with the cycle before the blend, and where there
    are ``blend`` of them, the blend is half a cross-fade into them; default: none). ``follow_take``: the
    in-between leans on the cycle where it did what the blend must, as Fill Gap's."""
    pos = np.asarray(pos, np.float64)
    seam = find_seam(pos, fps, match)
    match_cm = float(pose_distance(pos, fps, np.array([seam]))[0])
    pos, turn = unwound(pos, seam)
    ground = list(GROUND_AXES)
    travel = np.zeros(3)
    travel[ground] = pos[seam, ROOT, ground] - pos[0, ROOT, ground]
    nxt = pos[:seam] + travel  # the next cycle, from its first frame: what the blend arrives in
    blend = int(min(max(blend, 0), seam // 2))
    kept = pos[:seam - blend]
    lead = np.empty((0, *pos.shape[1:])) if lead is None else np.asarray(lead, np.float64)
    if blend:
        made = inbetween_positions(engine, np.concatenate([lead, kept]), nxt, fps, blend, follow_take)
        if len(lead) >= blend:  # half of it the cycle's end cross-faded into the take's frames that lead into its start
            made = 0.5 * (made + cross_fade(pos[seam - blend:seam], lead[-blend:] + travel))
        cycle = np.concatenate([kept, made, nxt[:1]])
    else:
        cycle = np.concatenate([kept, nxt[:1]])
    loop = Loop(cycle, seam, travel, match_cm, blend, turn)
    return loop.on_the_spot() if in_place else loop
