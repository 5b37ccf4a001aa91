"""Curve-driven synthesis: the paper's run-time control, with the torch model.

Window by window (``n`` frames each): compute the control signal that walks the path
from where the character is (:func:`paths.control_signal`), then fine-tune a COPY of the
pre-trained weights for a few steps on the control costs, predict the window with it,
and restore the pre-trained weights before the next window, so the rollout never drifts
off the learnt manifold. Costs (DESIGN.md), over the predicted window:

- ``H_ctr``: squared deviation of the root channels (velocity, yaw rate; normalised
  units) from the control signal;
- ``H_bone``: squared relative deviation of bone lengths from the seed's skeleton;
- ``H_fp``: squared horizontal foot speed (cm / frame), weighted by the predicted contacts;
- and, beyond the paper, H_ctr integrated: the squared distance of the window's root
  positions from where the control signal aims them (10 cm units), which stops small
  velocity errors from adding up along the path.

Only the predictor LSTM cell is fine-tuned by default; the frozen encoder state and
decoded context are computed once per window and the frozen spatial networks run folded
(:mod:`spatial_fold`), so a 1,000-frame path takes a few seconds on one CPU thread.
Each window's pose jump at its first frame is faded out (:func:`smooth_seam`).

Features are RAW ``[T, C]`` in :data:`conventions.LAYOUT` order; positions are metres,
Y-up, :data:`conventions.MODEL_FPS`, the standard skeleton (see :mod:`normalise`).
"""

from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass, replace
from pathlib import Path as FilePath

import numpy as np
import torch

from ..inference.engine import bone_lengths, project_to_skeleton
from ..inference.spatial_fold import fold_spatial
from ..inference.steps import drive
from ..inference.torch_engine import build_model
from ..io.checkpoint import Checkpoint, load_release, walk_seed_index
from ..motion.conventions import CONTACT_JOINTS, LAYOUT, MODEL_FPS, PARENTS, UP_AXIS
from ..motion.features import (
    RootStart,
    continue_positions,
    features_to_positions,
    heading,
    integrate_root,
    positions_to_features,
    yaw_matrix,
)
from ..motion.geometry import rotate_ground
from .normalise import fit_normalisation, model_frames_available, sample_at
from .paths import Path, Steering, control_signal
from .seam import SEAM_FRAMES, blend_seam

WALK_SPEED = 1.3  # m/s used when the seed barely moves (its own speed cannot steer anything)
POSITION_SCALE = 0.1  # metres: root position errors are costed in units of 10 cm


@dataclass
class ControlSettings:
    speed: float | None = None  # m/s along the path; None: the seed motion's own ground speed
    steps: int = 4  # fine-tuning steps of the weight copy per window (0: plain prediction)
    lr: float = 1e-3  # Adam learning rate of the fine-tuned copy (Adam moves each weight about lr per step)
    w_ctr: float = 1.0  # weight of H_ctr
    w_bone: float = 10.0  # weight of H_bone
    w_fp: float = 0.5  # weight of H_fp
    w_pos: float = 1.0  # weight of the root positions' deviation from the path (H_ctr integrated; 10 cm units)
    tune: str = "predictor"  # which weights the copy fine-tunes: "predictor" (LSTM cell, fast) or "all"
    return_frames: float = 30.0  # frames over which an offset from the path (and its heading) is steered out
    seam_frames: int = SEAM_FRAMES  # frames over which the pose's jump at each window's start is faded out
    seed: int = 0  # torch seed: a fixed seed gives the same motion
    threads: int = 1  # torch CPU threads while following (batch 1: more cost more than they give); 0: as set


def natural_speed(feats: np.ndarray, fps: float = MODEL_FPS) -> float:
    """Mean ground speed (m/s) of the root in raw features ``[T, C]``."""
    return float(np.linalg.norm(np.asarray(feats)[:, LAYOUT.velocity], axis=-1).mean() * fps)


def ground_track(raw: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Headings ``[T]`` and root ground positions ``[T, 2]`` (x, z) integrated over raw features
    ``[T, C]``, relative to the first frame's root and heading."""
    yaw_rate, vel = raw[:, LAYOUT.yaw_rate], raw[:, LAYOUT.velocity]
    yaw = torch.cat([yaw_rate.new_zeros(1), torch.cumsum(yaw_rate[:-1], 0)])
    return yaw, torch.cat([vel.new_zeros(1, 2), torch.cumsum(rotate_ground(yaw[:-1], vel[:-1], torch), 0)])


def foot_speed_cm(raw: torch.Tensor) -> torch.Tensor:
    """Horizontal speed (cm / frame) ``[T - 1, 4]`` of the contact joints over raw features ``[T, C]``."""
    yaw, root = ground_track(raw)
    local = raw[:, LAYOUT.positions].reshape(len(raw), -1, 3)[:, CONTACT_JOINTS][..., [0, 2]]  # (T, 4, 2)
    feet = rotate_ground(yaw[:, None], local, torch) + root[:, None]
    return 100.0 * torch.linalg.vector_norm(feet[1:] - feet[:-1], dim=-1)


def _folded_frames(ckpt: Checkpoint):
    """The frozen spatial encoder and decoder of ``ckpt`` as folded torch functions ``(N, C) -> (N, W)``
    and ``(N, W) -> (N, C)``, equal to ``STRNN.encode_frame`` / ``decode_frame`` in eval mode."""
    w = {k: np.asarray(v, np.float32) for k, v in ckpt.weights.items()}
    to = lambda a: torch.from_numpy(np.array(a, np.float32))  # noqa: E731 (a writable copy)
    enc, dec, (scale, shift) = fold_spatial(w, ckpt.config, to=to, tanh=torch.tanh)
    scale, shift = to(scale), to(shift)
    return (lambda x: enc(x) * scale + shift), dec


def smooth_seam(ctx: np.ndarray, new: np.ndarray, frames: int) -> np.ndarray:
    """Raw window ``new`` ``[n, C]`` with the jump of its body pose from the raw context ``[m, C]``
    faded out over ``frames`` frames (:func:`seam.blend_seam` on the root-local joints)."""

    if frames <= 0:
        return new
    out = new.copy()
    pose = lambda f: f[:, LAYOUT.positions].reshape(len(f), -1, 3)  # noqa: E731
    out[:, LAYOUT.positions] = blend_seam(pose(ctx), pose(new), frames).reshape(len(new), -1)
    return out


class PathFollower:
    """Steers the torch STRNN along a :class:`paths.Path`. Build with :meth:`load`."""

    def __init__(self, ckpt: Checkpoint, settings: ControlSettings | None = None):
        ckpt.require_generator("follow a path")
        self.ckpt, self.settings = ckpt, settings or ControlSettings()
        self.model = build_model(ckpt)
        self.m, self.n = ckpt.config["encode_len"], ckpt.config["predict_len"]
        self.mean, self.std = torch.from_numpy(ckpt.mean), torch.from_numpy(ckpt.std)
        self.tuned = self._tunable(self.settings.tune)
        for p in self.model.parameters():
            p.requires_grad_(False)
        for p in self.tuned:
            p.requires_grad_(True)
        self.pretrained = [p.detach().clone() for p in self.tuned]
        self.encode_frame, self.decode_frame = _folded_frames(ckpt)

    @classmethod
    def load(cls, folder: str | FilePath | None = None, settings: ControlSettings | None = None) -> PathFollower:
        """Load a release folder (default: the bundled model)."""
        return cls(load_release(folder), settings)

    def _tunable(self, which: str) -> list[torch.nn.Parameter]:
        if which == "all":
            return list(self.model.parameters())
        if which == "predictor":
            return list(self.model.predictor.parameters())
        raise ValueError(f"tune must be 'predictor' or 'all', got {which!r}")

    def _restore(self) -> None:
        with torch.no_grad():
            for p, p0 in zip(self.tuned, self.pretrained):
                p.copy_(p0)

    def costs(self, last: torch.Tensor, out: torch.Tensor, control: torch.Tensor, lengths: torch.Tensor,
              aim: torch.Tensor | None = None) -> dict[str, torch.Tensor]:
        """H_ctr (and its integrated form, ``pos``), H_bone, H_fp of a normalised window ``out`` ``[n, C]``
        after the raw frame ``last`` ``[C]``; ``control`` ``[n, 3]`` normalised root channels, ``lengths``
        ``[J - 1]`` metres, ``aim`` ``[n, 2]`` where the roots should be (metres, in the frame of ``last``)."""
        raw = out * self.std + self.mean
        local = raw[:, LAYOUT.positions].reshape(len(raw), -1, 3)
        bones = torch.linalg.vector_norm(local[:, 1:] - local[:, PARENTS[1:]], dim=-1)
        contact = raw[:, LAYOUT.contacts].detach().clamp(0.0, 1.0)  # (n, 4)
        joined = torch.cat([last[None], raw])
        speed = foot_speed_cm(joined)  # (n, 4): into each predicted frame
        cost = {"ctr": (out[:, LAYOUT.root] - control).pow(2).mean(),
                "bone": (bones / lengths - 1.0).pow(2).mean(),
                "fp": (contact * speed.pow(2)).mean()}
        if aim is not None:
            cost["pos"] = ((ground_track(joined)[1][1:] - aim) / POSITION_SCALE).pow(2).sum(-1).mean()
        return cost

    def window(self, ctx: np.ndarray, control: np.ndarray, lengths: np.ndarray,
               aim: np.ndarray | None = None) -> np.ndarray:
        """The next ``n`` raw frames ``[n, C]`` after raw context ``[m, C]``, steered towards the raw
        root channels ``control`` ``[n, 3]`` (and the root positions ``aim`` ``[n, 2]``, metres in the
        frame of the context's last root) by a fine-tuned copy of the weights (restored after)."""
        cfg = self.settings
        x = ((torch.from_numpy(np.asarray(ctx, np.float32)) - self.mean) / self.std)[None]  # (1, m, C)
        target = (torch.from_numpy(np.asarray(control, np.float32)) - self.mean[LAYOUT.root]) / self.std[LAYOUT.root]
        last, rest = torch.from_numpy(np.asarray(ctx[-1], np.float32)), torch.from_numpy(lengths.astype(np.float32))
        goal = None if aim is None else torch.from_numpy(np.asarray(aim, np.float32))
        weights = {"ctr": cfg.w_ctr, "bone": cfg.w_bone, "fp": cfg.w_fp, "pos": cfg.w_pos}
        forward = self._predictor_pass(x) if cfg.tune == "predictor" else lambda: self.model(x)[0, self.m:]
        try:
            if cfg.steps > 0:
                opt = torch.optim.Adam(self.tuned, lr=cfg.lr)
                for _ in range(cfg.steps):
                    cost = self.costs(last, forward(), target, rest, goal)
                    loss = sum(weights[k] * v for k, v in cost.items())
                    opt.zero_grad()
                    loss.backward()
                    opt.step()
            with torch.no_grad():
                out = forward()
        finally:
            self._restore()
        return (out * self.std + self.mean).numpy()

    def _predictor_pass(self, x: torch.Tensor):
        """A function giving the normalised prediction ``[n, C]`` of context ``x`` ``[1, m, C]`` that reruns
        only the predictor: what the fine-tuned predictor cannot change (encoder state, decoded context,
        first input) is computed once, and the frozen spatial networks run folded (a few dense layers,
        as in the NumPy engine), so a fine-tuning step costs a fraction of a full pass."""
        model, enc, dec = self.model, self.encode_frame, self.decode_frame
        with torch.no_grad():
            _, (h, c) = model.encoder(enc(x[0])[None])
            state, step, decoded = (h[0], c[0]), model.start.expand_as(h[0]), []
            for _ in range(self.m):  # the backward decoder, as STRNN.spatio_temporal runs it
                state = model.decoder(step, state)
                decoded.append(dec(state[0]))
                step = enc(decoded[-1])
            decoded = torch.stack(decoded[::-1], 1)  # (1, m, C), chronological
            first = enc(x[:, -1])

        def forward() -> torch.Tensor:
            state, step, frames = (h[0], c[0]), first, []
            for _ in range(self.n):
                state = model.predictor(step, state)
                frames.append(dec(state[0]))
                step = enc(frames[-1])
            window = torch.cat([decoded, torch.stack(frames, 1)], 1)  # (1, m + n, C)
            return (model.filter(window) if model.filter is not None else window)[0, self.m:]

        return forward

    def follow(self, seed: np.ndarray, start: RootStart, path: Path, frames: int | None = None) -> np.ndarray:
        """Raw features ``[frames, C]`` continuing the raw seed ``[T >= m, C]`` (whose first frame's
        root is ``start``) along ``path``; ``frames`` None: until the path ends (one lap if cyclic)."""
        return drive(self.follow_steps(seed, start, path, frames))

    @contextlib.contextmanager
    def _threads(self):
        """torch's CPU threads as :attr:`ControlSettings.threads` asks, restored after."""
        before = torch.get_num_threads()
        wanted = self.settings.threads
        if wanted > 0 and wanted != before:
            torch.set_num_threads(wanted)
        try:
            yield
        finally:
            if torch.get_num_threads() != before:
                torch.set_num_threads(before)

    def follow_steps(self, seed: np.ndarray, start: RootStart, path: Path, frames: int | None = None):
        """:meth:`follow` as a step generator (:mod:`steps`): yields the fraction done after each
        window, returns the features. The weights are the pre-trained ones between windows, so
        closing it part way leaves the follower as it was."""
        cfg = self.settings
        torch.manual_seed(cfg.seed)
        seed = np.asarray(seed, np.float32)
        speed = cfg.speed if cfg.speed else natural_speed(seed[-self.m:])
        speed = speed if speed >= 0.3 else WALK_SPEED
        root, yaw = integrate_root(seed, start)
        p, theta = root[-1], float(yaw[-1])
        s = path.project(p[[0, 2]], 0.0, path.length, tie=0.05)  # at a crossing, the earlier branch
        if frames is None:
            frames = int(math.ceil((path.length - (0.0 if path.cyclic else s)) / speed * MODEL_FPS))
        ctx, lengths = seed[-self.m:], bone_lengths(seed[None, -self.m:])
        out, total = [], 0
        while total < frames:
            control, aim = control_signal(path, p[[0, 2]], theta, s, speed, self.n + 1, MODEL_FPS,
                                          Steering(cfg.return_frames))
            control = control[1:]  # the context's last frame already holds the step into the window
            aim = rotate_ground(-theta, aim[1:-1] - p[[0, 2]])  # new frames' roots, in the last root's frame
            with self._threads():
                new = self.window(ctx, control, lengths[0, 1:], aim)
            new = project_to_skeleton(smooth_seam(ctx, new, cfg.seam_frames)[None], lengths)[0]
            r, y = integrate_root(np.concatenate([ctx[-1:], new]), RootStart(p, theta))
            p, theta = r[-1], float(y[-1])
            s = path.project(p[[0, 2]], s, s + 2.0 + speed * self.n / MODEL_FPS)  # never backwards
            out.append(new)
            total += len(new)
            ctx = np.concatenate([ctx, new])[-self.m:]
            yield min(total / frames, 1.0)
        return np.concatenate(out)[:frames]


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


def follow_path(follower: PathFollower, seed: np.ndarray, path: Path, frames: int | None = None,
                align: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Positions ``[frames, 21, 3]`` walking ``path`` after seed positions ``[T >= m, 21, 3]``
    (metres, Y-up, 30 fps, the standard skeleton), and their raw features ``[frames, C]``.
    ``align`` first puts the seed on the path's start (else it walks from where it is)."""
    return drive(follow_path_steps(follower, seed, path, frames, align))


def follow_path_steps(follower: PathFollower, seed: np.ndarray, path: Path, frames: int | None = None,
                      align: bool = True):
    """:func:`follow_path` as a step generator: yields the fraction done after each window."""
    seed = align_to_path(seed, path) if align else np.asarray(seed, np.float32)
    feats, start = positions_to_features(seed)
    new = yield from follower.follow_steps(feats, start, path, frames)
    return continue_positions(feats, start, new), new


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
    return drive(follow_curve_steps(follower, points, cyclic, fps, frames, speed, context, rest))


def follow_curve_steps(follower: PathFollower, points: np.ndarray, cyclic: bool, fps: float,
                       frames: int | None = None, speed: float | None = None, context: np.ndarray | None = None,
                       rest: np.ndarray | None = None):
    """:func:`follow_curve_positions` as a step generator: yields the fraction done after each
    window; the follower's settings are restored however it ends."""

    if context is not None:
        duration = (len(context) - 1) / fps
        ctx = sample_at(context, fps, duration - np.arange(model_frames_available(len(context), fps))[::-1] / MODEL_FPS)
        norm = fit_normalisation(ctx)
        seed = norm.to_model(ctx)
    else:
        norm = fit_normalisation(np.asarray(rest)[None])
        seed = walk_seed(follower.ckpt)
    path = Path(np.asarray(points, np.float64)[:, [0, 2]] * norm.scale, cyclic)
    n_model = None if frames is None else int(math.ceil(frames * MODEL_FPS / fps)) + 1
    saved = follower.settings
    follower.settings = replace(saved, speed=speed * norm.scale if speed else None)
    try:
        walked, _ = yield from follow_path_steps(follower, seed, path, n_model, align=context is None)
        new = norm.to_user(walked)
    finally:
        follower.settings = saved
    if context is None:
        seq, first = new, 0
    else:
        seq, first = np.concatenate([ctx[-1:], blend_seam(ctx, new)]), 1
    duration = (len(seq) - 1) / MODEL_FPS
    count = frames if frames is not None else int(math.floor(duration * fps + 1e-6)) + 1 - first
    return sample_at(seq, MODEL_FPS, (np.arange(count) + first) / fps)
