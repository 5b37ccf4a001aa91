"""Training the baselines of :mod:`baselines`: windows of the train split (held-out groups
and mirroring as for STRNN), AdamW with one cosine decay over ``steps``, the validation MSE
every ``val_every`` steps, a resumable state, and the release folder at the end. The time
budget ``max_minutes`` ends the run early with a release all the same (``--resume`` goes on).
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch

from ..io.checkpoint import save_release
from .baselines import MODELS, ResidualGRUConfig, SiMLPeConfig
from .dataset import Normaliser, load_folder
from .training import (
    Mirror,
    Progress,
    Windows,
    atomic_save,
    data_record,
    licence_of,
    pick_seeds,
    setup_logging,
    validation_mse,
)


@dataclass
class BaselineTrainConfig:
    data: str  # folder of BVH files (searched recursively)
    out: str = "runs/simlpe"  # training state, log and release go here
    model: SiMLPeConfig | ResidualGRUConfig = field(default_factory=SiMLPeConfig)  # its type names the baseline
    steps: int = 20000  # optimiser steps; the cosine decay spans them
    batch: int = 128  # windows per step
    lr: float = 3e-4  # AdamW (siMLPe's)
    lr_final: float = 0.01  # the cosine decay ends at this fraction of lr
    weight_decay: float = 1e-4
    clip_grad: float = 5.0  # gradient-norm clip (Martinez et al.'s)
    seed: int = 0
    val_every: int = 250  # steps between validation passes
    checkpoint_seconds: float = 120.0  # how often the resumable state is written
    cache: str = "data/cache"  # cached arrays of the data folder
    max_minutes: float = 0.0  # the time budget: when it runs out first, the release is written anyway; 0 = none
    command: str = ""  # the command line, recorded in the release
    mirror: float = 0.0  # share of training windows mirrored left to right
    hold_out: bool = False  # keep the held-out groups of configs/data.toml out of training and validation

    @property
    def arch(self) -> str:
        return next(name for name, (_, config) in MODELS.items() if isinstance(self.model, config))


def lr_scale(cfg: BaselineTrainConfig, step: int) -> float:
    """Cosine decay from 1 at step 0 to ``lr_final`` at ``steps``."""
    progress = min(step / max(cfg.steps, 1), 1.0)
    return float(cfg.lr_final + (1 - cfg.lr_final) * 0.5 * (1 + np.cos(np.pi * progress)))


def validate(model, val: Windows, m: int, limit: int = 1024) -> float:
    """Mean squared error of the normalised prediction on fixed validation windows."""
    return validation_mse(model, model, val, m, limit)


def prepare(cfg: BaselineTrainConfig):
    """(data, normaliser, training windows, validation windows or None) of the run."""
    data = load_folder(cfg.data, cache_dir=cfg.cache or None, progress=False)
    if cfg.hold_out:
        data = data.without_held_out()
    norm = Normaliser.fit(np.concatenate([c.features for c in data.split("train")]))
    length = cfg.model.encode_len + cfg.model.predict_len
    val = Windows(data, "validation", norm, length, stride=10) if data.split("validation") else None
    return data, norm, Windows(data, "train", norm, length), val


def save_state(path: Path, model, opt, step: int, history: list, rng: np.random.Generator, cfg):
    atomic_save({"model": model.state_dict(), "optimizer": opt.state_dict(), "step": step,
                  "history": json.dumps(history), "torch_rng": torch.get_rng_state(),
                  "numpy_rng": json.dumps(rng.bit_generator.state), "config": json.dumps(asdict(cfg))}, path)


def restore_state(path: Path, model, opt, rng: np.random.Generator) -> tuple[int, list]:
    """Load a saved state into ``model``, ``opt`` and the random generators: (step, history)."""
    saved = torch.load(path, weights_only=True)
    model.load_state_dict(saved["model"])
    opt.load_state_dict(saved["optimizer"])
    torch.set_rng_state(saved["torch_rng"])
    rng.bit_generator.state = json.loads(saved["numpy_rng"])
    return saved["step"], json.loads(saved["history"])


def train_step(model, opt, cfg: BaselineTrainConfig, window: torch.Tensor, step: int) -> float:
    """One optimiser step on normalised windows ``(B, m + n, C)``; returns the loss."""
    m = cfg.model.encode_len
    loss = model.loss(model(window[:, :m]), window[:, m:])
    for group in opt.param_groups:
        group["lr"] = cfg.lr * lr_scale(cfg, step)
    opt.zero_grad(set_to_none=True)
    loss.backward()
    torch.nn.utils.clip_grad_norm_(model.parameters(), cfg.clip_grad)
    opt.step()
    return loss.item()


def train_baseline(cfg: BaselineTrainConfig, resume: bool = False, progress: bool = True) -> Path:
    """Train, checkpointing to ``cfg.out/train_state.pt``; writes ``cfg.out/release`` and returns it."""
    out, state_path = Path(cfg.out), Path(cfg.out) / "train_state.pt"
    log = setup_logging(out, 0)
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    data, norm, train_w, val_w = prepare(cfg)
    model = MODELS[cfg.arch][0](cfg.model)
    opt = torch.optim.AdamW(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    step, history = 0, []
    if resume and state_path.exists():
        step, history = restore_state(state_path, model, opt, rng)
        log.info("resumed at step %d", step)
    log.info("config %s", json.dumps(asdict(cfg) | {"arch": cfg.arch}))
    log.info("%s: %d parameters; %d training windows, %d clips (%s)", cfg.arch, n_params(model), len(train_w),
             len(data.clips), {s: len(data.split(s)) for s in ("train", "validation", "test")})
    mirror, bar = Mirror(norm), Progress(cfg.steps, step, enabled=progress)
    started = last_ckpt = time.time()
    out_of_time = False
    while step < cfg.steps and not out_of_time:
        window = mirror(train_w.batch(rng.integers(0, len(train_w), cfg.batch)), rng.random(cfg.batch) < cfg.mirror)
        loss = train_step(model, opt, cfg, window, step)
        step += 1
        bar.update(loss, cfg.arch)
        out_of_time = bool(cfg.max_minutes) and time.time() - started > 60 * cfg.max_minutes
        entry = log_entry(model, cfg, val_w, step, loss, time.time() - started, final=step == cfg.steps or out_of_time)
        if entry:
            history.append(entry)
            log.info(json.dumps(entry))
        if time.time() - last_ckpt > cfg.checkpoint_seconds or step == cfg.steps or out_of_time:
            save_state(state_path, model, opt, step, history, rng, cfg)
            last_ckpt = time.time()
    bar.close()
    if out_of_time:
        log.info("--max-minutes reached at step %d of %d: release written from this step (--resume goes on)",
                 step, cfg.steps)
    release = write_baseline_release(model, cfg, data, norm, history, step, out / "release")
    log.info("release written to %s", release)
    return release


def log_entry(model, cfg: BaselineTrainConfig, val_w, step: int, loss: float, elapsed: float, final: bool):
    """The log line of this step (every 50 steps, with the validation MSE every ``val_every``), or None."""
    validating = val_w is not None and (step % cfg.val_every == 0 or final)
    if step % 50 and not validating and not final:
        return None
    entry = {"step": step, "loss": round(loss, 6), "lr": round(cfg.lr * lr_scale(cfg, step), 8),
             "elapsed_s": round(elapsed, 1)}
    if validating:
        entry["val_mse"] = round(validate(model, val_w, cfg.model.encode_len), 6)
    return entry


def n_params(model) -> int:
    return sum(p.numel() for p in model.parameters())


def write_baseline_release(model, cfg: BaselineTrainConfig, data, norm: Normaliser, history: list, step: int,
                           folder: Path) -> Path:
    """A release folder like STRNN's, with ``architecture`` in model.json."""
    weights = {k: v.detach().cpu().numpy() for k, v in model.state_dict().items()}
    seeds, names = pick_seeds(data, cfg.model.encode_len)
    meta = {
        "architecture": cfg.arch,
        "purpose": "generate",
        "parameters": n_params(model),
        "training": {"command": cfg.command, "steps": cfg.steps, "steps_done": step, "optimizer": "adamw",
                     "lr": cfg.lr, "lr_final": cfg.lr_final, "weight_decay": cfg.weight_decay, "batch": cfg.batch,
                     "mirror": cfg.mirror, "hold_out": cfg.hold_out, "final": history[-1] if history else None},
        "data": data_record(data),
        "licence": licence_of(data),
    }
    return save_release(folder, weights, cfg.model.to_dict(), norm.mean, norm.std, meta, seeds, names)
