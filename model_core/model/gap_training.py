"""Training the gap model of :mod:`model_core.inference.gap_engine` (torch).

Windows of the train split (held-out groups left out with ``hold_out``): ``CONTEXT`` frames, a gap
of 1 to ``MAX_GAP`` frames, and the two frames after it. Each take is also read mirrored and at
other paces (resampled), so the model learns gaits and builds beyond the data's own. The loss is
the mean distance of the gap's joints from the take's, in metres, as L2P measures it.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn

from ..inference import gap_engine as ge
from ..io.files import write_atomic, write_json
from ..motion.conventions import MODEL_FPS
from ..motion.features import mirror_positions
from ..motion.geometry import interpolate_frames
from .dataset import DataError, load_folder
from .training import licence_of, setup_logging


@dataclass
class GapTrainConfig:
    data: str
    out: str = "runs/gap"
    width: int = 768
    blocks: int = 4
    sines: int = 16
    steps: int = 20000
    batch: int = 256
    lr: float = 1e-3
    lr_final: float = 0.02
    weight_decay: float = 1e-4
    seed: int = 0
    paces: tuple = (0.8, 0.9, 1.0, 1.1, 1.25)  # each take also read at these multiples of its pace
    mirror: bool = True
    jitter: float = 0.01  # std (m, standard body) of noise on the context's terms, in a random share of windows
    dropout: float = 0.0  # dropout inside each residual block
    capture_phases: bool = False  # every phase of a 60 or 120 fps take a clip of its own (dataset.load_folder)
    hold_out: bool = False
    val_every: int = 500
    checkpoint_seconds: float = 300.0
    max_minutes: float = 0.0
    cache: str = "data/cache"
    command: str = ""


class GapNet(nn.Module):
    def __init__(self, cfg: GapTrainConfig, in_mean, in_std, out_scale):
        super().__init__()
        self.k = cfg.sines
        self.register_buffer("in_mean", torch.as_tensor(in_mean, dtype=torch.float32))
        self.register_buffer("in_std", torch.as_tensor(in_std, dtype=torch.float32))
        self.register_buffer("out_scale", torch.as_tensor(out_scale, dtype=torch.float32))
        self.inp = nn.Linear(ge.INPUTS, cfg.width)
        self.blocks = nn.ModuleList()
        for _ in range(cfg.blocks):
            b = nn.Module()
            b.norm = nn.LayerNorm(cfg.width)
            b.fc1, b.fc2 = nn.Linear(cfg.width, cfg.width), nn.Linear(cfg.width, cfg.width)
            self.blocks.append(b)
        self.norm = nn.LayerNorm(cfg.width)
        self.drop = nn.Dropout(cfg.dropout) if cfg.dropout > 0 else nn.Identity()
        self.out = nn.Linear(cfg.width, cfg.sines * ge.TERMS)
        nn.init.zeros_(self.out.weight)
        nn.init.zeros_(self.out.bias)

    def forward(self, x):
        h = self.inp((x - self.in_mean) / self.in_std)
        for b in self.blocks:
            h = h + b.fc2(self.drop(nn.functional.gelu(b.fc1(b.norm(h)), approximate="tanh")))
        out = self.out(self.norm(h)).reshape(len(x), self.k, ge.TERMS)
        return out * self.out_scale


def positions_torch(t):
    """:func:`gap_engine.positions` in torch: ``[..., 66]`` -> ``[..., 21, 3]``."""
    local = t[..., 3:].reshape(t.shape[:-1] + (21, 3))
    c, s = torch.cos(t[..., 2:3]), torch.sin(t[..., 2:3])
    x = c * local[..., 0] + s * local[..., 2] + t[..., 0:1]
    z = -s * local[..., 0] + c * local[..., 2] + t[..., 1:2]
    return torch.stack([x, local[..., 1], z], -1)


class Windows:
    """Every train-split take as body terms, at each pace, as it is and mirrored, in one array."""

    def __init__(self, clips, paces, mirror: bool, jitter: float = 0.0):
        self.jitter = jitter
        parts, starts = [], []
        total = 0
        for clip in clips:
            for pace in paces:
                pos = clip.positions
                if pace != 1.0:
                    pos = interpolate_frames(pos, np.arange(0.0, len(pos) - 1 + 1e-9, pace))
                for flip in ((False, True) if mirror else (False,)):
                    p = mirror_positions(pos) if flip else pos
                    if len(p) < ge.CONTEXT + 4:
                        continue
                    parts.append(ge.terms(p * ge.body_scale(p)).astype(np.float32))
                    starts.append((total, len(p)))
                    total += len(p)
        if not parts:
            raise DataError(f"no take has the {ge.CONTEXT + 4} frames a gap model's window needs")
        self.data = np.concatenate(parts)
        self.clips = np.array(starts)

    def sample(self, rng: np.random.Generator, b: int, gaps: np.ndarray | None = None):
        """(context ``[B, C, 66]``, gap ``[B, MAX_GAP, 66]`` padded, target ``[B, 2, 66]``, gap lengths ``[B]``,
        target moving on ``[B]``), relative to each context's last frame."""
        n = gaps if gaps is not None else np.where(rng.random(b) < 0.5, rng.integers(1, 61, b),
                                                   rng.integers(1, ge.MAX_GAP + 1, b))
        n = np.minimum(n, self.clips[:, 1].max() - ge.CONTEXT - 2)  # no gap longer than the longest take allows
        length = ge.CONTEXT + n + 2
        cum = np.cumsum(self.clips[:, 1])
        pick = np.searchsorted(cum, rng.random(b) * cum[-1], side="right")  # a clip in proportion to its length
        for _ in range(100):  # draw again for clips too short for their gap
            short = self.clips[pick, 1] < length
            if not short.any():
                break
            pick[short] = np.searchsorted(cum, rng.random(int(short.sum())) * cum[-1], side="right")
        begin, size = self.clips[pick, 0], self.clips[pick, 1]
        s = begin + (rng.random(b) * (size - length + 1)).astype(int)
        idx_c = s[:, None] + np.arange(ge.CONTEXT)[None]
        idx_g = s[:, None] + ge.CONTEXT + np.minimum(np.arange(ge.MAX_GAP)[None], n[:, None] - 1)
        idx_t = s[:, None] + ge.CONTEXT + n[:, None] + np.arange(2)[None]
        origin = self.data[idx_c[:, -1]].astype(np.float64)
        rel = [ge.relative(self.data[i].astype(np.float64), origin) for i in (idx_c, idx_g, idx_t)]
        moves_on = (rng.random(b) < 0.5).astype(np.float64) if gaps is None else np.zeros(b)
        if gaps is None and self.jitter:  # a little noise on what the model reads: capture is never clean
            rel[0] = rel[0] + rng.normal(0.0, self.jitter, rel[0].shape) * rng.random((b, 1, 1))
        return rel[0], rel[1], rel[2], n, moves_on


def batch_tensors(model_k: int, ctx, gap, tgt, n, moves_on):
    x = ge.inputs(ctx, tgt, moves_on, n)
    base = ge.interpolate_terms(ctx[:, -1], tgt[:, 0], n, ge.MAX_GAP)
    basis = ge.sines(n, ge.MAX_GAP, model_k)
    mask = np.arange(ge.MAX_GAP)[None] < n[:, None]
    f = lambda a: torch.as_tensor(np.asarray(a), dtype=torch.float32)  # noqa: E731
    return f(x), f(base), f(basis), f(gap), f(mask)


def loss_of(model, x, base, basis, gap, mask):
    coef = model(x)
    pred = base + torch.einsum("bfk,bkc->bfc", basis, coef)
    err = torch.linalg.norm(positions_torch(pred) - positions_torch(gap), dim=-1).mean(-1)  # [B, F]
    return (err * mask).sum() / mask.sum()


def train_gap(cfg: GapTrainConfig, resume: bool = False) -> Path:
    out = Path(cfg.out)
    out.mkdir(parents=True, exist_ok=True)
    log = setup_logging(out, 0)
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    data = load_folder(cfg.data, cache_dir=cfg.cache or None, progress=False, capture_phases=cfg.capture_phases)
    if cfg.hold_out:
        data = data.without_held_out()
    train = Windows(data.split("train"), cfg.paces, cfg.mirror, cfg.jitter)
    val = Windows(data.split("validation"), (1.0,), False) if data.split("validation") else train
    if val is train:
        log.info("no validation split in %s: the validation figures are on training windows", cfg.data)
    log.info("train frames %d in %d readings; validation frames %d", len(train.data), len(train.clips), len(val.data))
    # Normalisation from a sample of windows; the output scale is the spread of what interpolation misses.
    ctx, gap, tgt, n, mo = train.sample(np.random.default_rng(123), 4096)
    x = ge.inputs(ctx, tgt, mo, n)
    miss = gap - ge.interpolate_terms(ctx[:, -1], tgt[:, 0], n, ge.MAX_GAP)
    valid = np.arange(ge.MAX_GAP)[None] < n[:, None]
    model = GapNet(cfg, x.mean(0), x.std(0) + 1e-3, miss[valid].std(0) + 1e-3)
    opt = torch.optim.AdamW(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    vrng = np.random.default_rng(7)
    val_sets = [batch_tensors(cfg.sines, *val.sample(vrng, 512, np.full(512, g))) for g in (15, 30, 60)]
    step, history = 0, []
    state_path = out / "train_state.pt"
    if resume and state_path.exists():
        state = torch.load(state_path, weights_only=True)
        model.load_state_dict(state["model"])
        opt.load_state_dict(state["opt"])
        step, history = int(state["step"]), json.loads(state["history"])
        rng = np.random.default_rng(cfg.seed + step)
    start, last_save = time.time(), time.time()
    while step < cfg.steps:
        progress = step / cfg.steps
        for g in opt.param_groups:
            g["lr"] = float(cfg.lr) * float(cfg.lr_final + (1 - cfg.lr_final) * 0.5 * (1 + np.cos(np.pi * progress)))
        model.train()
        loss = loss_of(model, *batch_tensors(cfg.sines, *train.sample(rng, cfg.batch)))
        opt.zero_grad()
        loss.backward()
        nn.utils.clip_grad_norm_(model.parameters(), 5.0)
        opt.step()
        step += 1
        if step % cfg.val_every == 0 or step == cfg.steps:
            model.eval()
            with torch.no_grad():
                l2p = [float(loss_of(model, *v)) * 100 for v in val_sets]
                lerp = [float((torch.linalg.norm(positions_torch(v[1]) - positions_torch(v[3]), dim=-1).mean(-1)
                                * v[4]).sum() / v[4].sum()) * 100 for v in val_sets]
            history.append({"step": step, "loss": float(loss.detach()), "val_l2p_cm": l2p, "interp_cm": lerp})
            log.info("step %d loss %.4f val L2P 15/30/60 %s (interpolation %s) %.0f s", step, float(loss.detach()),
                     " / ".join(f"{v:.2f}" for v in l2p), " / ".join(f"{v:.2f}" for v in lerp), time.time() - start)
        over = cfg.max_minutes and time.time() - start > cfg.max_minutes * 60
        if time.time() - last_save > cfg.checkpoint_seconds or over:
            _save_state(state_path, model, opt, step, history)
            last_save = time.time()
        if over:
            log.info("time budget of %g minutes spent at step %d", cfg.max_minutes, step)
            break
    _save_state(state_path, model, opt, step, history)
    return save_gap_release(out / "release", model, cfg, step, history, data)


def _save_state(path: Path, model, opt, step, history):
    state = {"model": model.state_dict(), "opt": opt.state_dict(), "step": step, "history": json.dumps(history)}
    write_atomic(path, lambda p: torch.save(state, p))


def save_gap_release(folder: Path, model: GapNet, cfg: GapTrainConfig, step: int, history, data) -> Path:
    from safetensors.numpy import save_file

    folder.mkdir(parents=True, exist_ok=True)
    weights = {k: v.detach().cpu().numpy().astype(np.float32) for k, v in model.state_dict().items()}
    write_atomic(folder / "model.safetensors", lambda p: save_file(weights, str(p)))
    doc = {"format": ge.FORMAT, "config": {"sines": cfg.sines, "blocks": cfg.blocks, "width": cfg.width,
                                           "context": ge.CONTEXT, "max_gap": ge.MAX_GAP},
           "fps": MODEL_FPS, "units": "metres", "up_axis": "y", "steps": step, "training": asdict(cfg),
           "history": history[-5:], "licence": licence_of(data) if data is not None else None}
    write_json(folder / "model.json", doc)
    return folder
