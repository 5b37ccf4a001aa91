"""Curve-driven synthesis on the NumPy engine: a character walks a path with the model.

Window by window (``n`` frames each): the control signal that walks the path from where the
character is (:func:`paths.control_signal`: the root's velocity and yaw rate, steering any
offset from the path and its heading out over ``return_frames``) takes the place of the root
channels of the model's prediction, and the window, fed back as context, tells the model how
the body moves: the model reads the root channels of its context, so the body it predicts next
walks at the speed and turns as the path asks, and the root stays on the path. The pose's jump
at each window's first frame is faded out (:func:`smooth_seam`) and every window is put back on
the seed's skeleton.

A character that stands away from the path's start walks there first, along a lead-in that leaves
the way it moves (or faces), meets the path along its tangent and turns no tighter than its pace allows,
and then follows the path from its start; with no frame count it walks until it reaches the
path's end (one lap of a closed path), however fast it walks.

The paper's run-time control (fine-tuning a copy of the weights on control costs each window)
is :mod:`follow_torch`, which needs torch; this module needs only NumPy, which Blender has.

Features are RAW ``[T, C]`` in :data:`conventions.LAYOUT` order; positions are metres, Y-up,
:data:`conventions.MODEL_FPS`, the standard skeleton (see :mod:`normalise`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path as FilePath

import numpy as np

from ..inference.engine import Engine, bone_lengths, on_learnt_body, project_to_skeleton
from ..inference.steps import drive
from ..io.checkpoint import Checkpoint, walk_seed_index
from ..motion.conventions import LAYOUT, MODEL_FPS, UP_AXIS
from ..motion.features import (
    RootStart,
    continue_positions,
    facing,
    features_to_positions,
    heading,
    integrate_root,
    on_body_of,
    positions_to_features,
    yaw_matrix,
)
from ..motion.geometry import rotate_ground
from ..motion.stance import planted_steps
from .normalise import fit_normalisation, model_frames_available, sample_at
from .paths import Path, Steering, control_signal, turning_path
from .seam import SEAM_FRAMES, blend_seam
from .skeleton import join_clip, sampled_on_bones

WALK_SPEED = 1.3  # m/s used when the seed barely moves (its own speed cannot steer anything)
LEAD_IN = 0.3  # metres: a character farther than this from the path's start walks to it first
LEAD_IN_STEP = 0.05  # metres between the points of a lead-in
LEAD_IN_TURN_S = 0.35  # a lead-in turns on the distance the character covers in this many seconds,
LEAD_IN_RADIUS = (0.3, 1.5)  # within these radii (metres)
STILL_SPEED = 0.3  # m/s: slower than this, a character's lead-in starts the way it faces
MAX_STRETCH = 3.0  # with no frame count, give up after this many times the frames the path should take
ARRIVED = 0.1  # metres: with no frame count, the walk ends this close to the path's end


@dataclass
class ControlSettings:
    speed: float | None = None  # m/s along the path; None: the seed motion's own ground speed
    return_frames: float = 30.0  # frames over which an offset from the path (and its heading) is steered out
    seam_frames: int = SEAM_FRAMES  # frames over which the pose's jump at each window's start is faded out


def natural_speed(feats: np.ndarray, fps: float = MODEL_FPS) -> float:
    """Mean ground speed (m/s) of the root in raw features ``[T, C]``."""
    return float(np.linalg.norm(np.asarray(feats)[:, LAYOUT.velocity], axis=-1).mean() * fps)


def match_mean(steps: np.ndarray, control: np.ndarray) -> np.ndarray:
    """``steps`` ``[n, 2]`` turned and scaled (one rotation, one factor) so that their mean is the mean of
    ``control`` ``[n, 2]``: the stride's own rhythm and sway, at the control's pace and direction. Where the
    two disagree by more than half or a quarter turn, the control as it is."""
    a, b = steps.mean(0), control.mean(0)
    norm_a, norm_b = np.linalg.norm(a), np.linalg.norm(b)
    if norm_a < 1e-6 or norm_b < 1e-6 or not 0.5 < norm_b / norm_a < 2.0:
        return np.array(control, np.float64)
    turn = np.arctan2(b[0], b[1]) - np.arctan2(a[0], a[1])  # rotate_ground(turn, a) points along b
    if abs(np.angle(np.exp(1j * turn))) > np.pi / 4:
        return np.array(control, np.float64)
    return rotate_ground(turn, steps) * (norm_b / norm_a)


def smooth_seam(ctx: np.ndarray, new: np.ndarray, frames: int) -> np.ndarray:
    """Raw window ``new`` ``[n, C]`` with the jump of its body pose from the raw context ``[m, C]``
    faded out over ``frames`` frames (:func:`seam.blend_seam` on the root-local joints)."""

    if frames <= 0:
        return new
    out = new.copy()
    pose = lambda f: f[:, LAYOUT.positions].reshape(len(f), -1, 3)  # noqa: E731
    out[:, LAYOUT.positions] = blend_seam(pose(ctx), pose(new), frames, land=False).reshape(len(new), -1)
    return out


class PathFollower:
    """Walks the STRNN along a :class:`paths.Path` on the NumPy engine. Build with :meth:`load`."""

    def __init__(self, engine: Engine, settings: ControlSettings | None = None):
        engine.ckpt.require_generator("follow a path")
        self.engine, self.ckpt, self.settings = engine, engine.ckpt, settings or ControlSettings()
        self.m, self.n = engine.m, engine.n

    @classmethod
    def load(cls, folder: str | FilePath | None = None, settings: ControlSettings | None = None, **kw):
        """Load a release folder (default: the bundled model)."""
        return cls(Engine.load(folder), settings, **kw)

    def window(self, ctx: np.ndarray, control: np.ndarray, lengths: np.ndarray,
               aim: np.ndarray | None = None, first: bool = True) -> np.ndarray:
        """The next ``n`` raw frames ``[n, C]`` after raw context ``[m, C]``: the model's prediction with
        the raw root channels ``control`` ``[n, 3]`` in place of its own: its yaw rate as it is, and its
        velocity as the steps of the planted foot (:func:`planted_steps`) turned and scaled to the
        control's mean step, so that the feet stay where they touch down. ``lengths`` and ``aim`` (the
        bones, the roots' aimed positions) are for followers that steer the model itself. ``first``: the
        context is the seed's; after it, the context is the walk's own and the model runs without its
        backward decoder (:meth:`Engine.predict_next`: 1.3 x the frames a second, the paths as near)."""
        predict = self.engine.predict if first else self.engine.predict_next
        new = predict(np.asarray(ctx, np.float32)[None])[0]
        new[:, LAYOUT.yaw_rate] = control[:, 2]
        new[:, LAYOUT.velocity] = match_mean(planted_steps(new, control[:, :2]), control[:, :2])
        return new

    def follow(self, seed: np.ndarray, start: RootStart, path: Path, frames: int | None = None,
               speed: float | None = None) -> np.ndarray:
        """Raw features ``[frames, C]`` continuing the raw seed ``[T >= m, C]`` (whose first frame's
        root is ``start``) along ``path``; ``frames`` None: until the path ends (one lap if cyclic);
        ``speed`` (m/s) None: the settings' (else the seed's own)."""
        return drive(self.follow_steps(seed, start, path, frames, speed))

    def follow_steps(self, seed: np.ndarray, start: RootStart, path: Path, frames: int | None = None,
                     speed: float | None = None):
        """:meth:`follow` as a step generator (:mod:`steps`): yields the fraction done after each
        window, returns the features. With ``frames`` None it walks until its projection reaches the
        path's end (one lap of a cyclic path), at most :data:`MAX_STRETCH` times the planned frames."""
        cfg = self.settings
        seed = np.asarray(seed, np.float32)
        speed = speed or cfg.speed or natural_speed(seed[-self.m:])
        speed = speed if speed >= 0.3 else WALK_SPEED
        root, yaw = integrate_root(seed, start)
        p, theta = root[-1], float(yaw[-1])
        s = path.project(p[[0, 2]], 0.0, path.length, tie=0.05)  # at a crossing, the earlier branch
        goal = path.length if path.cyclic else path.length - s  # arc length still to walk
        planned = max(1, int(math.ceil(goal / speed * MODEL_FPS)))
        limit = planned * MAX_STRETCH if frames is None else frames
        # a seed shorter than the model reads is led in by its first frame (Engine.full_context)
        ctx, lengths = self.engine.full_context(seed[None])[0], bone_lengths(seed[None, -self.m:])
        out, total, walked = [], 0, 0.0
        while total < limit and (frames is not None or not out or walked < goal - ARRIVED):
            control, aim = control_signal(path, p[[0, 2]], theta, s, speed, self.n + 1, MODEL_FPS,
                                          Steering(cfg.return_frames))
            control = control[1:]  # the context's last frame already holds the step into the window
            aim = rotate_ground(-theta, aim[1:-1] - p[[0, 2]])  # new frames' roots, in the last root's frame
            new = self.window(ctx, control, lengths[0, 1:], aim, first=not out)
            new = project_to_skeleton(smooth_seam(ctx, new, cfg.seam_frames)[None], lengths)[0]
            r, y = integrate_root(np.concatenate([ctx[-1:], new]), RootStart(p, theta))
            p, theta = r[-1], float(y[-1])
            before = s
            s = path.project(p[[0, 2]], s, s + 2.0 + speed * self.n / MODEL_FPS)  # never backwards
            walked += s - before
            if path.cyclic and s >= path.length:
                s -= path.length
            out.append(new)
            total += len(new)
            ctx = np.concatenate([ctx, new])[-self.m:]
            yield min(total / frames, 1.0) if frames else min(walked / max(goal, 1e-9), 1.0)
        new = np.concatenate(out)
        if frames is not None:
            return new[:frames]
        return new[:self._arrival(new, goal, walked)]

    def _arrival(self, new: np.ndarray, goal: float, walked: float) -> int:
        """How many of the frames of a walk to a path's end to keep: those up to where the walk reached it
        (the last window overshoots by up to a window), and at least one."""
        if walked <= goal:
            return len(new)
        speeds = np.linalg.norm(new[:, LAYOUT.velocity], axis=-1)
        past = walked - goal  # metres walked beyond the end, in the last frames
        back = np.cumsum(speeds[::-1])
        return max(1, len(new) - int(np.searchsorted(back, past)))


def align_to_path(seed: np.ndarray, path: Path) -> np.ndarray:
    """Seed positions ``[T, 21, 3]`` turned and moved on the ground so that the last frame's root
    stands on the path's start, facing along it."""
    seed = np.asarray(seed, np.float64)
    turn = float(path.heading(0.0) - heading(seed)[-1])
    pivot = seed[-1, 0].copy()
    pivot[UP_AXIS] = 0.0
    moved = np.einsum("ij,fkj->fki", yaw_matrix(np.array(turn)), seed - pivot)
    start = path.at(0.0)
    moved[..., 0] += start[0]
    moved[..., 2] += start[1]
    return moved.astype(np.float32)


def with_lead_in(path: Path, position: np.ndarray, distance: float = LEAD_IN,
                 direction: np.ndarray | None = None, speed: float = 0.0) -> Path:
    """``path``, or when ground ``position`` ``[2]`` is farther than ``distance`` from its start, the walk
    from there to its start followed by the path (a closed path's whole lap).

    The walk there leaves ``position`` along ``direction`` ``[2]`` (the way the character moves or faces;
    None: towards the path's start) and meets the path along the path's own tangent, turning no tighter
    than a character moving at ``speed`` (m/s) can (:func:`lead_in_radius`; :func:`paths.turning_path`):
    a straight lead-in made a corner where it met the path, and a runner coming at it from the side
    turned there within a frame."""
    position = np.asarray(position, np.float64)
    start = path.at(0.0)
    if np.linalg.norm(start - position) <= distance:
        return path
    leave = start - position if direction is None else np.asarray(direction, np.float64)
    lead = turning_path(position, leave, start, path.tangent(0.0), lead_in_radius(speed), LEAD_IN_STEP)
    return Path(np.concatenate([lead[:-1], path.points]), cyclic=False)


def lead_in_radius(speed: float) -> float:
    """The tightest turn (metres) of a lead-in for a character moving at ``speed`` (m/s): a walker at
    1.3 m/s turns on 0.46 m, a runner at 4 m/s on 1.4 m."""
    return float(np.clip(speed * LEAD_IN_TURN_S, *LEAD_IN_RADIUS))


def travel(seed: np.ndarray) -> tuple[np.ndarray, float]:
    """(ground direction ``[2]`` (x, z), speed m/s) in which positions ``[T, 21, 3]`` (30 fps, metres) move
    over their last sixth of a second; the direction they face where they barely move."""
    back = min(len(seed) - 1, 5)
    step = seed[-1, 0, [0, 2]] - seed[len(seed) - 1 - back, 0, [0, 2]]
    speed = float(np.linalg.norm(step)) * MODEL_FPS / max(back, 1)
    return (step if speed > STILL_SPEED else facing(seed[-1:])[0, [0, 2]]), speed


def follow_path(follower: PathFollower, seed: np.ndarray, path: Path, frames: int | None = None,
                align: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Positions ``[frames, 21, 3]`` walking ``path`` after seed positions ``[T >= m, 21, 3]``
    (metres, Y-up, 30 fps, the standard skeleton), and their raw features ``[frames, C]``.
    ``align`` first puts the seed on the path's start (else it walks from where it is)."""
    return drive(follow_path_steps(follower, seed, path, frames, align))


def follow_path_steps(follower: PathFollower, seed: np.ndarray, path: Path, frames: int | None = None,
                      align: bool = True, speed: float | None = None):
    """:func:`follow_path` as a step generator: yields the fraction done after each window. A seed on a rig unlike
    every body the model learnt walks on the body it learnt most and comes back on its own bones
    (:func:`engine.on_learnt_body`; the features returned are the model's, on that body)."""
    seed = align_to_path(seed, path) if align else np.asarray(seed, np.float32)
    seen, back = on_learnt_body(follower.engine, seed)
    feats, start = positions_to_features(seen)
    new = yield from follower.follow_steps(feats, start, path, frames, speed)
    return back(continue_positions(feats, start, new)), new


def walk_seed(ckpt: Checkpoint) -> np.ndarray:
    """Positions ``[m, 21, 3]`` of the shipped seed that walks (by its clip name; else the first seed)."""
    if not len(ckpt.seeds):
        raise ValueError("the model ships no seed motion: give the armature an action to start from")
    return features_to_positions(ckpt.seeds[walk_seed_index(ckpt.seed_names)])


def follow_curve_positions(follower: PathFollower, points: np.ndarray, cyclic: bool, fps: float,
                           frames: int | None = None, speed: float | None = None, context: np.ndarray | None = None,
                           rest: np.ndarray | None = None) -> np.ndarray:
    """Scene positions ``[frames, 21, 3]`` at ``fps`` walking a curve.

    ``points`` ``[P, 3]``: the curve in the scene (Y-up, scene units). ``context`` ``[F, 21, 3]``:
    the clip to continue (its last frames at ``fps``), or None to start on the curve from a
    shipped seed sized like ``rest`` ``[21, 3]`` (the rig's rest joints). ``frames`` None: until the
    curve ends; ``speed`` in scene units per second, None: the motion's own."""
    return drive(follow_curve_positions_steps(follower, points, cyclic, fps, frames, speed, context, rest))


def follow_curve_positions_steps(follower: PathFollower, points: np.ndarray, cyclic: bool, fps: float,
                       frames: int | None = None, speed: float | None = None, context: np.ndarray | None = None,
                       rest: np.ndarray | None = None):
    """:func:`follow_curve_positions` as a step generator: yields the fraction done after each window.
    A clip that ends away from the curve's start walks to it first (:func:`with_lead_in`)."""

    if context is not None:
        duration = (len(context) - 1) / fps
        ctx = sample_at(context, fps, duration - np.arange(model_frames_available(len(context), fps))[::-1] / MODEL_FPS)
        norm = fit_normalisation(ctx)
        seed = norm.to_model(ctx)
    else:
        norm = fit_normalisation(np.asarray(rest)[None])
        seed = walk_seed(follower.ckpt)
    path = Path(np.asarray(points, np.float64)[:, [0, 2]] * norm.scale, cyclic)
    if context is not None:
        direction, moving = travel(seed)
        path = with_lead_in(path, seed[-1, 0, [0, 2]], direction=direction, speed=moving)
    n_model = None if frames is None else int(math.ceil(frames * MODEL_FPS / fps)) + 1
    walked, _ = yield from follow_path_steps(follower, seed, path, n_model, align=context is None,
                                             speed=speed * norm.scale if speed else None)
    new = norm.to_user(walked)
    # on the rig's own body, which its solve keeps: from the shipped seed's body (scaled to the legs of ``rest``), or
    # after a clip from whatever chest and pelvis the walk drifted to (the clip's last frame holds the rig's)
    if context is None:
        seq, first = on_body_of(new, rest), 0
    else:
        seq, first = join_clip(ctx, on_body_of(new, ctx[-1])), 1
    duration = (len(seq) - 1) / MODEL_FPS
    count = frames if frames is not None else int(math.floor(duration * fps + 1e-6)) + 1 - first
    return sampled_on_bones(seq, (np.arange(count) + first) * (MODEL_FPS / fps))  # on the bones between frames
