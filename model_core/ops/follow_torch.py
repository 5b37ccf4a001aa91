"""The paper's run-time control for curve-driven synthesis, with the torch model.

:class:`TorchPathFollower` walks a path as :class:`follow.PathFollower` does, window by window
from the control signal, but instead of putting the control into the prediction it fine-tunes
a COPY of the pre-trained weights for a few steps on the control costs, predicts the window with
it, and restores the pre-trained weights before the next window, so the rollout never drifts off
the learnt manifold. Costs (DESIGN.md), over the predicted window:

- ``H_ctr``: squared deviation of the root channels (velocity, yaw rate; normalised
  units) from the control signal;
- ``H_bone``: squared relative deviation of bone lengths from the seed's skeleton;
- ``H_fp``: squared horizontal foot speed (cm / frame), weighted by the predicted contacts;
- and, beyond the paper, H_ctr integrated: the squared distance of the window's root
  positions from where the control signal aims them (10 cm units), which stops small
  velocity errors from adding up along the path.

Only the predictor LSTM cell is fine-tuned by default; the frozen encoder state and
decoded context are computed once per window and the frozen spatial networks run folded
(:mod:`spatial_fold`). Needs torch: the extension follows curves with :mod:`follow` (NumPy);
this is the paper's method, kept for evaluation and research (``evaluate.py --paths --follow-torch``).
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass

import numpy as np
import torch

from ..inference.engine import Engine, offset_weights
from ..inference.spatial_fold import fold_spatial
from ..inference.torch_engine import build_model
from ..io.checkpoint import Checkpoint
from ..motion.conventions import CONTACT_JOINTS, LAYOUT, PARENTS
from ..motion.geometry import rotate_ground
from .follow import ControlSettings, PathFollower

POSITION_SCALE = 0.1  # metres: root position errors are costed in units of 10 cm


@dataclass
class TuningSettings:
    steps: int = 4  # fine-tuning steps of the weight copy per window (0: plain prediction)
    lr: float = 1e-3  # Adam learning rate of the fine-tuned copy (Adam moves each weight about lr per step)
    w_ctr: float = 1.0  # weight of H_ctr
    w_bone: float = 10.0  # weight of H_bone
    w_fp: float = 0.5  # weight of H_fp
    w_pos: float = 1.0  # weight of the root positions' deviation from the path (H_ctr integrated; 10 cm units)
    tune: str = "predictor"  # which weights the copy fine-tunes: "predictor" (LSTM cell, fast) or "all"
    seed: int = 0  # torch seed: a fixed seed gives the same motion
    threads: int = 1  # torch CPU threads while following (batch 1: more cost more than they give); 0: as set

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


class TorchPathFollower(PathFollower):
    """Steers the torch STRNN along a :class:`paths.Path` by fine-tuning. Build with :meth:`load`."""

    def __init__(self, engine: Engine, settings: ControlSettings | None = None, tuning: TuningSettings | None = None):
        super().__init__(engine, settings)
        self.tuning = tuning or TuningSettings()
        torch.manual_seed(self.tuning.seed)
        ckpt = engine.ckpt
        self.model = build_model(ckpt)
        self.mean, self.std = torch.from_numpy(ckpt.mean), torch.from_numpy(ckpt.std)
        self.tuned = self._tunable(self.tuning.tune)
        for p in self.model.parameters():
            p.requires_grad_(False)
        for p in self.tuned:
            p.requires_grad_(True)
        self.pretrained = [p.detach().clone() for p in self.tuned]
        self.encode_frame, self.decode_frame = _folded_frames(ckpt)

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
               aim: np.ndarray | None = None, first: bool = True) -> np.ndarray:
        """The next ``n`` raw frames ``[n, C]`` after raw context ``[m, C]``, steered towards the raw
        root channels ``control`` ``[n, 3]`` (and the root positions ``aim`` ``[n, 2]``, metres in the
        frame of the context's last root) by a fine-tuned copy of the weights (restored after). Every
        window is tuned and run whole, the seed's (``first``) and the later ones alike."""
        cfg = self.tuning
        x = ((torch.from_numpy(np.asarray(ctx, np.float32)) - self.mean) / self.std)[None]  # (1, m, C)
        target = (torch.from_numpy(np.asarray(control, np.float32)) - self.mean[LAYOUT.root]) / self.std[LAYOUT.root]
        last, rest = torch.from_numpy(np.asarray(ctx[-1], np.float32)), torch.from_numpy(lengths.astype(np.float32))
        goal = None if aim is None else torch.from_numpy(np.asarray(aim, np.float32))
        weights = {"ctr": cfg.w_ctr, "bone": cfg.w_bone, "fp": cfg.w_fp, "pos": cfg.w_pos}
        r = self.model.cfg.recon_len  # the window's decoded frames before the prediction
        forward = self._predictor_pass(x) if cfg.tune == "predictor" else lambda: self.model(x)[0, r:]
        try:
            with self._threads():
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
            # An offsets model's frames are offsets from the context's last frame (STRNNConfig.offsets).
            base = x[:, -1] if model.cfg.offsets else torch.zeros_like(x[:, -1])
            keep = offset_weights(self.n, model.cfg.offset_keep)
            for _ in range(model.cfg.recon_len):  # the backward decoder, as STRNN.spatio_temporal runs it
                state = model.decoder(step, state)
                decoded.append(base + dec(state[0]))
                step = enc(decoded[-1])
            decoded = torch.stack(decoded[::-1], 1)  # (1, r, C), chronological
            extra = model.context_code(x)
            skip = model.skip_frames(x)
            skip = torch.zeros(1, self.n, x.shape[-1]) if skip is None else skip
            first = enc(x[:, -1]) + extra

        def forward() -> torch.Tensor:
            state, step, frames = (h[0], c[0]), first, []
            for i in range(self.n):
                state = model.predictor(step, state)
                frames.append(base * float(keep[i]) + dec(state[0]) + skip[:, i])
                step = enc(frames[-1]) + extra
            window = torch.cat([decoded, torch.stack(frames, 1)], 1)  # (1, r + n, C)
            return (model.filter(window, x) if model.filter is not None else window)[0, model.cfg.recon_len:]

        return forward

    @contextlib.contextmanager
    def _threads(self):
        """torch's CPU threads as :attr:`TuningSettings.threads` asks, restored after."""
        before = torch.get_num_threads()
        wanted = self.tuning.threads
        if wanted > 0 and wanted != before:
            torch.set_num_threads(wanted)
        try:
            yield
        finally:
            if torch.get_num_threads() != before:
                torch.set_num_threads(before)

