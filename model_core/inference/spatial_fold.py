"""Fold the spatial encoder and decoder of a checkpoint into dense NumPy layers.

Each spatial level of :mod:`model_core.model.strnn` (L1..L4, per body group) becomes one
dense matrix with zeros where the body graph has no edge, and each batch norm
(eval mode: ``y = a * t + s``) is folded into the layer that reads it. The folded
functions compute exactly what the torch modules compute in eval mode.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..motion.conventions import LIMBS, group_channels

_EPS = 1e-5  # torch BatchNorm1d eps
Array = np.ndarray
SMALL_ROWS = 4  # up to this many rows, a product is faster as one matrix-vector product per row


def rows_matmul(a: Array, w: Array) -> Array:
    """``a @ w``. For a NumPy ``a`` ``[N, K]`` of 2 to :data:`SMALL_ROWS` rows, one matrix-vector
    product per row: BLAS's matrix-matrix path is several times slower than that for so few rows
    (a generating model's batch of 1 is 2 rows in the decoder, 4 with the mirrored reading)."""
    if isinstance(a, np.ndarray) and a.ndim == 2 and 1 < len(a) <= SMALL_ROWS:
        out = np.empty((len(a), w.shape[1]), np.result_type(a, w))
        for i in range(len(a)):
            np.dot(a[i], w, out=out[i])
        return out
    return a @ w


def stack_matmul(a: Array, w: Array) -> Array:
    """``np.matmul(a, w)`` of stacks ``[S, N, K]`` and ``[S, K, M]``, by :func:`rows_matmul` for few rows."""
    if a.shape[1] <= SMALL_ROWS:
        return np.stack([rows_matmul(a[i], w[i]) for i in range(len(a))])
    return np.matmul(a, w)


def _bn(w: dict, prefix: str) -> tuple[Array, Array]:
    """Scale and shift ``(a, s)`` of the batch norm at ``prefix`` in eval mode (identity for a model
    trained without spatial norms, whose weights have none)."""
    if f"{prefix}.running_var" not in w:
        n = len(w[prefix.rsplit(".", 1)[0] + ".0.bias"])
        return np.ones(n, np.float32), np.zeros(n, np.float32)
    a = w[f"{prefix}.weight"] / np.sqrt(w[f"{prefix}.running_var"] + _EPS)
    return a, w[f"{prefix}.bias"] - w[f"{prefix}.running_mean"] * a


def _fold(bn: tuple[Array, Array], weight: Array, bias: Array) -> tuple[Array, Array]:
    """Fold ``y = a * t + s`` feeding ``y @ weight + bias`` into weights applied to ``t``."""
    a, s = bn
    return a[:, None] * weight, bias + s @ weight


def _blocks(w: dict, prefix: str, keys, n_in: int, rows_of, width: int):
    """Dense (n_in, len(keys) * width) matrix of several blocks; ``rows_of(k, W)`` yields
    (row slice or index array, sub-matrix) pairs placing block k's input weights."""
    mat = np.zeros((n_in, len(keys) * width), np.float32)
    bias = np.zeros(len(keys) * width, np.float32)
    scale, shift = np.ones(len(keys) * width, np.float32), np.zeros(len(keys) * width, np.float32)
    for i, k in enumerate(keys):
        cols = slice(i * width, (i + 1) * width)
        for rows, sub in rows_of(k, w[f"{prefix}.{k}.0.weight"].T):
            mat[rows, cols] = sub
        bias[cols] = w[f"{prefix}.{k}.0.bias"]
        scale[cols], shift[cols] = _bn(w, f"{prefix}.{k}.3")
    return mat, bias, (scale, shift)


def _same(a: Array) -> Array:
    return a


def fold_spatial(w: dict, cfg: dict, to: Callable = _same,
                 tanh: Callable = np.tanh) -> tuple[Callable, Callable, tuple[Array, Array]]:
    """Return ``enc(x (N, C)) -> (N, W)`` (before the last batch norm), ``dec(h (N, W)) -> (N, C)``
    and the last encoder batch norm ``(a, s)``, which the caller folds into the LSTMs.

    ``to`` converts each folded matrix and ``tanh`` is the activation, so the same layers run on
    another array library (``torch.from_numpy`` and ``torch.tanh``: differentiable twins)."""
    c, width = cfg["frame_size"], cfg["width"]
    if not cfg["spatial"]:
        we, be = to(w["encode_frame.weight"].T.copy()), to(w["encode_frame.bias"])
        wd, bd = to(w["decode_frame.weight"].T.copy()), to(w["decode_frame.bias"])
        identity = (np.ones(width, np.float32), np.zeros(width, np.float32))
        return (lambda x: rows_matmul(x, we) + be), (lambda h: rows_matmul(h, wd) + bd), identity
    enc, out_bn = _fold_encoder(w, c, width, to, tanh)
    return enc, _fold_decoder(w, c, width, to, tanh), out_bn


def _fold_encoder(w: dict, c: int, width: int, to: Callable = _same, tanh: Callable = np.tanh):
    g = group_channels()
    w1, w2, w3 = width // 8, width // 4, width // 2
    parts = ("torso",) + LIMBS
    m1, b1, bn1 = _blocks(w, "encode_frame.l1", parts, c, lambda k, W: [(g[k], W)], w1)

    def l2_rows(k, W):  # input is cat(part[k], part[torso])
        i = parts.index(k)
        return [(slice(i * w1, (i + 1) * w1), W[:w1]), (slice(0, w1), W[w1:])]

    m2, b2, bn2 = _blocks(w, "encode_frame.l2", LIMBS, len(parts) * w1, l2_rows, w2)
    m2, b2 = _fold(bn1, m2, b2)

    def l3_rows(k, W):  # upper = cat(l_arm, r_arm), lower = cat(l_leg, r_leg)
        first = 0 if k == "upper" else 2
        return [(slice(first * w2, (first + 2) * w2), W)]

    m3, b3, bn3 = _blocks(w, "encode_frame.l3", ("upper", "lower"), 4 * w2, l3_rows, w3)
    m3, b3 = _fold(bn2, m3, b3)
    w4 = w["encode_frame.l4.0.weight"].T  # rows: upper, lower, root, contacts
    m4h, b4 = _fold(bn3, w4[: 2 * w3], w["encode_frame.l4.0.bias"])
    m4x = np.zeros((c, width), np.float32)
    m4x[g["root"] + g["contacts"]] = w4[2 * w3:]
    n1 = m1.shape[1]
    first = to(np.concatenate([m1, m4x], 1))  # one matmul feeds L1 and L4's direct inputs
    b1, m2, b2, m3, b3, m4h, b4 = (to(np.ascontiguousarray(a)) for a in (b1, m2, b2, m3, b3, m4h, b4))

    def enc(x: Array) -> Array:
        z = rows_matmul(x, first)
        t = tanh(z[:, :n1] + b1)
        t = tanh(rows_matmul(t, m2) + b2)
        t = tanh(rows_matmul(t, m3) + b3)
        return tanh(rows_matmul(t, m4h) + z[:, n1:] + b4)

    return enc, _bn(w, "encode_frame.l4.3")


def _fold_decoder(w: dict, c: int, width: int, to: Callable = _same, tanh: Callable = np.tanh) -> Callable:
    g = group_channels()
    w1, w2, w3 = width // 8, width // 4, width // 2
    m4, b4, bn4 = _blocks(w, "decode_frame.l4", ("upper", "lower"), width, lambda k, W: [(slice(None), W)], w3)
    src = {"l_arm": 0, "r_arm": 0, "l_leg": 1, "r_leg": 1}
    m3, b3, bn3 = _blocks(w, "decode_frame.l3", LIMBS, 2 * w3,
                          lambda k, W: [(slice(src[k] * w3, (src[k] + 1) * w3), W)], w2)
    m3, b3 = _fold(bn4, m3, b3)
    m2, b2, bn2 = _blocks(w, "decode_frame.l2", LIMBS, 4 * w2,
                          lambda k, W: [(slice(LIMBS.index(k) * w2, (LIMBS.index(k) + 1) * w2), W)], 2 * w1)
    m2, b2 = _fold(bn3, m2, b2)
    out_h = np.zeros((width, c), np.float32)
    out_l = np.zeros((4 * 2 * w1, c), np.float32)
    bias = np.zeros(c, np.float32)
    for name in ("root", "contacts"):
        out_h[:, g[name]] = w[f"decode_frame.{name}.weight"].T
        bias[g[name]] = w[f"decode_frame.{name}.bias"]
    torso_w = w["decode_frame.torso.weight"].T  # (4 * w1, 12): torso halves of the four limbs
    for i, k in enumerate(LIMBS):
        base = i * 2 * w1
        out_l[base:base + w1, g[k]] = w[f"decode_frame.out.{k}.weight"].T
        out_l[base + w1:base + 2 * w1, g["torso"]] = torso_w[i * w1:(i + 1) * w1]
        bias[g[k]] = w[f"decode_frame.out.{k}.bias"]
    bias[g["torso"]] = w["decode_frame.torso.bias"]
    out_l, bias = _fold(bn2, out_l, bias)
    n4 = m4.shape[1]
    first = to(np.concatenate([m4, out_h], 1))
    b4, m3, b3, m2, b2, out_l, bias = (to(np.ascontiguousarray(a)) for a in (b4, m3, b3, m2, b2, out_l, bias))

    def dec(h: Array) -> Array:
        z = rows_matmul(h, first)
        t = tanh(z[:, :n4] + b4)
        t = tanh(rows_matmul(t, m3) + b3)
        t = tanh(rows_matmul(t, m2) + b2)
        return rows_matmul(t, out_l) + z[:, n4:] + bias

    return dec
