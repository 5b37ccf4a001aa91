"""The gap model: a learnt in-betweener that reads the frames before a gap and the pose after it and
says how the motion between them differs from their interpolation (NumPy; the weights are trained
by :mod:`model_core.model.gap_training`).

Every frame is taken in the body's own terms (:func:`terms`: the hips' ground position, the heading,
and the joints in the body's frame), relative to the context's last frame. The model's output is a
short sine series per channel over the gap, ``sum_k c_k sin(k pi s)`` at the fraction ``s`` of the
way, added to the interpolation in those terms: the series is 0 at both ends, so the gap leaves the
context and reaches the target exactly, and it is smooth for every gap length, which is only an
input. What the series adds is what interpolation cannot know: a step's lift and swing, a body that
speeds up, slows, bobs or turns on its way.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..io.checkpoint import CheckpointError, read_safetensors
from ..motion.conventions import STANDARD_LEG_LENGTH
from ..motion.features import root_and_local, wrap_angle, yaw_matrix
from ..rig.rigs import leg_length

FORMAT = "strnn-gap-1"
CONTEXT = 10  # context frames the model reads (fewer are padded by holding the first)
TERMS = 66  # per frame: the hips' ground x and z, the heading, 21 joints x 3 in the body's frame
MAX_GAP = 120  # gap frames at 30 fps the model was trained for (4 s)
INPUTS = CONTEXT * TERMS + 2 * TERMS + 2


def body_scale(pos: np.ndarray) -> float:
    """What brings the legs of ``pos`` ``[F, 21, 3]`` to the standard length: the model reads every body
    at one size, so that a tall or a short actor is not motion it has never seen."""
    legs = leg_length(np.asarray(pos, np.float64))
    return float(STANDARD_LEG_LENGTH / legs) if np.isfinite(legs) and legs > 1e-9 else 1.0


def terms(pos: np.ndarray) -> np.ndarray:
    """``[F, 66]`` body terms of positions ``[F, 21, 3]`` (Y-up): the hips' ground position (x, z), the
    heading (radians about +Y, unwrapped over the frames) and the joints in the body's frame
    (:func:`features.root_and_local`, flattened)."""
    root, yaw, local = root_and_local(pos)
    return np.concatenate([root[:, [0, 2]], yaw[:, None], local.reshape(len(local), -1)], 1)


def positions(t: np.ndarray) -> np.ndarray:
    """Positions ``[..., 21, 3]`` of body terms ``[..., 66]`` (the inverse of :func:`terms`)."""
    local = t[..., 3:].reshape(t.shape[:-1] + (21, 3))
    root = np.stack([t[..., 0], np.zeros_like(t[..., 0]), t[..., 1]], -1)
    return np.einsum("...ij,...kj->...ki", yaw_matrix(t[..., 2]), local) + root[..., None, :]


def relative(t: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """Body terms ``[..., F, 66]`` taken relative to the frame ``origin`` ``[..., 66]``: its ground position
    at 0 and its heading 0 (the pose in the body's frame does not change)."""
    out = np.array(t, np.float64)
    yaw0 = origin[..., 2]
    c, s = np.cos(yaw0)[..., None], np.sin(yaw0)[..., None]
    dx, dz = t[..., 0] - origin[..., None, 0], t[..., 1] - origin[..., None, 1]
    out[..., 0], out[..., 1] = c * dx - s * dz, s * dx + c * dz
    out[..., 2] = t[..., 2] - yaw0[..., None]
    return out


def absolute(t: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """The inverse of :func:`relative`."""
    out = np.array(t, np.float64)
    yaw0 = origin[..., 2]
    c, s = np.cos(yaw0)[..., None], np.sin(yaw0)[..., None]
    out[..., 0] = c * t[..., 0] + s * t[..., 1] + origin[..., None, 0]
    out[..., 1] = -s * t[..., 0] + c * t[..., 1] + origin[..., None, 1]
    out[..., 2] = t[..., 2] + yaw0[..., None]
    return out


def interpolate_terms(last: np.ndarray, target: np.ndarray, n: np.ndarray, frames: int) -> np.ndarray:
    """``[B, frames, 66]`` interpolation from ``last`` to ``target`` ``[B, 66]`` over gaps of ``n`` ``[B]``
    frames (frames past a gap's end repeat its target): the heading the short way round."""
    i = np.arange(1, frames + 1)[None]
    s = np.minimum(i / (np.asarray(n)[:, None] + 1.0), 1.0)[..., None]
    delta = target - last
    delta[:, 2] = wrap_angle(delta[:, 2])
    return last[:, None] + s * delta[:, None]


def sines(n: np.ndarray, frames: int, k: int) -> np.ndarray:
    """``[B, frames, k]`` sine basis ``sin(j pi i / (n + 1))`` for gap frames ``i = 1 .. frames``, 0 past each
    gap's end."""
    i = np.arange(1, frames + 1)[None, :, None]
    n1 = np.asarray(n, np.float64)[:, None, None] + 1.0
    basis = np.sin(np.arange(1, k + 1)[None, None] * np.pi * i / n1)
    return basis * (i < n1)


def inputs(ctx: np.ndarray, target: np.ndarray, moves_on: np.ndarray, n: np.ndarray) -> np.ndarray:
    """The model's input ``[B, INPUTS]``: the context's last frames ``[B, CONTEXT, 66]`` and the target's
    frame and the step after it ``[B, 2, 66]`` in terms relative to the context's last frame, whether that
    step is known ``moves_on`` ``[B]`` (0 or 1; if not, it is given as 0), and the gap's length ``n``."""
    step = (target[:, 1] - target[:, 0]) * moves_on[:, None]
    tgt = target[:, 0].copy()
    tgt[:, 2] = wrap_angle(tgt[:, 2])
    b = len(ctx)
    return np.concatenate([ctx.reshape(b, -1), tgt, step, moves_on[:, None], np.asarray(n, np.float64)[:, None]
                           / 60.0], 1)


@dataclass
class GapModel:
    """The gap model's weights and normalisation, run in NumPy."""

    weights: dict
    config: dict

    @classmethod
    def load(cls, folder: str | Path) -> GapModel:
        folder = Path(folder)
        try:
            doc = json.loads((folder / "model.json").read_text())
        except (OSError, ValueError) as e:
            raise CheckpointError(f"{folder}: no readable gap model ({e})") from None
        if doc.get("format") != FORMAT:
            raise CheckpointError(f"{folder}: not a gap model (format {doc.get('format')!r}, wanted {FORMAT!r})")
        cfg = doc.get("config")
        if not isinstance(cfg, dict) or not all(isinstance(cfg.get(k), int) for k in ("sines", "blocks", "width")):
            raise CheckpointError(f"{folder / 'model.json'}: no complete 'config' (sines, blocks, width): copy the "
                                  "model folder again")
        if cfg.get("context", CONTEXT) != CONTEXT or cfg.get("max_gap", MAX_GAP) != MAX_GAP:
            raise CheckpointError(f"{folder}: a gap model for {cfg.get('context')} context frames and gaps up to "
                                  f"{cfg.get('max_gap')}; this code reads {CONTEXT} and bridges {MAX_GAP}")
        try:
            weights = read_safetensors(folder / "model.safetensors")
        except (OSError, ValueError) as e:
            raise CheckpointError(f"{folder / 'model.safetensors'} is unreadable ({e}): copy the model folder "
                                  "again") from e
        w, k = cfg["width"], cfg["sines"]
        shapes = {"in_mean": (INPUTS,), "in_std": (INPUTS,), "out_scale": (TERMS,), "inp.weight": (w, INPUTS),
                  "norm.weight": (w,), "out.weight": (k * TERMS, w)}
        shapes |= {f"blocks.{b}.fc{i}.weight": (w, w) for b in range(cfg["blocks"]) for i in (1, 2)}
        for name, shape in shapes.items():
            if name not in weights or tuple(weights[name].shape) != shape:
                raise CheckpointError(f"{folder / 'model.safetensors'}: {name} is missing or not {shape}: the "
                                      "weights do not match model.json (copy the model folder again)")
        return cls({n: a.astype(np.float64 if n in ("in_mean", "in_std") else np.float32) for n, a in weights.items()},
                   doc)

    @property
    def k(self) -> int:
        return int(self.config["config"]["sines"])

    def coefficients(self, x: np.ndarray) -> np.ndarray:
        """Sine coefficients ``[B, k, 66]`` for inputs ``[B, INPUTS]``."""
        w = self.weights
        h = ((x - w["in_mean"]) / w["in_std"]).astype(np.float32)  # in the weights' precision: no float64 copies
        h = h @ w["inp.weight"].T + w["inp.bias"]
        for b in range(int(self.config["config"]["blocks"])):
            p = f"blocks.{b}."
            z = _layer_norm(h, w[p + "norm.weight"], w[p + "norm.bias"])
            z = _gelu(z @ w[p + "fc1.weight"].T + w[p + "fc1.bias"])
            h = h + z @ w[p + "fc2.weight"].T + w[p + "fc2.bias"]
        h = _layer_norm(h, w["norm.weight"], w["norm.bias"])
        out = (h @ w["out.weight"].T + w["out.bias"]).reshape(len(x), self.k, TERMS)
        return out * w["out_scale"]

    def fill(self, context: np.ndarray, target: np.ndarray, frames: int) -> np.ndarray:
        """The ``frames`` positions ``[frames, 21, 3]`` between ``context`` ``[C, 21, 3]`` (C >= 1) and
        ``target`` ``[T, 21, 3]`` (T >= 1; a second frame gives the motion after it), at 30 fps, metres."""
        context, target = np.asarray(context, np.float64), np.asarray(target, np.float64)
        scale = body_scale(np.concatenate([context, target]))
        context, target = context * scale, target * scale
        if len(context) < CONTEXT:
            context = np.concatenate([np.repeat(context[:1], CONTEXT - len(context), 0), context])
        seq = terms(np.concatenate([context[-CONTEXT:], target[:2]]))
        origin = seq[CONTEXT - 1]
        rel = relative(seq[None], origin[None])[0]
        ctx, tgt = rel[:CONTEXT], rel[CONTEXT:]
        moves_on = np.array([1.0 if len(tgt) > 1 else 0.0])
        tgt = np.concatenate([tgt, tgt[-1:]])[:2]
        n = np.array([frames])
        x = inputs(ctx[None], tgt[None], moves_on, n)
        out = interpolate_terms(ctx[None, -1], tgt[None, 0], n, frames)
        out = out + np.einsum("bfk,bkc->bfc", sines(n, frames, self.k), self.coefficients(x))
        return (positions(absolute(out, origin[None])[0]) / scale).astype(np.float32)


def _layer_norm(x: np.ndarray, weight: np.ndarray, bias: np.ndarray, eps: float = 1e-5) -> np.ndarray:
    mu = x.mean(-1, keepdims=True)
    var = ((x - mu) ** 2).mean(-1, keepdims=True)
    return (x - mu) / np.sqrt(var + eps) * weight + bias


def _gelu(x: np.ndarray) -> np.ndarray:
    return 0.5 * x * (1.0 + np.tanh(0.7978845608028654 * (x + 0.044715 * x ** 3)))
