"""Training STRNN: data windows, the input-noise schedule, the hybrid strategy
(spatio-temporal net with MSE + long-horizon cost; residual filter pre-trained on
ground truth; then only the filter fine-tuned on the frozen net's output),
atomic resumable checkpoints and optional data-parallel training (torchrun).
"""

from __future__ import annotations

import copy
import json
import logging
import os
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch
import torch.distributed as dist
from torch.nn.parallel import DistributedDataParallel

from ..io.checkpoint import PURPOSES, load_release, save_release
from ..io.files import unwritable, write_atomic
from ..motion.conventions import LAYOUT
from ..motion.features import (
    MIRROR_SIGN,
    MIRROR_SOURCE,
    features_to_positions,
    positions_to_features,
    scale_proportions,
)
from ..motion.noise import add_rotation_jitter
from ..ops.seam import PREDICT_SEAM_FRAMES, seam_fade
from .dataset import SPLITS, MotionData, Normaliser, load_folder, window_starts
from .strnn import STRNN, STRNNConfig, smoothness_cost

PHASES = ("spatio_temporal", "residual_pretrain", "residual_finetune")


@dataclass
class TrainConfig:
    data: str  # folder of BVH files (searched recursively)
    out: str = "runs/default"  # training state, log and release checkpoint go here
    model: STRNNConfig = field(default_factory=lambda: STRNNConfig(width=128))
    steps: int = 5000  # optimiser steps over all phases
    phase_split: tuple[float, float, float] = (0.8, 0.05, 0.15)  # fraction of steps per phase
    batch: int = 128  # windows per step (split across data-parallel ranks)
    optimizer: str = "adam"  # "adam" or "adadelta" (the paper's: lr 1, rho 0.95)
    lr: float = 1e-3
    weight_decay: float = 1e-5  # L2 on weights
    smooth_weight: float = 1.0  # w_s of the long-horizon cost
    # Recovery from the model's own output: contexts generated open loop for 1 to this many windows
    # (0: off) in this share of the first phase's steps, followed by the supervised window.
    rollout_windows: int = 0
    rollout_fraction: float = 0.5
    recon_weight: float = 1.0  # weight of the decoded (reconstructed) frames against the predicted ones in the MSE
    # Weight of the error of the joints' frame-to-frame motion (normalised positions), from the last context frame
    # on through the prediction: the first predicted frames must move on from where the context ends, at its pace.
    velocity_weight: float = 0.0
    # Weight of the error (m^2) of the joints' world positions over the predicted frames, the root's track and
    # heading integrated from the context's last frame as features_to_positions does: what MPJPE measures, where
    # a small error of the root's velocity every frame adds up to a body that falls behind its take (0: off).
    world_weight: float = 0.0
    noise_start: float = 0.1  # input-noise std at step 0 (normalised units)
    noise_zero_at: float = 0.5  # fraction of the first phase at which the noise reaches 0
    residual_noise: float = 0.05  # input noise while pre-training the filter on ground truth
    denoise_fraction: float = 0.25  # share of each batch whose context is re-derived from noisy positions ...
    denoise_max_cm: float = 6.0  # ... with a per-window noise std (cm) drawn from U(0, this): teaches denoising
    # Above 0: half of those contexts get jitter of the joints' rotations instead, of a per-window std drawn
    # from U(0, this) degrees (motion.noise.add_rotation_jitter), as a BVH's or a keyed rig's channels carry.
    denoise_rotation_deg: float = 0.0
    lr_final: float = 0.1  # cosine decay of the learning rate to this fraction within each phase
    seed: int = 0
    checkpoint_seconds: float = 120.0  # how often the resumable state is written
    val_every: int = 250  # steps between validation passes
    cache: str = "data/cache"  # cached arrays of the data folder
    max_minutes: float = 0.0  # stop (with a checkpoint) after this long; 0 = no limit
    command: str = ""  # the command line, recorded in the release metadata
    init: str = ""  # start from the weights of this training state or release folder (fine-tuning)
    purpose: str = PURPOSES[0]  # recorded in the release: "denoise" marks a model whose predictions are not for use
    mirror: float = 0.0  # share of training windows mirrored left to right (augmentation)
    # Above 0: each training window is played at a speed drawn log-uniformly from [1 / (1 + this), 1 + this]
    # times the capture's (time-warp augmentation, Windows.raw_frames): motion of other paces than the data's.
    # Rollout windows (rollout_windows) are played as captured.
    time_warp: float = 0.0
    # Above 0: each training window's torso and arms are made longer or shorter, each by a factor drawn
    # uniformly from [1 - this, 1 + this] (motion.features.scale_proportions): bodies of other proportions.
    proportions: float = 0.0
    # Every phase of a take captured at a whole multiple of the model's rate as a clip of its own
    # (dataset.load_folder's capture_phases), not only the first.
    capture_phases: bool = False
    # Before the release is written, recompute the batch norms' running statistics as the plain average
    # over this many training batches of the whole model's forward pass (0: keep them as trained).
    recalibrate_batches: int = 0
    hold_out: bool = False  # keep the held-out groups of configs/data.toml out of training and validation
    # torch device of the model and its batches ("cpu", "cuda", "cuda:1"); the windows are drawn and augmented
    # on the CPU either way, and the release is written from CPU copies of the weights.
    device: str = "cpu"


def phase_at(cfg: TrainConfig, step: int) -> str:
    a = cfg.phase_split[0] * cfg.steps
    b = a + cfg.phase_split[1] * cfg.steps
    if not cfg.model.residual:
        return PHASES[0]
    return PHASES[0] if step < a else PHASES[1] if step < b else PHASES[2]


def noise_std(cfg: TrainConfig, step: int) -> float:
    """Decreasing input noise: linear from ``noise_start`` to 0 (the paper's schedule)."""
    end = max(1.0, cfg.noise_zero_at * cfg.phase_split[0] * cfg.steps)
    return max(0.0, cfg.noise_start * (1.0 - step / end))


class Windows:
    """Normalised training windows ``(B, m + n, C)`` drawn from one split."""

    def __init__(self, data: MotionData, split: str, norm: Normaliser, length: int, stride: int = 1):
        clips = data.split(split)
        if not clips:
            raise ValueError(f"{data.root}: no clips in the {split!r} split")
        self.raw = np.concatenate([c.features for c in clips])
        self.feats = norm.encode(self.raw).astype(np.float32)
        self.norm = norm
        self.root, self.split = data.root, split
        self.lengths = [len(c.features) for c in clips]
        self._index(length, stride)

    def _index(self, length: int, stride: int) -> None:
        offsets = np.concatenate([[0], np.cumsum(self.lengths)[:-1]])
        starts = window_starts(self.lengths, length, stride)
        if len(starts) == 0:
            raise ValueError(f"{self.root}: no {self.split!r} clip is {length} frames long")
        self.starts = offsets[starts[:, 0]] + starts[:, 1]
        self.ends = offsets[starts[:, 0]] + np.asarray(self.lengths)[starts[:, 0]]  # one past each window's clip
        self.span = np.arange(length)

    def with_length(self, length: int, stride: int = 1) -> Windows:
        """Windows of another length over the same (shared, not copied) frames."""
        other = copy.copy(self)
        other._index(length, stride)
        return other

    def __len__(self):
        return len(self.starts)

    def batch(self, idx: np.ndarray, speeds: np.ndarray | None = None,
              bodies: np.ndarray | None = None) -> torch.Tensor:
        """Windows ``idx``; with ``speeds``, each played that many times as fast, and with ``bodies``
        ``(B, 2)``, each by a body of other proportions (:meth:`raw_frames`)."""
        if speeds is None and bodies is None:
            return torch.from_numpy(self.feats[self.starts[idx][:, None] + self.span])
        return torch.from_numpy(self.norm.encode(self.raw_frames(idx, speeds, bodies=bodies)).astype(np.float32))

    def raw_frames(self, idx: np.ndarray, speeds: np.ndarray | None, length: int | None = None,
                   bodies: np.ndarray | None = None) -> np.ndarray:
        """Un-normalised windows ``(B, length, C)`` played ``speeds`` ``(B,)`` times as fast (time-warp
        augmentation): frames sampled every ``speed`` frames of the clip, linearly between its frames, the
        root's per-frame motion scaled by the speed and contacts kept where they hold for most of the way.
        A window that a faster speed would carry past its clip's end is played as fast as its clip allows.
        ``bodies`` ``(B, 2)``: the factors of each window's torso and arms (:func:`scale_proportions`)."""
        length = len(self.span) if length is None else length
        if speeds is None:
            speeds = np.ones(len(idx))
        starts, ends = self.starts[idx], self.ends[idx]
        speeds = np.minimum(np.asarray(speeds, np.float64), (ends - 1 - starts) / max(length - 1, 1))
        t = starts[:, None] + speeds[:, None] * np.arange(length)
        lo = np.minimum(np.floor(t).astype(np.int64), ends[:, None] - 1)
        hi = np.minimum(lo + 1, ends[:, None] - 1)
        a = (t - lo)[..., None]
        out = (1.0 - a) * self.raw[lo] + a * self.raw[hi]
        out[..., LAYOUT.root] *= speeds[:, None, None]
        out[..., LAYOUT.contacts] = out[..., LAYOUT.contacts] >= 0.5
        if bodies is not None:
            out = scale_proportions(out, bodies[:, 0], bodies[:, 1])
        return out.astype(np.float32)

    def noisy_contexts(self, idx: np.ndarray, m: int, max_cm: float, rng: np.random.Generator,
                       max_deg: float = 0.0, speeds: np.ndarray | None = None,
                       bodies: np.ndarray | None = None) -> torch.Tensor:
        """Normalised contexts ``(B, m, C)`` re-derived, as at inference, from the windows'
        positions plus Gaussian noise of a per-window std drawn from U(0, ``max_cm``), or, with
        ``max_deg`` above 0, for half of them rotation jitter of a std drawn from U(0, ``max_deg``)."""
        # All windows convert together, frames first ([m, B, 21, 3]): each as on its own, at a fraction of the cost.
        pos = features_to_positions(self.raw_frames(idx, speeds, m, bodies).transpose(1, 0, 2))
        turned = rng.random(len(idx)) < 0.5 if max_deg > 0 else np.zeros(len(idx), bool)
        std = rng.uniform(0, max_cm, len(idx)) / 100.0
        pos = pos + rng.normal(0.0, 1.0, pos.shape) * np.where(turned, 0.0, std)[None, :, None, None]
        for b in np.flatnonzero(turned):
            pos[:, b] = add_rotation_jitter(pos[:, b], rng.uniform(0, max_deg), rng)
        feats = positions_to_features(pos)[0].transpose(1, 0, 2)
        return torch.from_numpy(self.norm.encode(feats).astype(np.float32))


class Mirror:
    """Left-right mirroring of normalised windows ``(B, T, C)``, row by row (augmentation)."""

    def __init__(self, norm: Normaliser):
        self.mean, self.std = torch.from_numpy(norm.mean), torch.from_numpy(norm.std)
        self.src, self.sign = torch.from_numpy(MIRROR_SOURCE), torch.from_numpy(MIRROR_SIGN)

    def __call__(self, x: torch.Tensor, rows: np.ndarray) -> torch.Tensor:
        if x is None or not rows.any():
            return x
        rows = torch.from_numpy(rows[: len(x)])
        raw = x[rows] * self.std + self.mean
        x = x.clone()
        x[rows] = (raw[..., self.src] * self.sign - self.mean) / self.std
        return x


def window_loss(model: STRNN, window: torch.Tensor, cfg: TrainConfig, phase: str, noise: float, net=None,
                noisy: torch.Tensor | None = None, norm: tuple[torch.Tensor, torch.Tensor] | None = None):
    """The loss of one phase on a batch of clean windows ``(B, m + n, C)``; the model's output is the window's
    last r + n frames (r: :attr:`STRNNConfig.recon_len`).

    ``noisy`` replaces the first contexts with ones derived from noisy positions; ``net`` is
    the (possibly data-parallel) wrapper that runs the first phase's forward; ``norm`` (the features' mean and
    std) is needed by ``cfg.world_weight``.
    """
    m, r = cfg.model.encode_len, cfg.model.recon_len
    if phase == PHASES[1]:
        noisy = window + cfg.residual_noise * torch.randn_like(window)
        return (model.filter(noisy[:, m - r:], noisy[:, :m]) - window[:, m - r:]).pow(2).mean()
    context = window[:, :m]
    window = window[:, m - r:]
    if noisy is not None:
        context = torch.cat([noisy, context[len(noisy):]])
    if noise > 0:
        context = context + noise * torch.randn_like(context)
    if phase == PHASES[2]:
        with torch.no_grad():
            decoded, predicted = model.spatio_temporal(context)
        out = model.filter(torch.cat([decoded, predicted], 1), context)
        loss = (out - window).pow(2).mean()
        if cfg.world_weight:
            loss = loss + cfg.world_weight * world_error(out[:, r:], window[:, r - 1:], *norm)
        return loss
    out = (net or model)(context, use_filter=False)
    w = torch.ones(out.shape[1], dtype=out.dtype, device=out.device)
    w[:r] = cfg.recon_weight  # decoded frames against predicted ones
    mse = ((out - window).pow(2).mean((0, 2)) * w).sum() / w.sum()
    loss = mse + cfg.smooth_weight * smoothness_cost(out)
    if cfg.velocity_weight:
        loss = loss + cfg.velocity_weight * velocity_error(out[:, r:], window[:, r - 1:])
    if cfg.world_weight:
        loss = loss + cfg.world_weight * world_error(out[:, r:], window[:, r - 1:], *norm)
    return loss


def world_positions(frames: torch.Tensor, mean: torch.Tensor, std: torch.Tensor) -> torch.Tensor:
    """Joint positions ``(B, T, J, 3)`` (metres) of normalised feature frames ``(B, T, C)``, the root's track and
    heading integrated from the first frame (at the origin, heading 0): :func:`features_to_positions` in torch,
    differentiable."""
    raw = frames * std + mean
    rate = raw[..., LAYOUT.yaw_rate]
    yaw = torch.cat([torch.zeros_like(rate[:, :1]), torch.cumsum(rate[:, :-1], 1)], 1)
    c, s = torch.cos(yaw), torch.sin(yaw)
    vel = raw[..., LAYOUT.velocity]
    steps = torch.stack([c * vel[..., 0] + s * vel[..., 1], -s * vel[..., 0] + c * vel[..., 1]], -1)
    track = torch.cat([torch.zeros_like(steps[:, :1]), torch.cumsum(steps[:, :-1], 1)], 1)
    local = raw[..., LAYOUT.positions].reshape(*raw.shape[:-1], -1, 3)
    c, s = c[..., None], s[..., None]
    x = c * local[..., 0] + s * local[..., 2] + track[..., None, 0]
    z = -s * local[..., 0] + c * local[..., 2] + track[..., None, 1]
    return torch.stack([x, local[..., 1], z], -1)


def world_error(predicted: torch.Tensor, truth: torch.Tensor, mean: torch.Tensor, std: torch.Tensor) -> torch.Tensor:
    """Mean squared distance (m^2) of the joints of ``predicted`` ``(B, n, C)``, continuing the true frame
    ``truth[:, 0]``, from those of ``truth`` ``(B, n + 1, C)``, both placed in the world from that frame on."""
    ours = world_positions(torch.cat([truth[:, :1], predicted], 1), mean, std)[:, 1:]
    return (ours - world_positions(truth, mean, std)[:, 1:]).pow(2).sum(-1).mean()


def velocity_error(predicted: torch.Tensor, truth: torch.Tensor) -> torch.Tensor:
    """Mean squared error of the joints' per-frame motion of ``predicted`` ``(B, n, C)`` continuing the true
    frame ``truth[:, 0]`` against ``truth`` ``(B, n + 1, C)``: a prediction that starts off the context's
    last frame, or moves at another pace, pays here even where its poses are close."""
    pos = LAYOUT.positions
    moved = torch.diff(torch.cat([truth[:, :1, pos], predicted[..., pos]], 1), dim=1)
    return (moved - torch.diff(truth[..., pos], dim=1)).pow(2).mean()


def rolled_context(model: STRNN, window: torch.Tensor, k: int,
                   seam_frames: float = PREDICT_SEAM_FRAMES) -> torch.Tensor:
    """The model's own context after ``k`` open-loop windows from the first m frames of ``window``
    ``(B, m + k n + ..., C)``, generated as the engine does (eval mode, seam correction), without gradient."""
    m, n, r = model.cfg.encode_len, model.cfg.predict_len, model.cfg.recon_len
    modes = [mod.training for mod in model.modules()]
    model.eval()
    ctx = window[:, :m]
    pos = LAYOUT.positions
    fade = seam_fade(n, seam_frames, torch, window.dtype).to(window.device)[None, :, None]
    with torch.no_grad():
        for _ in range(k):
            out = model(ctx)
            pred = out[:, r:].clone()
            pred[..., pos] += fade * (ctx[:, -1:, pos] - out[:, r - 1:r, pos])
            ctx = torch.cat([ctx, pred], 1)[:, -m:]
    for mod, mode in zip(model.modules(), modes):
        mod.training = mode
    return ctx


def rollout_batch(model: STRNN, full: torch.Tensor, k: int) -> tuple[torch.Tensor, torch.Tensor]:
    """(target window ``(B, m + n, C)``, context ``(B, m, C)``) after ``k`` open-loop windows from the
    start of the true windows ``full`` ``(B, m + (k + 1) n, C)``: the context is the model's own
    output, which the decoder is to reconstruct, and the predictor is to continue it with the truth."""
    m, n = model.cfg.encode_len, model.cfg.predict_len
    context = rolled_context(model, full, k)
    return torch.cat([context, full[:, k * n + m:k * n + m + n]], 1), context


def recalibrate_batch_norms(model: STRNN, windows: Windows, batches: int, size: int,
                            rng: np.random.Generator) -> None:
    """Running statistics of every batch norm as the plain average over ``batches`` random training
    batches of the model's forward pass (its training-mode statistics, without a gradient). Training
    leaves them as a moving average of the last calls: the predictor's and decoder's steps late in the
    last batches, which the context's frames at inference do not match (see STRNNConfig.spatial_norm)."""
    norms = [m for m in model.modules() if isinstance(m, torch.nn.BatchNorm1d)]
    if not norms:
        return
    modes = [m.training for m in model.modules()]
    keep = [n.momentum for n in norms]
    for n in norms:
        n.reset_running_stats()
        n.momentum = None  # cumulative average
    model.train()
    device = next(model.parameters()).device
    with torch.no_grad():
        m = model.cfg.encode_len
        for _ in range(batches):
            model(windows.batch(rng.integers(0, len(windows), size))[:, :m].to(device))
    for n, momentum in zip(norms, keep):
        n.momentum = momentum
    for mod, mode in zip(model.modules(), modes):
        mod.training = mode


def phase_progress(cfg: TrainConfig, step: int) -> float:
    """Fraction (0..1) of the current phase done at ``step``."""
    bounds = np.cumsum([0.0, *cfg.phase_split]) * cfg.steps
    k = min(int(np.searchsorted(bounds, step, side="right")) - 1, 2)
    return float((step - bounds[k]) / max(bounds[k + 1] - bounds[k], 1.0))


def trainable(model: STRNN, phase: str) -> list[torch.nn.Parameter]:
    res = set(model.filter.parameters()) if model.filter is not None else set()
    for p in model.parameters():
        p.requires_grad_((p in res) == (phase != PHASES[0]))
    return [p for p in model.parameters() if p.requires_grad]


def initial_weights(path: str | Path, model: STRNN) -> dict[str, torch.Tensor]:
    """``model``'s weights taken from a training state (``train_state.pt``) or a release folder, for
    ``--init``; the residual filter keeps its fresh weights where its width differs (a new filter on a
    trained net), and is grown into its place where the window is longer (a longer context read whole,
    ``--encode-len``, or a longer prediction, ``--predict-len``: :func:`_grown_filter`). Any other difference is an
    error that names it."""
    path = Path(path)
    if path.is_dir():
        release = load_release(path)
        release.require_strnn()
        found = {k: torch.from_numpy(np.asarray(v)) for k, v in release.weights.items()}
        source = release.config
    else:
        saved = torch.load(path, weights_only=True)
        found = saved["model"]
        source = json.loads(saved["config"])["model"] if "config" in saved else None
    # Where the source's window (reconstructed | predicted frames) starts in this model's: after the frames this
    # model reconstructs more (a longer context read whole); a longer prediction adds its frames after it.
    lead = None if source is None else model.cfg.recon_len - (source.get("decode_len") or source["encode_len"])
    out = {}
    for k, v in model.state_dict().items():
        w = found.get(k, v)
        extra = model.cfg.encode_len * model.cfg.frame_size
        if k == "filter.net.0.weight" and model.cfg.filter_context and v.shape == (w.shape[0], w.shape[1] + extra):
            # A filter that reads the context, from one that did not: it starts as the old filter,
            # the true context's weights at zero.
            w = torch.cat([w, torch.zeros(v.shape[0], v.shape[1] - w.shape[1], dtype=w.dtype)], 1)
        if w.shape != v.shape and k.startswith("filter.") and not model.cfg.filter_context:
            w = _grown_filter(k, w, v, model.cfg.frame_size, lead)
        if w.shape != v.shape:
            if not k.startswith("filter."):
                raise ValueError(f"--init {path}: {k} has shape {tuple(w.shape)}, this model's {tuple(v.shape)}: "
                                 "start from a model of the same width and frame size")
            w = v
        out[k] = w
    return out


def _grown_filter(key: str, old: torch.Tensor, new: torch.Tensor, frame_size: int,
                  lead: int | None = None) -> torch.Tensor:
    """The residual filter's first or last layer ``old`` of a shorter window, set into its place in ``new``'s
    shape: ``lead`` frames after the new window's start (None: at its end, as a longer context read whole puts
    more frames before the same window; 0: at its start, as a longer prediction adds frames after it). The new
    frames start with zero weights, so the filter starts as the old one on the frames it knew. ``old`` itself
    where the two differ otherwise."""
    first, last = key == "filter.net.0.weight", key in ("filter.net.6.weight", "filter.net.6.bias")
    axis = 1 if first else 0
    if not (first or last) or old.dim() != new.dim() or old.shape[axis] >= new.shape[axis] or \
            (new.shape[axis] - old.shape[axis]) % frame_size or \
            any(a != b for i, (a, b) in enumerate(zip(old.shape, new.shape)) if i != axis):
        return old
    start = new.shape[axis] - old.shape[axis] if lead is None else lead * frame_size
    if not 0 <= start <= new.shape[axis] - old.shape[axis]:
        return old
    grown = torch.zeros(new.shape, dtype=old.dtype)
    grown.narrow(axis, start, old.shape[axis]).copy_(old)
    return grown


# The temporal skip's map (STRNNConfig.temporal_skip) holds extrapolation weights of order 1 to 10 (constant
# velocity is -(i + 1) on one column), which Adam's steps of about the learning rate would take tens of
# thousands of steps to reach: it learns this many times faster, without weight decay.
SKIP_LR_FACTOR = 10.0


def make_optimizer(cfg: TrainConfig, params, fast=()):
    """The optimiser over ``params``; those in ``fast`` (the temporal skip) at SKIP_LR_FACTOR x the rate."""
    if cfg.optimizer == "adadelta":
        return torch.optim.Adadelta(params, lr=1.0, rho=0.95, eps=1e-8, weight_decay=cfg.weight_decay)
    fast_ids = {id(p) for p in fast}
    slow = [p for p in params if id(p) not in fast_ids]
    quick = [p for p in params if id(p) in fast_ids]
    groups = [{"params": slow}] + ([{"params": quick, "lr": cfg.lr * SKIP_LR_FACTOR, "weight_decay": 0.0}]
                                   if quick else [])
    return torch.optim.AdamW(groups, lr=cfg.lr, weight_decay=cfg.weight_decay)


def validate(model: STRNN, val: Windows, cfg: TrainConfig, limit: int = 1024) -> float:
    """Mean squared error of the full model's prediction on fixed validation windows."""
    m, r = cfg.model.encode_len, cfg.model.recon_len
    return validation_mse(model, lambda context: model(context)[:, r:], val, m, limit)


def validation_mse(model, predict, val: Windows, m: int, limit: int = 1024) -> float:
    """Mean squared error of ``predict(context (B, m, C)) -> (B, T - m, C)`` (``model`` in eval mode
    meanwhile) on up to ``limit`` fixed, evenly spread validation windows."""
    was = model.training
    model.eval()
    idx = np.linspace(0, len(val) - 1, min(limit, len(val))).astype(int)
    total = 0.0
    device = next(model.parameters()).device
    with torch.no_grad():
        for chunk in np.array_split(idx, max(1, len(idx) // 256)):
            w = val.batch(chunk).to(device)
            total += (predict(w[:, :m]) - w[:, m:]).pow(2).sum().item()
    model.train(was)
    return total / (len(idx) * (val.span.size - m) * w.shape[-1])


def atomic_save(obj, path: Path):
    write_atomic(path, lambda tmp: torch.save(obj, tmp))


def setup_logging(out: Path, rank: int) -> logging.Logger:
    log = logging.getLogger(f"strnn.train.{out}")
    log.setLevel(logging.INFO)
    if rank == 0 and not log.handlers:
        out.mkdir(parents=True, exist_ok=True)
        fh = logging.FileHandler(out / "train.log")
        fh.setFormatter(logging.Formatter("%(asctime)s %(message)s"))
        log.addHandler(fh)
    return log


def _dist_env() -> tuple[int, int]:
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world > 1 and not dist.is_initialized():
        dist.init_process_group("nccl" if torch.cuda.is_available() else "gloo")
    return (dist.get_rank(), world) if world > 1 else (0, 1)


def train(cfg: TrainConfig, resume: bool = False, progress: bool = True) -> Path:
    """Train, checkpointing to ``cfg.out/train_state.pt``; writes the release folder
    ``cfg.out/release`` at the end and returns it."""
    rank, world = _dist_env()
    out = Path(cfg.out)
    reason = unwritable(out)  # before any work, and before the run folder appears
    if reason:
        raise ValueError(f"--out {out}: cannot write there ({reason}); choose another --out")
    torch.manual_seed(cfg.seed + rank)
    rng = np.random.default_rng(cfg.seed + rank)
    data = load_folder(cfg.data, cache_dir=cfg.cache, progress=rank == 0 and progress,
                       capture_phases=cfg.capture_phases)
    if cfg.hold_out:
        data = data.without_held_out()
    norm = Normaliser.fit(np.concatenate([c.features for c in data.split("train")]))
    length = cfg.model.encode_len + cfg.model.predict_len
    train_w = Windows(data, "train", norm, length)
    long_w = train_w.with_length(length + cfg.rollout_windows * cfg.model.predict_len) if cfg.rollout_windows else None
    val_w = Windows(data, "validation", norm, length, stride=10) if data.split("validation") else None
    model = STRNN(cfg.model)
    state_path = out / "train_state.pt"
    step, phase, opt, history = 0, None, None, []
    saved = torch.load(state_path, weights_only=True) if resume and state_path.exists() else None
    if saved is not None:
        model.load_state_dict(saved["model"])
        step, history = saved["step"], json.loads(saved["history"])
        torch.set_rng_state(saved["torch_rng"])
        rng.bit_generator.state = json.loads(saved["numpy_rng"])
    if saved is None and cfg.init:
        model.load_state_dict(initial_weights(cfg.init, model))
    device = torch.device(cfg.device)
    model.to(device)
    # everything is checked and loaded: only now does the run folder (and its log) appear
    log = setup_logging(out, rank)
    if saved is not None:
        log.info("resumed at step %d", step)
    elif resume:
        log.info("no state at %s; starting from scratch", state_path)
    if saved is None and cfg.init:
        log.info("initial weights from %s", cfg.init)
    if rank == 0:
        log.info("config %s", json.dumps(asdict(cfg)))
        log.info("data: %d clips (%s), %d training windows, %d unreadable files", len(data.clips),
                 {s: len(data.split(s)) for s in ("train", "validation", "test")}, len(train_w), len(data.failures))
    per_rank = max(1, cfg.batch // world)
    mirror = Mirror(norm)
    stats = (torch.from_numpy(norm.mean).to(device), torch.from_numpy(norm.std).to(device))
    started, last_ckpt = time.time(), time.time()
    bar = Progress(cfg.steps, step, enabled=rank == 0 and progress)
    net = model
    while step < cfg.steps:
        now = phase_at(cfg, step)
        if now != phase:
            phase = now
            params = trainable(model, phase)
            model.train()
            if phase == PHASES[2]:
                model.encode_frame.eval(), model.decode_frame.eval()
            net = DistributedDataParallel(model) if world > 1 and phase == PHASES[0] else model
            opt = make_optimizer(cfg, params, fast=[model.skip] if cfg.model.temporal_skip else [])
            if saved is not None and saved["phase"] == phase:
                opt.load_state_dict(saved["optimizer"])
            log.info("phase %s from step %d (%d parameters trained)", phase, step, sum(p.numel() for p in params))
        k = int(rng.integers(1, cfg.rollout_windows + 1)) if (
            long_w is not None and phase == PHASES[0] and rng.random() < cfg.rollout_fraction) else 0
        flip = rng.random(per_rank) < cfg.mirror
        if k:
            full = mirror(long_w.batch(rng.integers(0, len(long_w), per_rank)), flip).to(device)
            window, noisy = rollout_batch(model, full, k)
        else:
            idx = rng.integers(0, len(train_w), per_rank)
            speeds = np.exp(rng.uniform(-1, 1, per_rank) * np.log1p(cfg.time_warp)) if cfg.time_warp > 0 else None
            p = cfg.proportions
            bodies = rng.uniform(1 - p, 1 + p, (per_rank, 2)) if p > 0 else None
            window = mirror(train_w.batch(idx, speeds, bodies), flip)
            n_heavy = int(round(cfg.denoise_fraction * len(idx))) if phase != PHASES[1] else 0
            noisy = train_w.noisy_contexts(idx[:n_heavy], cfg.model.encode_len, cfg.denoise_max_cm, rng,
                                           cfg.denoise_rotation_deg, None if speeds is None else speeds[:n_heavy],
                                           None if bodies is None else bodies[:n_heavy]) if n_heavy else None
            noisy = mirror(noisy, flip)
            window, noisy = window.to(device), None if noisy is None else noisy.to(device)
        loss = window_loss(model, window, cfg, phase, noise_std(cfg, step), net=net, noisy=noisy, norm=stats)
        scale = float(cfg.lr_final + (1 - cfg.lr_final) * 0.5 * (1 + np.cos(np.pi * phase_progress(cfg, step))))
        for group in opt.param_groups:
            group["lr"] = group.setdefault("base_lr", group["lr"]) * scale
        opt.zero_grad(set_to_none=True)
        loss.backward()
        if world > 1 and phase != PHASES[0]:
            for p in params:
                dist.all_reduce(p.grad)
                p.grad /= world
        torch.nn.utils.clip_grad_norm_(params, 5.0)
        opt.step()
        step += 1
        bar.update(loss.item(), phase)
        entry = None
        if rank == 0 and step % 50 == 0:
            entry = {"step": step, "phase": phase, "loss": round(loss.item(), 6),
                     "noise": round(noise_std(cfg, step), 4), "elapsed_s": round(time.time() - started, 1)}
        if rank == 0 and val_w is not None and (step % cfg.val_every == 0 or step == cfg.steps):
            entry = entry or {"step": step, "phase": phase, "loss": round(loss.item(), 6)}
            entry["val_mse"] = round(validate(model, val_w, cfg), 6)
        if entry:
            history.append(entry)
            log.info(json.dumps(entry))
        out_of_time = cfg.max_minutes and time.time() - started > 60 * cfg.max_minutes
        if rank == 0 and (time.time() - last_ckpt > cfg.checkpoint_seconds or step == cfg.steps or out_of_time):
            atomic_save({"model": model.state_dict(), "optimizer": opt.state_dict(), "step": step, "phase": phase,
                          "history": json.dumps(history), "torch_rng": torch.get_rng_state(),
                          "numpy_rng": json.dumps(rng.bit_generator.state), "config": json.dumps(asdict(cfg))},
                         state_path)
            last_ckpt = time.time()
        if out_of_time:
            log.info("stopping at step %d: --max-minutes reached; continue with --resume", step)
            break
    bar.close()
    release = out / "release"
    if rank == 0 and step >= cfg.steps:
        if cfg.recalibrate_batches:
            recalibrate_batch_norms(model, train_w, cfg.recalibrate_batches, cfg.batch, rng)
            log.info("batch norm statistics recomputed over %d training batches", cfg.recalibrate_batches)
        write_release(model, cfg, data, norm, history, release)
        log.info("release checkpoint written to %s", release)
    if world > 1:
        dist.barrier()
        dist.destroy_process_group()
    return release


class Progress:
    """A small progress bar with loss and ETA on stderr (no extra dependency)."""

    def __init__(self, total: int, start: int, enabled: bool):
        self.total, self.step, self.enabled = total, start, enabled
        self.t0, self.s0, self.avg = time.time(), start, None

    def update(self, loss: float, phase: str):
        self.step += 1
        self.avg = loss if self.avg is None else 0.98 * self.avg + 0.02 * loss
        if not self.enabled or (self.step % 5 and self.step != self.total):
            return
        rate = (self.step - self.s0) / max(time.time() - self.t0, 1e-9)
        eta = (self.total - self.step) / max(rate, 1e-9)
        done = int(30 * self.step / self.total)
        sys.stderr.write(f"\r[{'#' * done}{'.' * (30 - done)}] {self.step}/{self.total} {phase} "
                         f"loss {self.avg:.4f} {rate:.2f} it/s ETA {int(eta // 60)}m{int(eta % 60):02d}s ")
        sys.stderr.flush()

    def close(self):
        if self.enabled:
            sys.stderr.write("\n")


def pick_seeds(data: MotionData, length: int, count: int = 12) -> tuple[np.ndarray, list[str]]:
    """One ``length``-frame window per action label from test-split clips (from the validation, then the
    training split when the folder has no test take long enough): ``[K, length, C]``."""
    for split in ("test", "validation", "train"):
        seeds, names = _seeds_of(data.split(split), length, count)
        if seeds:
            return np.stack(seeds), names
    raise ValueError(f"{data.root}: no clip has {length} frames at 30 fps to keep as a seed; add longer takes")


def _seeds_of(clips, length: int, count: int) -> tuple[list[np.ndarray], list[str]]:
    seen, seeds, names = set(), [], []
    for clip in sorted(clips, key=lambda c: c.name):
        parts = Path(clip.name).stem.split("_")
        label = parts[1] if len(parts) > 2 else str(Path(clip.name).parent)  # "take_action_style_NNN" names
        start = min(30, len(clip.features) - length)
        if label in seen or start < 0:
            continue
        seen.add(label)
        seeds.append(clip.features[start:start + length])
        names.append(f"{clip.name}@{start}")
        if len(seeds) == count:
            break
    return seeds, names


def init_record(init: str | Path) -> dict:
    """Where a fine-tuned model started: ``{"from": path, "training": the start's own training record}``
    (read from its model.json, or the command in its train_state.pt), so a release names its whole recipe."""
    path, record = Path(init), {"from": str(init)}
    if (path / "model.json").is_file():
        record["training"] = json.loads((path / "model.json").read_text()).get("training")
    elif path.is_file():
        record["training"] = {"command": json.loads(torch.load(path, weights_only=True)["config"]).get("command", "")}
    return record


LICENCES = {  # the terms a release inherits from each library it was trained on (top folder of the data)
    "bandai-namco": "CC BY-NC 4.0 (trained on the Bandai Namco Research Motion Dataset, credit Bandai Namco "
                    "Research Inc.)",
    "cmu": "CMU Graphics Lab Motion Capture Database terms (data obtained from mocap.cs.cmu.edu; the database "
           "was created with funding from NSF EIA-0196217)",
}


def licence_of(data: MotionData) -> str:
    """The licence a release trained on ``data`` carries: the terms of each known library among its
    clips, and a reminder for clips from anywhere else."""
    tops = {c.name.split("/")[0] if "/" in c.name else Path(data.root).name for c in data.clips}
    terms = [text for top, text in LICENCES.items() if top in tops]
    if tops - set(LICENCES):
        terms.append("the terms of the other training data (" + ", ".join(sorted(tops - set(LICENCES))) + ")")
    return " and ".join(terms)


def data_record(data: MotionData) -> dict:
    """What a release was trained on: the folder's name, clips and frames per split, the split rule."""
    return {"root": Path(data.root).name, "clips": {s: len(data.split(s)) for s in SPLITS},
            "frames": {s: int(sum(len(c.features) for c in data.split(s))) for s in SPLITS},
            "split_rule": "crc32(take key) % 20: 0-1 test, 2 validation, else train (model_core/model/dataset.py)"}


def write_release(model: STRNN, cfg: TrainConfig, data: MotionData, norm: Normaliser, history: list, folder: Path):
    weights = {k: v.detach().cpu().numpy() for k, v in model.state_dict().items() if v.dtype.is_floating_point}
    seeds, names = pick_seeds(data, cfg.model.encode_len)
    meta = {
        "purpose": cfg.purpose,
        "training": {"command": cfg.command, "steps": cfg.steps, "optimizer": cfg.optimizer, "batch": cfg.batch,
                     "final": history[-1] if history else None,
                     **({"init": init_record(cfg.init)} if cfg.init else {})},
        "data": data_record(data),
        "licence": licence_of(data),
    }
    save_release(folder, weights, cfg.model.to_dict(), norm.mean, norm.std, meta, seeds, names)


def export_state(cfg: TrainConfig, folder: Path | None = None) -> Path:
    """Write a release folder from ``cfg.out/train_state.pt`` as it is now (a model mid-training)."""
    state_path = Path(cfg.out) / "train_state.pt"
    if not state_path.exists():
        raise ValueError(f"{state_path}: no training state to export")
    saved = torch.load(state_path, weights_only=True)
    data = load_folder(cfg.data, cache_dir=cfg.cache, progress=False, capture_phases=cfg.capture_phases)
    if cfg.hold_out:
        data = data.without_held_out()
    norm = Normaliser.fit(np.concatenate([c.features for c in data.split("train")]))
    model = STRNN(cfg.model)
    model.load_state_dict(saved["model"])
    folder = folder or Path(cfg.out) / f"release_step{saved['step']}"
    write_release(model, cfg, data, norm, json.loads(saved["history"]), folder)
    return folder
