"""siMLPe inference in NumPy: the release's short-horizon partner (no torch needed).

The project's siMLPe (Guo et al. 2023, "Back to MLP", :class:`model_core.model.baselines.SiMLPe`) reads the
context's DCT along time through a stack of temporal fully connected blocks and predicts offsets from the last
frame. Trained without the held-out groups, it predicts the next 20 frames of motion unlike the training data
better than the STRNN does, and the two err apart: a release may hold one in :data:`checkpoint.SIMLPE`, and the
first window of every rollout is then its weighted average with the STRNN's (:meth:`Engine.predict_first`).
Every later window is the STRNN's own. Features in and out are RAW (un-normalised) ``[..., T, C]`` in
:data:`LAYOUT` order; the same maths as the torch model, which ``tests/inference/test_simlpe_engine.py`` checks.
"""

from __future__ import annotations

import numpy as np

from ..io.checkpoint import ARCHITECTURES, Checkpoint, CheckpointError
from ..motion.features import read_mirrored

_LAYER_NORM_EPS = 1e-5  # torch.nn.LayerNorm's


def dct_matrix(length: int) -> np.ndarray:
    """Orthonormal DCT-II ``[length, length]`` (row k: frequency k); its transpose is its inverse."""
    k = np.arange(length, dtype=np.float64)[:, None]
    t = np.arange(length, dtype=np.float64)[None]
    d = np.cos(np.pi * (2 * t + 1) * k / (2 * length)) * np.sqrt(2.0 / length)
    d[0] /= np.sqrt(2.0)
    return d.astype(np.float32)


class SiMLPeEngine:
    """A siMLPe release run in NumPy, with the engine's prediction interface (raw features in and out)."""

    mirrored_reading = True  # predict() averages the context's reading and its mirror image's, as Engine does

    def __init__(self, ckpt: Checkpoint):
        if ckpt.architecture != ARCHITECTURES[1]:
            raise CheckpointError(f"this model folder holds a {ckpt.architecture} model, not a siMLPe")
        self.ckpt = ckpt
        self.m, self.n = ckpt.config["encode_len"], ckpt.config["predict_len"]
        self.mean, self.std = ckpt.mean, ckpt.std
        w = {k: v.astype(np.float32) for k, v in ckpt.weights.items()}
        try:
            self.fc_in = (w["fc_in.weight"].T.copy(), w["fc_in.bias"])
            self.fc_out = (w["fc_out.weight"].T.copy(), w["fc_out.bias"])
            self.blocks = [(w[f"blocks.{i}.weight"], w[f"blocks.{i}.bias"].reshape(-1, 1, 1),
                            w[f"blocks.{i}.norm.weight"], w[f"blocks.{i}.norm.bias"])
                           for i in range(ckpt.config["blocks"])]
        except KeyError as e:
            raise CheckpointError(f"the siMLPe weights lack {e}: the folder's model.json and model.safetensors "
                                  "come from different models (copy both from the same model folder)") from None
        self.dct = dct_matrix(self.m)

    def predict_once(self, context: np.ndarray) -> np.ndarray:
        """Raw context ``[B, m, C]`` -> the next ``n`` raw frames ``[B, n, C]``, from one reading."""
        x = ((np.asarray(context, np.float32) - self.mean) / self.std).astype(np.float32)
        b, m, c = x.shape
        z = (self.dct @ x.transpose(1, 0, 2).reshape(m, b * c)).reshape(m, b, c)  # (m, B, C) frequencies
        z = z @ self.fc_in[0] + self.fc_in[1]
        for weight, bias, gain, shift in self.blocks:
            y = (weight @ z.reshape(m, b * c)).reshape(m, b, c) + bias  # mixes along time
            mu = y.mean(-1, keepdims=True)
            var = ((y - mu) ** 2).mean(-1, keepdims=True)
            z = z + (y - mu) / np.sqrt(var + _LAYER_NORM_EPS) * gain + shift  # layer norm over the channels
        z = z @ self.fc_out[0] + self.fc_out[1]
        offsets = (self.dct.T @ z.reshape(m, b * c)).reshape(m, b, c).transpose(1, 0, 2)  # (B, m, C)
        return (offsets[:, :self.n] + x[:, -1:]) * self.std + self.mean

    def predict(self, context: np.ndarray) -> np.ndarray:
        """Raw context ``[B, m, C]`` -> the next ``n`` raw frames ``[B, n, C]``: read as it is and mirrored, the
        two predictions averaged (the mirrored one mirrored back), as :meth:`Engine.predict` reads."""
        return read_mirrored(self.predict_once, context) if self.mirrored_reading else self.predict_once(context)

    def predict_next(self, context: np.ndarray) -> np.ndarray:
        """:meth:`predict` for a rollout's windows after the first (:meth:`Engine.predict_next`'s interface): a
        siMLPe has no decoder to leave out, so it reads its own motion as it reads a clip."""
        return self.predict(context)
