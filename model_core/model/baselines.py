"""Two published motion-prediction baselines, to score STRNN against. The engines the add-on uses refuse
their release folders; a release may carry the project's siMLPe to share its first predicted window
(``checkpoint.SIMLPE``), which the NumPy twin of :class:`SiMLPe` runs (``inference/simlpe_engine.py``).

- siMLPe (Guo et al. 2023, "Back to MLP: A Simple Baseline for Human Motion Prediction"):
  the context's DCT along time, a stack of temporal fully connected blocks with a layer
  norm over the channels, the inverse DCT, offsets added to the last context frame.
- Residual GRU (Martinez et al. 2017, "On human motion prediction using recurrent neural
  networks"): one GRU cell shared by encoder and decoder, each output frame the input
  frame plus a linear read-out of the state; the decoder always reads its own output.

Both map a normalised context ``(B, m, C)`` to the next ``n`` normalised frames ``(B, n, C)``
(:data:`conventions.LAYOUT`). :class:`BaselineEngine` runs a release folder with the STRNN
engine's own open-loop rollout, on raw features, for ``scripts/evaluate.py``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn

from ..inference.engine import Engine
from ..inference.simlpe_engine import dct_matrix
from ..io.checkpoint import ARCHITECTURES, Checkpoint, CheckpointError, load_release
from ..motion.conventions import LAYOUT

_OTHER = np.setdiff1d(np.arange(LAYOUT.size), np.arange(LAYOUT.size)[LAYOUT.positions])  # root motion, contacts


@dataclass
class SiMLPeConfig:
    frame_size: int = LAYOUT.size  # channels per frame
    encode_len: int = 20  # m: context frames, also the length of the DCT
    predict_len: int = 20  # n: predicted frames, the first n of the m frames the network outputs
    blocks: int = 48  # temporal MLP blocks (the paper's)

    def __post_init__(self):
        if not 1 <= self.predict_len <= self.encode_len:
            raise ValueError(f"siMLPe predicts 1 to encode_len ({self.encode_len}) frames, not {self.predict_len}")

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass
class ResidualGRUConfig:
    frame_size: int = LAYOUT.size  # channels per frame
    encode_len: int = 20  # m: context frames
    predict_len: int = 20  # n: predicted frames
    width: int = 512  # GRU units (the paper's 1024 for one action, 512 here)

    def __post_init__(self):
        if self.encode_len < 2 or self.predict_len < 1:
            raise ValueError("the residual GRU needs at least 2 context frames and 1 predicted frame")

    def to_dict(self) -> dict:
        return asdict(self)


class TemporalBlock(nn.Module):
    """``x + norm(fc(x))`` on ``(T, B, C)`` (time first, so that mixing along it is one plain matrix
    product): ``fc`` mixes along time, ``norm`` is siMLPe's layer norm over the channels."""

    def __init__(self, channels: int, length: int):
        super().__init__()
        self.weight = nn.Parameter(torch.empty(length, length))
        self.bias = nn.Parameter(torch.zeros(length, 1, 1))
        self.norm = nn.LayerNorm(channels)
        nn.init.xavier_uniform_(self.weight, gain=1e-8)  # the paper's: each block starts as the identity

    def forward(self, x):
        return x + self.norm((self.weight @ x.flatten(1)).view_as(x) + self.bias)


class SiMLPe(nn.Module):
    def __init__(self, cfg: SiMLPeConfig):
        super().__init__()
        self.cfg = cfg
        c, m = cfg.frame_size, cfg.encode_len
        self.register_buffer("dct", torch.from_numpy(dct_matrix(m)), persistent=False)
        self.fc_in = nn.Linear(c, c)
        self.blocks = nn.Sequential(*(TemporalBlock(c, m) for _ in range(cfg.blocks)))
        self.fc_out = nn.Linear(c, c)
        nn.init.xavier_uniform_(self.fc_out.weight, gain=1e-8)  # starts as the zero-velocity predictor
        nn.init.zeros_(self.fc_out.bias)

    def forward(self, context: torch.Tensor) -> torch.Tensor:
        """Normalised context ``(B, m, C)`` -> the next n normalised frames ``(B, n, C)``."""
        b, m, c = context.shape
        x = (self.dct @ context.transpose(0, 1).flatten(1)).view(m, b, c)  # (m, B, C) frequencies
        x = self.fc_out(self.blocks(self.fc_in(x)))
        frames = (self.dct.T @ x.flatten(1)).view_as(x).transpose(0, 1)  # (B, m, C) offsets
        return frames[:, : self.cfg.predict_len] + context[:, -1:]

    def loss(self, pred: torch.Tensor, true: torch.Tensor) -> torch.Tensor:
        """The paper's: per-joint L2 of the frames plus the same of their frame-to-frame velocities."""
        return unit_errors(pred - true).mean() + unit_errors(pred.diff(dim=1) - true.diff(dim=1)).mean()


def unit_errors(delta: torch.Tensor) -> torch.Tensor:
    """``(..., C)`` -> ``(..., J + 7)``: the Euclidean error of each joint's position, the absolute
    error of each other channel (root motion, contacts)."""
    joints = delta[..., LAYOUT.positions].unflatten(-1, (-1, 3)).norm(dim=-1)
    return torch.cat([joints, delta[..., _OTHER].abs()], -1)


class ResidualGRU(nn.Module):
    def __init__(self, cfg: ResidualGRUConfig):
        super().__init__()
        self.cfg = cfg
        self.gru = nn.GRU(cfg.frame_size, cfg.width, batch_first=True)
        self.out = nn.Linear(cfg.width, cfg.frame_size)
        nn.init.zeros_(self.out.weight)  # starts as the zero-velocity predictor
        nn.init.zeros_(self.out.bias)

    def forward(self, context: torch.Tensor) -> torch.Tensor:
        """Normalised context ``(B, m, C)`` -> the next n normalised frames ``(B, n, C)``: the
        encoder reads all but the last frame, the decoder starts from it and reads its own output."""
        _, h = self.gru(context[:, :-1])  # (1, B, W)
        frame, frames = context[:, -1:], []
        for _ in range(self.cfg.predict_len):
            y, h = self.gru(frame, h)  # (B, 1, W)
            frame = frame + self.out(y)
            frames.append(frame)
        return torch.cat(frames, 1)

    def loss(self, pred: torch.Tensor, true: torch.Tensor) -> torch.Tensor:
        """The paper's L2 (mean squared error) over the predicted frames."""
        return (pred - true).pow(2).mean()


MODELS = {"simlpe": (SiMLPe, SiMLPeConfig), "residual_gru": (ResidualGRU, ResidualGRUConfig)}
assert set(MODELS) == set(ARCHITECTURES[1:])


def build_baseline(ckpt: Checkpoint) -> nn.Module:
    """The torch model of a baseline release, in eval mode."""
    if ckpt.architecture not in MODELS:
        raise CheckpointError(f"this model folder holds an {ckpt.architecture} model, not a baseline (one of "
                              f"{', '.join(MODELS)}): score it with scripts/evaluate.py --checkpoint")
    model_cls, config_cls = MODELS[ckpt.architecture]
    try:
        model = model_cls(config_cls(**ckpt.config))
        model.load_state_dict({k: torch.from_numpy(np.ascontiguousarray(v)) for k, v in ckpt.weights.items()})
    except (TypeError, ValueError, RuntimeError) as e:
        raise CheckpointError(f"{ckpt.architecture} weights do not match their config {ckpt.config}: {e}") from None
    return model.eval()


class BaselineEngine:
    """A baseline with the engine interface (raw features in and out). Build with :meth:`load`."""

    def __init__(self, ckpt: Checkpoint):
        ckpt.require_generator("predict motion")
        self.ckpt, self.name = ckpt, ckpt.architecture
        self.model = build_baseline(ckpt)
        self.m, self.n = ckpt.config["encode_len"], ckpt.config["predict_len"]
        self.mean, self.std = ckpt.mean, ckpt.std

    @classmethod
    def load(cls, folder: str | Path) -> BaselineEngine:
        return cls(load_release(folder))

    @property
    def seeds(self) -> np.ndarray:
        """Seed windows of the release, raw features ``[K, m, C]``."""
        return self.ckpt.seeds

    @torch.inference_mode()
    def predict_once(self, context: np.ndarray) -> np.ndarray:
        """Raw context ``[B, m, C]`` -> the next ``n`` raw frames ``[B, n, C]``, from one reading."""
        x = torch.from_numpy(((np.asarray(context, np.float32) - self.mean) / self.std).astype(np.float32))
        return self.model(x).numpy() * self.std + self.mean

    # The STRNN engine's prediction (the context read as it is and mirrored), rollout (skeleton
    # projection, contacts rounded) and position-level wrapper only call predict_once and read m,
    # so the baselines are generated exactly as STRNN is.
    mirrored_reading = Engine.mirrored_reading
    predict = predict_next = Engine.predict  # one model, no decoder: every window the same
    predict_first = Engine.predict_first
    lean_regularised = Engine.lean_regularised
    companion = simlpe = regularised = None  # a baseline release is one model
    full_context = Engine.full_context
    extrapolate = Engine.extrapolate
    extend = Engine.extend
