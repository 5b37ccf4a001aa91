"""STRNN inference with the torch model: the twin of :class:`model_core.inference.engine.Engine`.

Same API (``load``, ``forward``, ``predict``, ``extrapolate``, ``denoise``), NumPy in and
out, built from the same release folder. Use it where torch is installed (benchmarks,
a GPU); the add-on uses the NumPy engine. This is the only inference module that
imports torch, so the rest of the project runs without it.
Features in and out are RAW (un-normalised) ``[..., T, C]`` in :data:`LAYOUT` order.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from ..io.checkpoint import Checkpoint, CheckpointError, load_release
from ..model.strnn import STRNN, STRNNConfig
from .engine import Engine
from .simlpe_engine import SiMLPeEngine

# State-dict entries a release may leave out: integer counters, not weights.
_OPTIONAL = ("num_batches_tracked",)


def build_model(ckpt: Checkpoint) -> STRNN:
    """The torch STRNN of a release checkpoint, in eval mode (batch norms use running stats)."""
    ckpt.require_strnn()
    model = STRNN(STRNNConfig(**ckpt.config))
    expected = {k: tuple(v.shape) for k, v in model.state_dict().items() if not k.endswith(_OPTIONAL)}
    found = {k: tuple(v.shape) for k, v in ckpt.weights.items()}
    wrong = [f"{k} {found.get(k)} (config wants {shape})" for k, shape in expected.items() if found.get(k) != shape]
    wrong += [f"{k} (not in the model)" for k in found.keys() - expected.keys()]
    if wrong:
        raise CheckpointError(f"checkpoint weights do not match its config {ckpt.config}: {len(wrong)} tensors "
                              f"differ, e.g. {'; '.join(wrong[:3])}")
    state = {k: torch.from_numpy(np.ascontiguousarray(v)) for k, v in ckpt.weights.items()}
    model.load_state_dict(state, strict=False)  # only the integer batch-norm counters are left out
    return model.eval()


class TorchEngine:
    """STRNN inference with torch. Build with :meth:`load`."""

    def __init__(self, ckpt: Checkpoint, device: str | torch.device = "cpu"):
        self.ckpt = ckpt
        self.device = torch.device(device)
        self.model = build_model(ckpt).to(self.device)
        cfg = ckpt.config
        self.m, self.n, self.width = cfg["encode_len"], cfg["predict_len"], cfg["width"]
        self.r = cfg.get("decode_len") or self.m  # the context's last frames the decoder reconstructs
        self.mean, self.std = ckpt.mean, ckpt.std
        self._mean = torch.from_numpy(ckpt.mean).to(self.device)
        self._std = torch.from_numpy(ckpt.std).to(self.device)
        self.companion = TorchEngine(ckpt.companion, device) if ckpt.companion is not None else None
        self.simlpe = SiMLPeEngine(ckpt.simlpe) if ckpt.simlpe is not None else None  # tiny: NumPy is as quick
        self.regularised = TorchEngine(ckpt.regularised, device) if ckpt.regularised is not None else None

    @classmethod
    def load(cls, folder: str | Path | None = None, device: str | torch.device = "cpu") -> TorchEngine:
        """Load a release folder (default: the bundled model)."""
        return cls(load_release(folder), device)

    @property
    def seeds(self) -> np.ndarray:
        """Shipped seed windows, raw features ``[K, m, C]``."""
        return self.ckpt.seeds

    @torch.inference_mode()
    def forward(self, context: np.ndarray, decode: bool = True) -> np.ndarray:
        """Raw context ``[B, m, C]`` -> raw decoded context (its last r frames) + prediction ``[B, r + n, C]``
        (``decode`` False: :meth:`Engine.forward`'s)."""
        x = torch.as_tensor(np.asarray(context, np.float32), device=self.device)
        out = self.model((x - self._mean) / self._std, decode=decode)
        return (out * self._std + self._mean).cpu().numpy()

    # The rollout, the windowed denoiser and the position-level wrappers only call
    # predict/forward and read m and r, so the NumPy engine's own code runs here unchanged:
    # the two engines cannot drift apart.
    seam_frames = Engine.seam_frames
    mirrored_reading = Engine.mirrored_reading
    decode_later_windows = Engine.decode_later_windows
    predict = Engine.predict
    predict_next = Engine.predict_next
    predict_once = Engine.predict_once
    predict_first = Engine.predict_first
    lean_regularised = Engine.lean_regularised
    full_context = Engine.full_context
    extrapolate = Engine.extrapolate
    reconstruct = Engine.reconstruct
    reconstruct_steps = Engine.reconstruct_steps
    extend = Engine.extend
    ground = Engine.ground
    reconstruct_positions = Engine.reconstruct_positions
    reconstruct_positions_steps = Engine.reconstruct_positions_steps
