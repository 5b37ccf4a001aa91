"""NumPy inference engine for STRNN (no torch needed): predict, extrapolate, denoise.

Loads the same release checkpoint as the torch model. Batch norms are folded into
the layers that read them, the four spatial levels become one dense matrix each
(zeros where the body graph has no edge), and the backward decoder and forward
predictor step together, so a 20-frame window costs a few hundred small NumPy calls (a rollout's later
windows run the predictor alone: :meth:`Engine.predict_next`).
Features in and out are RAW (un-normalised) ``[..., T, C]`` in :data:`LAYOUT` order.
"""

from __future__ import annotations

from functools import lru_cache, partial
from pathlib import Path

import numpy as np

from ..io.checkpoint import Checkpoint, load_release
from ..motion.conventions import LAYOUT, PARENTS
from ..motion.features import (
    RootStart,
    body_lengths,
    continue_positions,
    features_to_positions,
    integrate_root,
    learnt_bodies,
    learnt_body,
    on_body_of,
    positions_to_features,
    read_mirrored,
    with_bone_lengths,
    yaw_matrix,
)
from ..motion.stance import SETTLE_FROM, ground, settle_stances
from ..ops.footlock import legs_out_of_floor
from ..ops.seam import PREDICT_SEAM_FRAMES, seam_fade
from .memory import ClipMemory
from .simlpe_engine import SiMLPeEngine
from .spatial_fold import fold_spatial, rows_matmul, stack_matmul
from .steps import drive


def _lstm(w: dict, prefix: str, suffix: str = "") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(W_ih.T, W_hh.T, bias) with i, f, o rows halved so one tanh yields all gates."""
    wih, whh = w[f"{prefix}.weight_ih{suffix}"], w[f"{prefix}.weight_hh{suffix}"]
    b = w[f"{prefix}.bias_ih{suffix}"] + w[f"{prefix}.bias_hh{suffix}"]
    h = whh.shape[1]
    scale = np.ones(4 * h, np.float32)
    scale[: 2 * h] = 0.5  # input and forget gates
    scale[3 * h:] = 0.5  # output gate; sigmoid(z) = 0.5 * tanh(z / 2) + 0.5
    return (wih * scale[:, None]).T.copy(), (whh * scale[:, None]).T.copy(), (b * scale).astype(np.float32)


@lru_cache(maxsize=8)
def _gate_affine(h: int) -> tuple[np.ndarray, np.ndarray]:
    """(scale, shift) ``[4H]`` taking tanh of the pre-scaled gates to sigmoid (i, f, o) and tanh (g):
    sigmoid(z) = 0.5 * tanh(z / 2) + 0.5."""
    scale = np.full(4 * h, 0.5, np.float32)
    scale[2 * h:3 * h] = 1.0
    return scale, 1.0 - scale


def _cell(gates: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """LSTM state update from pre-scaled gates ``[..., 4H]`` (PyTorch order i, f, g, o).
    Few, in-place NumPy calls: at batch 1 their overhead, not arithmetic, is the cost."""
    h = c.shape[-1]
    scale, shift = _gate_affine(h)
    t = np.tanh(gates)
    t *= scale
    t += shift
    c = t[..., h:2 * h] * c
    c += t[..., :h] * t[..., 2 * h:3 * h]
    return t[..., 3 * h:] * np.tanh(c), c


def offset_weights(n: int, keep: int | None) -> np.ndarray:
    """How much of the last context frame each of ``n`` predicted frames adds to its decoded offset
    ``[n]``: 1 for the first ``keep`` frames, then falling linearly to 0 at the last (``keep`` None or
    at least ``n``: all 1). Only for a model whose decoder outputs offsets."""
    w = np.ones(n)
    if keep is not None and keep < n:
        w[keep:] = 1.0 - np.arange(1, n - keep + 1) / (n - keep)
    return w


_UNREAD = object()  # Engine.gap before it is first asked for
# A clip whose bone lengths (summed differences, in model units) are within this share of a body the model learnt
# (a seed window's) is read as it is (on_learnt_body); others are read on the body it learnt most. The training
# takes' bodies: the Bandai actors' within 0.4 % of each other, the CMU skeletons' 12 to 15 % from them (two of the
# three with a seed window of their own); a generated Rigify rig's 14 % or more from all of them. Read on the
# learnt body, a walk on a Rigify rig walks on (0.30 -> 0.88 x its pace); a CMU take read on the Bandai body
# predicts better up to 1 s but more of its long extensions die, so the bodies the model learnt are kept (model
# card, "What it is").
LEARNT_BODY_TOLERANCE = 0.05

# The siMLPe's share of the first window where the release holds one (checkpoint.SIMLPE), the STRNN's (with
# its companion) the rest: chosen on the held-out groups among 0.5 to 0.8 (model card, "What it is").
SIMLPE_SHARE = 0.6

# How many windows of a rollout lean on the release's regularised STRNN (checkpoint.REGULARISED) as far as the model
# does not know the clip's motion (Engine.extrapolate's ``unfamiliar``): the first two, 1.33 s, where the motion is
# still the clip's; every later window is the release's own, as a model trained with dropout and run without it
# settles long rollouts into a stand (model card, "What it is").
REGULARISED_WINDOWS = 2


class Engine:
    """STRNN inference in NumPy. Build with :meth:`load`."""

    seam_frames = PREDICT_SEAM_FRAMES  # fade-out (frames) of the seam correction in predict() (ops/seam.py)
    mirrored_reading = True  # predict() averages the context's reading and its mirror image's
    decode_later_windows = False  # True: a rollout's later windows run the backward decoder too (predict_next)

    def __init__(self, ckpt: Checkpoint):
        ckpt.require_strnn()
        cfg = ckpt.config
        self.ckpt = ckpt
        self.m, self.n, self.width = cfg["encode_len"], cfg["predict_len"], cfg["width"]
        self.r = cfg.get("decode_len") or self.m  # the context's last frames the decoder reconstructs
        self.offsets = bool(cfg.get("offsets", False))
        self.base_weights = offset_weights(self.n, cfg.get("offset_keep")).astype(np.float32)  # per predicted frame
        self.mean, self.std = ckpt.mean, ckpt.std
        w = {k: v.astype(np.float32) for k, v in ckpt.weights.items()}
        self.enc_frame, self.dec_frame, out_bn = fold_spatial(w, cfg)
        # The last encoder batch norm (scale a, shift s) feeds each LSTM's input weights.
        a, s = out_bn
        wih, self.enc_whh, b = _lstm(w, "encoder", "_l0")
        self.enc_wih, self.enc_b = a[:, None] * wih, b + s @ wih
        dec, pred = _lstm(w, "decoder"), _lstm(w, "predictor")
        self.step_wih = np.stack([a[:, None] * dec[0], a[:, None] * pred[0]])  # (2, W, 4H)
        self.step_whh = np.stack([dec[1], pred[1]])
        self.step_b = np.stack([dec[2] + s @ dec[0], pred[2] + s @ pred[0]])[:, None]  # (2, 1, 4H)
        # The decoder's first input is the learnt start code, not a batch-normed frame code.
        self.start_gates = (w["start"] - s) @ dec[0]
        # A predictor that reads the context (STRNNConfig.predictor_context): its code of the context enters
        # the predictor's gates through the predictor's input weights, folded into one map.
        self.context_gates = (w["context_in.weight"].T @ pred[0]).astype(np.float32) \
            if cfg.get("predictor_context") else None
        # A decoder that reads the encoder's state at the frame it reconstructs (STRNNConfig.decoder_skip),
        # through the decoder's input weights, folded into one map.
        self.dec_skip_gates = (w["dec_skip.weight"].T @ dec[0]).astype(np.float32) \
            if cfg.get("decoder_skip") else None
        self.skip = w["skip"] if cfg.get("temporal_skip") else None  # (n, m): STRNNConfig.temporal_skip
        self.filter = [(w[f"filter.net.{i}.weight"].T.copy(), w[f"filter.net.{i}.bias"]) for i in (0, 2, 4, 6)] \
            if cfg["residual"] else None
        self.filter_context = bool(cfg.get("filter_context", False))
        self.companion = Engine(ckpt.companion) if ckpt.companion is not None else None
        self.simlpe = SiMLPeEngine(ckpt.simlpe) if ckpt.simlpe is not None else None
        self.regularised = Engine(ckpt.regularised) if ckpt.regularised is not None else None
        self._gap = _UNREAD  # the release's gap model (Fill Gap's in-betweener): read on first use (gap)

    @property
    def gap(self):
        """The release's gap model (Fill Gap's in-betweener, :meth:`Checkpoint.load_gap`), or None: read the
        first time it is asked for, and kept. Assign None to fill gaps with the STRNN alone."""
        if self._gap is _UNREAD:
            self._gap = self.ckpt.load_gap()
        return self._gap

    @gap.setter
    def gap(self, model) -> None:
        self._gap = model

    @classmethod
    def load(cls, folder: str | Path | None = None) -> Engine:
        """Load a release folder (default: the bundled model)."""
        return cls(load_release(folder))

    @property
    def seeds(self) -> np.ndarray:
        """Shipped seed windows, raw features ``[K, m, C]``."""
        return self.ckpt.seeds

    # ----------------------------------------------------------------- core
    def _window(self, x: np.ndarray, decode: bool = True) -> np.ndarray:
        """Normalised context ``(B, m, C)`` -> normalised window ``(B, r + n, C)``: the context's last r frames
        decoded, then the prediction. ``decode`` False: the context's last r frames stand in for their
        reconstruction and the backward decoder is not run (:meth:`predict_next`)."""
        b, m, c = x.shape
        r = self.r
        xin = self.enc_frame(x.reshape(b * m, c)) @ self.enc_wih
        xin = (xin + self.enc_b).reshape(b, m, -1)
        h = np.zeros((b, self.width), np.float32)
        cs = np.zeros_like(h)
        states = np.empty((m, b, self.width), np.float32) if decode and self.dec_skip_gates is not None else None
        for t in range(m):
            h, cs = _cell(xin[:, t] + rows_matmul(h, self.enc_whh), cs)
            if states is not None:
                states[t] = h
        # The decoder's gates from the encoder's state at each frame, in the decoder's (backward) order.
        dec_skip = (states[::-1].reshape(m * b, -1) @ self.dec_skip_gates).reshape(m, b, -1) \
            if states is not None else None
        # The recurrent steps run as a stack: (decoder, predictor), or the predictor alone; p is its place.
        k = 2 if decode else 1
        p = k - 1
        wih, whh, bias = self.step_wih[2 - k:], self.step_whh[2 - k:], self.step_b[2 - k:]
        hs, cs = np.stack([h] * k), np.stack([cs] * k)  # (k, B, H)
        first = self.enc_frame(x[:, -1]) @ self.step_wih[1]  # (B, 4H)
        gin = (np.stack([np.broadcast_to(self.start_gates, first.shape), first]) if decode else first[None]) + bias
        extra = (x - x[:, -1:]).reshape(b, -1) @ self.context_gates if self.context_gates is not None else None
        if extra is not None:
            gin[p] += extra
        if dec_skip is not None:
            gin[0] += dec_skip[0]
        steps = max(r, self.n) if decode else self.n
        out = np.empty((k, steps, b, c), np.float32)
        base = x[:, -1] if self.offsets else None  # (B, C)
        skip = np.einsum("it,btc->ibc", self.skip, x - x[:, -1:]) if self.skip is not None else None
        for t in range(steps):
            hs, cs = _cell(gin + stack_matmul(hs, whh), cs)
            frames = self.dec_frame(hs.reshape(k * b, -1))  # (kB, C)
            if base is not None:
                if decode:
                    frames[:b] += base
                frames[p * b:] += base * self.base_weights[min(t, self.n - 1)]
            if skip is not None:
                frames[p * b:] += skip[min(t, self.n - 1)]
            out[:, t] = frames.reshape(k, b, c)
            if t + 1 < steps:
                gin = stack_matmul(self.enc_frame(frames).reshape(k, b, -1), wih) + bias
                if extra is not None:
                    gin[p] += extra
                if dec_skip is not None and t + 1 < r:
                    gin[0] += dec_skip[t + 1]
        decoded = out[0, :r][::-1] if decode else x[:, -r:].transpose(1, 0, 2)
        window = np.concatenate([decoded, out[p, : self.n]]).transpose(1, 0, 2)  # (B, T, C)
        if self.filter is not None:
            y = window.reshape(b, -1)
            z = np.concatenate([y, x.reshape(b, -1)], 1) if self.filter_context else y
            for i, (wt, bias) in enumerate(self.filter):
                z = rows_matmul(z, wt) + bias
                if i < 3:
                    z = np.where(z > 0, z, np.expm1(np.minimum(z, 0)))  # ELU
            window = (y + z).reshape(window.shape)
        return window

    def forward(self, context: np.ndarray, decode: bool = True) -> np.ndarray:
        """Raw context ``[B, m, C]`` -> raw decoded context (its last r frames) + prediction ``[B, r + n, C]``
        (``decode`` False: the context's last r frames, filtered, in place of their reconstruction)."""
        x = ((np.asarray(context, np.float32) - self.mean) / self.std).astype(np.float32)
        return self._window(x, decode) * self.std + self.mean

    def predict(self, context: np.ndarray, decode: bool = True) -> np.ndarray:
        """Raw context ``[B, m, C]`` -> the next ``n`` raw frames ``[B, n, C]``.

        With :attr:`mirrored_reading` (the default) the model reads each context twice, as it is and
        as its mirror image (left and right swapped: :func:`mirror_features`, exact on the features),
        in one batch, and the two predictions are averaged, the mirrored one mirrored back. Each
        reading errs in its own way and their average less than either, and what is predicted no
        longer depends on which side of the body was captured as the left. ``decode`` False: the
        backward decoder is not run (:meth:`predict_next`)."""
        self.ckpt.require_generator("predict motion")
        context = np.asarray(context, np.float32)
        once = self.predict_once if decode else partial(self.predict_once, decode=False)
        return read_mirrored(once, context) if self.mirrored_reading else once(context)

    def predict_first(self, context: np.ndarray, unfamiliar: float | np.ndarray = 0.0) -> np.ndarray:
        """:meth:`predict` for the first window of a rollout: with a release that holds a second STRNN
        (:data:`checkpoint.COMPANION`), the average of the two models' predictions; with one that holds a siMLPe
        (:data:`checkpoint.SIMLPE`), that weighted with the siMLPe's by :data:`SIMLPE_SHARE`. Models trained
        apart err differently, and their average is nearer the truth over the next 20 frames (the siMLPe is
        the nearer on motion unlike the training data); but window after window an average drifts towards
        a slower, lower idle, so each later window is this model's own (model card). A partner that reads
        fewer frames than this model reads the last of them; one that predicts fewer frames continues its own
        prediction as far (:func:`partner_ahead`). ``unfamiliar`` (one share, or one per context ``[B]``): how far the
        STRNNs' prediction (this model's, with its companion's) goes towards the regularised model's
        (:meth:`lean_regularised`) before the siMLPe shares it."""
        own = self.predict(context)
        if self.companion is not None:
            own = 0.5 * (own + partner_ahead(self.companion, context, self.n))
        own = self.lean_regularised(own, context, unfamiliar, first=True)
        if self.simlpe is not None:
            own = (1.0 - SIMLPE_SHARE) * own + SIMLPE_SHARE * partner_ahead(self.simlpe, context, self.n)
        return own

    def lean_regularised(self, own: np.ndarray, context: np.ndarray, unfamiliar: float | np.ndarray,
                         first: bool = False) -> np.ndarray:
        """A prediction ``own`` ``[B, n, C]`` from ``context`` ``[B, m, C]`` (this model's, or in a first window its
        and its companion's average) moved ``unfamiliar`` (0 to 1, one or one per context) of the way towards the
        regularised model's (:data:`checkpoint.REGULARISED`: the release fine-tuned with dropout, nearer the truth
        over the next second of motion the release does not know, further on motion it does, where the share is 0);
        ``own`` as it is without that model or where every share is 0. ``first``: the rollout's first window (the
        regularised model reads the context as :meth:`predict` does), else a later one (:meth:`predict_next`)."""
        share = np.clip(np.asarray(unfamiliar, np.float32), 0.0, 1.0)
        if self.regularised is None or not share.any():
            return own
        other = self.regularised.predict(context) if first else self.regularised.predict_next(context)
        share = share.reshape(-1, 1, 1) if share.ndim else share
        return (1.0 - share) * own + share * other

    def predict_next(self, context: np.ndarray) -> np.ndarray:
        """:meth:`predict` for a rollout's windows after the first, whose context is the model's own motion
        (with :attr:`decode_later_windows` False): the context's last r frames stand in for the backward
        decoder's reconstruction of them, so only the encoder and the forward predictor run: 1.5 x the frames a
        second. On its own motion the decoder rebuilds the context closely, and the continuations
        are as near the takes with or without it (model card, "Speed")."""
        return self.predict(context, decode=self.decode_later_windows)

    def predict_once(self, context: np.ndarray, decode: bool = True) -> np.ndarray:
        """:meth:`predict` from one reading of the context ``[B, m, C]`` (float32).

        Seam correction: the decoder's error on the last context frame (its offset from the
        true frame) is carried into the prediction and fades out over ``seam_frames`` frames,
        so the continuation starts where the context ends (0 turns it off). ``decode`` False: the
        backward decoder is not run (:meth:`predict_next`)."""
        window = self.forward(context, decode)
        pred = window[:, self.r:]
        if self.seam_frames > 0:
            offset = context[:, -1, LAYOUT.positions] - window[:, self.r - 1, LAYOUT.positions]
            fade = seam_fade(self.n, self.seam_frames)
            pred[..., LAYOUT.positions] += fade[None, :, None] * offset[:, None]
        return pred

    def full_context(self, ctx: np.ndarray) -> np.ndarray:
        """The last ``m`` frames of contexts ``[B, F, C]``; one of fewer frames is led in by its first frame's
        features (the first pose, moving as it moves there), so that a model that reads a longer context than the
        product asks of a clip (:data:`conventions.MIN_MODEL_FRAMES`) continues a short clip too."""
        if ctx.shape[1] >= self.m:
            return ctx[:, -self.m:]
        if ctx.shape[1] < 1:
            raise ValueError("a rollout needs at least one context frame")
        return np.concatenate([np.repeat(ctx[:, :1], self.m - ctx.shape[1], 1), ctx], 1)

    def extrapolate(self, seed: np.ndarray, frames: int, keep_bone_lengths: bool = True,
                    paired_windows: int | None = 1, memory: ClipMemory | None = None,
                    first_motion: float | np.ndarray = 1.0, settle: bool = False,
                    floor: float | np.ndarray | None = None, unfamiliar: float | np.ndarray = 0.0) -> np.ndarray:
        """Open-loop generation: repeat (take the last m frames, predict n more).

        ``seed``: raw features ``[m, C]`` or ``[B, m, C]``; returns ``[frames, C]`` or
        ``[B, frames, C]``. With ``keep_bone_lengths`` each predicted window is put back on
        the seed's skeleton (bone directions kept) and contacts rounded before it is fed back.
        ``paired_windows``: how many windows from the first are :meth:`predict_first`'s average with
        the companion (None: all of them; a bounded gap, which Fill Gap bends onto its target).
        ``memory`` (a single seed's clip, :class:`memory.ClipMemory`): each window after the first (and the first
        where the memory has a ``first_scale``) leans on what the clip did after its stretch most like the
        continuation's last frames. ``first_motion`` (a share per seed, or one for all): how much of its motion
        away from the context's last pose the first window keeps (:func:`still_window`; 1: all of it).
        ``settle``: the later windows that are stances stand where they are instead of gliding
        (:func:`stance.settle_stances`; what comes out only, the windows fed back are the model's own).
        ``floor`` (a height in the features' units, or one per seed ``[B]``): frames whose lowest heel or toe would go
        under it come out lifted onto it, eased in over the third window (:func:`stance.ground`; again only what comes
        out).
        """
        seed = np.asarray(seed, np.float32)
        single = seed.ndim == 2
        ctx = seed[None] if single else seed
        ctx = self.full_context(ctx)
        lengths = bone_lengths(ctx) if keep_bone_lengths else None
        chunks, total = [], 0
        while total < frames:
            paired = paired_windows is None or len(chunks) < paired_windows
            if paired:
                new = self.predict_first(ctx, unfamiliar if len(chunks) < REGULARISED_WINDOWS else 0.0)
            else:
                new = self.predict_next(ctx)
                if len(chunks) < REGULARISED_WINDOWS:
                    new = self.lean_regularised(new, ctx, unfamiliar)
            if memory is not None and (chunks or memory.first_scale is not None):
                new = np.stack([memory.lean(c, w, first=not chunks, window=len(chunks)) for c, w in zip(ctx, new)])
            if not chunks:
                new = still_window(ctx[:, -1], new, first_motion)
            if keep_bone_lengths:
                new = project_to_skeleton(new, lengths)
            chunks.append(new)
            total += new.shape[1]
            ctx = np.concatenate([ctx, new], 1)[:, -self.m:]
        out = np.concatenate(chunks, 1)[:, :frames]
        if settle:
            out = settle_stances(out, self.n)
        if floor is not None:
            pos = self.ground(out[..., LAYOUT.positions].reshape(*out.shape[:-1], -1, 3), floor)
            out[..., LAYOUT.positions] = pos.reshape(*out.shape[:-1], -1)
        return out[0] if single else out

    def reconstruct(self, feats: np.ndarray, stride: int | None = None) -> np.ndarray:
        """Project raw features ``[F, C]`` (F >= m) onto the manifold: overlapping m-frame
        windows through encoder and decoder, blended with a Hann weight (over the r frames each window
        reconstructs: its last; a take is led in by its first frame so that its first frames are too)."""
        return drive(self.reconstruct_steps(feats, stride))

    def reconstruct_steps(self, feats: np.ndarray, stride: int | None = None, batch: int = 256):
        """:meth:`denoise` as a step generator (:mod:`steps`): yields the fraction of the windows
        done after each ``batch`` of them, returns the features. Each batch is blended in as it comes,
        so a long take holds one batch of windows at a time."""
        feats = np.asarray(feats, np.float32)
        if len(feats) < self.m:
            raise ValueError(f"denoising needs at least {self.m} frames, got {len(feats)}")
        lead = self.m - self.r  # frames before each window's reconstructed ones
        feats = np.concatenate([np.repeat(feats[:1], lead, 0), feats]) if lead else feats
        f = len(feats)
        stride = stride or max(1, self.r // 4)
        starts = sorted(set(range(0, f - self.m + 1, stride)) | {f - self.m})
        weight = np.hanning(self.r + 2)[1:-1].astype(np.float32)[:, None]
        acc = np.zeros_like(feats)
        norm = np.zeros((f, 1), np.float32)
        for i in range(0, len(starts), batch):
            part = starts[i:i + batch]
            decoded = self.forward(np.stack([feats[s:s + self.m] for s in part]))
            for s, d in zip(part, decoded):
                acc[s + lead:s + self.m] += weight * d[: self.r]
                norm[s + lead:s + self.m] += weight
            yield min(i + batch, len(starts)) / len(starts)
        return acc[lead:] / norm[lead:]

    # ------------------------------------------------------ position level
    def extend(self, positions: np.ndarray, frames: int, memory: np.ndarray | None = None,
               first_scale: float | None = None, floor: float | None = None, **kw) -> np.ndarray:
        """Continue global positions ``[F, 21, 3]`` (metres, Y-up, 30 fps, F >= m) by
        ``frames`` new frames ``[frames, 21, 3]``, root motion continuing. The model reads the clip on
        the body it learnt (:func:`on_learnt_body`) and its frames come back on the clip's own. ``memory``
        ``[M, 21, 3]`` (the same space and rate, ending on ``positions``' last frame; usually more of the clip):
        the clip's own motion, which each window after the first leans on (:class:`memory.ClipMemory`), and the
        first too with ``first_scale`` (:func:`memory.first_scale`). ``floor`` (a height): no new frame's heel or
        toe goes under it once the lift has eased in over the third window (:func:`stance.ground`), on the clip's
        own body, after the frames come back to it."""
        seen, back = on_learnt_body(self, positions)
        feats, start = positions_to_features(seen)
        clip = None if memory is None else \
            ClipMemory(positions_to_features(on_learnt_body(self, memory)[0])[0], self.m, self.n, self.std, first_scale)
        new = back(continue_positions(feats, start, self.extrapolate(feats[-self.m:], frames, memory=clip, **kw)))
        return new if floor is None else self.ground(new, floor)

    def ground(self, pos: np.ndarray, floor: float | np.ndarray) -> np.ndarray:
        """A rollout's joints ``[..., F, 21, 3]`` (its first frame the first new one) kept out of ``floor``: lifted
        as a whole from its third window on, eased in over that window (:func:`stance.ground`), as its stances
        settle; a foot the hips still leave under it (the first two windows, where the model's hips are kept) is
        raised by its own leg (:func:`footlock.legs_out_of_floor`)."""
        return legs_out_of_floor(ground(pos, floor, start=SETTLE_FROM * self.n, ramp=self.n), floor)

    def reconstruct_positions(self, positions: np.ndarray, root_weight: float = 3.0,
                          yaw_weight: float = 10.0) -> np.ndarray:
        """Denoise global positions ``[F, 21, 3]``: :meth:`denoise_positions_steps` run to the end."""
        return drive(self.reconstruct_positions_steps(positions, root_weight, yaw_weight))

    def reconstruct_positions_steps(self, positions: np.ndarray, root_weight: float = 3.0, yaw_weight: float = 10.0):
        """Denoise global positions ``[F, 21, 3]``; a step generator like :meth:`reconstruct_steps`.

        The body comes from the model. It is placed on the input frame by frame by the heading
        and shift that fit it best to all 21 input joints (least squares, so the noise of the
        joints averages out); then the heading track is smoothed and the shift track blended
        with the model's own root steps (its slow part from the fit, its fast part from the
        model), ``yaw_weight`` and ``root_weight`` setting how smooth (chosen on the validation
        split)."""
        positions = np.asarray(positions, dtype=np.float64)
        feats, _ = positions_to_features(positions)
        clean = yield from self.reconstruct_steps(feats)
        origin = RootStart(np.zeros(3), 0.0)
        root_model, _ = integrate_root(clean, origin)
        body = features_to_positions(clean, origin) - root_model[:, None]  # root at the origin
        yaw, shift = fit_yaw_shift(body, positions)
        yaw = blend_track(yaw[:, None], np.zeros((len(yaw) - 1, 1)), yaw_weight)[:, 0]
        rot = yaw_matrix(yaw)
        steps = np.einsum("fij,fj->fi", rot[:-1], np.diff(root_model, axis=0))
        root = blend_track(shift, steps, root_weight)
        return (np.einsum("fij,fkj->fki", rot, body) + root[:, None]).astype(np.float32)


def partner_ahead(partner, context: np.ndarray, frames: int) -> np.ndarray:
    """A first window's partner's prediction ``[B, frames, C]`` from the last of the contexts ``[B, F, C]`` it reads:
    one window where it predicts as many frames, else its own open loop (its next windows read its own frames) to as
    far, so that a partner of a shorter window shares all of a longer one."""
    ctx, out, total = context[:, -partner.m:], [], 0
    while total < frames:
        new = partner.predict(ctx) if not out else partner.predict_next(ctx)
        out.append(new)
        total += new.shape[1]
        ctx = np.concatenate([ctx, new], 1)[:, -partner.m:]
    return np.concatenate(out, 1)[:, :frames]


def still_window(last: np.ndarray, window: np.ndarray, motion: float | np.ndarray) -> np.ndarray:
    """Windows ``[B, n, C]`` kept at ``motion`` (a share per window ``[B]``, or one) of their motion away from the
    frames ``last`` ``[B, C]`` held still: the root-local joints drawn towards ``last``'s, the root's velocity and
    turn scaled by it, the contacts as predicted. 1 (or more) leaves a window as it is."""
    motion = np.broadcast_to(np.asarray(motion, np.float32), window.shape[:1])
    if (motion >= 1.0).all():
        return window
    held = np.repeat(np.asarray(last, np.float32)[:, None], window.shape[1], 1)
    held[..., LAYOUT.root] = 0.0
    held[..., LAYOUT.contacts] = window[..., LAYOUT.contacts]
    k = np.minimum(motion, 1.0)[:, None, None]
    return (held + k * (window - held)).astype(window.dtype)


def fit_yaw_shift(body: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per frame, the turn about the up axis ``[F]`` (unwrapped radians) and shift ``[F, 3]``
    that put ``body`` ``[F, J, 3]`` closest to ``target`` ``[F, J, 3]`` in the least-squares
    sense: ``yaw_matrix(yaw) @ body + shift ~ target``."""
    bc, tc = body.mean(1), target.mean(1)
    b, t = body - bc[:, None], target - tc[:, None]
    sin = (t[..., 0] * b[..., 2] - t[..., 2] * b[..., 0]).sum(1)
    cos = (t[..., 0] * b[..., 0] + t[..., 2] * b[..., 2]).sum(1)
    yaw = np.unwrap(np.arctan2(sin, cos))
    return yaw, tc - np.einsum("fij,fj->fi", yaw_matrix(yaw), bc)


def blend_track(noisy: np.ndarray, steps: np.ndarray, weight: float) -> np.ndarray:
    """Track ``[F, K]`` minimising ``|p - noisy|^2 + weight * |diff(p) - steps|^2`` (``steps`` ``[F-1, K]``)."""
    f = len(noisy)
    # Normal equations (I + w D^T D) p = noisy + w D^T steps: tridiagonal, solved by elimination.
    diag = 1.0 + weight * np.r_[1.0, np.full(f - 2, 2.0), 1.0] if f > 1 else np.ones(1)
    rhs = noisy.astype(np.float64).copy()
    rhs[:-1] -= weight * steps
    rhs[1:] += weight * steps
    return solve_tridiagonal(np.full(f - 1, -weight), diag, rhs)


def solve_tridiagonal(off: np.ndarray, diag: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve a symmetric tridiagonal system (``off`` ``[F-1]``, ``diag`` ``[F]``) for ``rhs`` ``[F, K]``."""
    d, r = diag.astype(np.float64).copy(), rhs.astype(np.float64).copy()
    for i in range(1, len(d)):
        k = off[i - 1] / d[i - 1]
        d[i] -= k * off[i - 1]
        r[i] -= k * r[i - 1]
    r[-1] /= d[-1]
    for i in range(len(d) - 2, -1, -1):
        r[i] = (r[i] - off[i] * r[i + 1]) / d[i]
    return r


def on_learnt_body(engine, positions: np.ndarray):
    """(``positions`` ``[F, 21, 3]`` on the body ``engine``'s model learnt, a function that puts frames back on
    the clip's own body). A model reads a body of other proportions (a rig whose spine and legs a bone map
    reads otherwise) as another way of moving: a walk on a generated Rigify rig, read as it is, slowed to a
    third of its pace within seconds. The same motion on the model's body (:func:`features.learnt_body`:
    its bone lengths, the clip's bone directions and hips; :func:`features.with_bone_lengths`) walks on, and comes
    back on the clip's body with its pelvis and chest turned whole (:func:`features.on_body_of`: a rig's solve keeps
    them; a generated Rigify rig's thighs sit 7 cm above its hips joint, where the learnt body's sit 4 cm below, and
    given back its bone lengths alone the whole leg came out 11 cm high, the feet 6 cm over the floor; an MMD model's
    arms, whose shoulders hang high and wide of its neck, up to 3.8 cm from the continuation's). A body within
    :data:`LEARNT_BODY_TOLERANCE` of one the model learnt (any of its seed windows'), or a model without seeds, reads
    the clip as it is."""
    seeds = getattr(engine, "seeds", None)
    bodies, body = learnt_bodies(seeds), learnt_body(seeds)
    positions = np.asarray(positions)
    own = body_lengths(positions)
    if body is None or (np.abs(bodies - own).sum(1) <= LEARNT_BODY_TOLERANCE * bodies.sum(1)).any():
        return positions, lambda frames: frames
    dtype = positions.dtype

    def back(frames: np.ndarray) -> np.ndarray:
        return on_body_of(with_bone_lengths(frames, own), positions[-1]).astype(np.asarray(frames).dtype)

    return with_bone_lengths(positions, body).astype(dtype), back


def bone_lengths(feats: np.ndarray) -> np.ndarray:
    """Median bone lengths ``[B, J]`` (0 for the root) of raw features ``[B, T, C]`` (:func:`features.body_lengths`)."""
    return body_lengths(feats[..., LAYOUT.positions].reshape(*feats.shape[:-1], -1, 3))


def _chain_matrices() -> tuple[np.ndarray, np.ndarray]:
    """``bone [J-1, J]``: joint positions -> bone vectors (joint j minus its parent, row j-1);
    ``chain [J, J-1]``: bone vectors -> joint offsets from the root (the bones from the root to j)."""
    j = len(PARENTS)
    bone = np.zeros((j - 1, j), np.float32)
    bone[np.arange(j - 1), np.arange(1, j)] = 1.0
    bone[np.arange(j - 1), PARENTS[1:]] -= 1.0
    chain = np.zeros((j, j - 1), np.float32)
    for joint in range(1, j):
        k = joint
        while k > 0:
            chain[joint, k - 1] = 1.0
            k = PARENTS[k]
    return bone, chain


_BONE, _CHAIN = _chain_matrices()


def project_to_skeleton(feats: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """Put raw features ``[B, T, C]`` back on bones of ``lengths`` ``[B, J]`` (directions kept,
    the root where it was) and round the contacts. Two small matmuls instead of a loop over joints."""
    out = feats.copy()
    local = feats[..., LAYOUT.positions].reshape(*feats.shape[:-1], -1, 3)
    d = np.tensordot(local, _BONE, axes=([-2], [1]))  # bone vectors (B, T, 3, J-1)
    norm = np.sqrt(np.einsum("...dj,...dj->...j", d, d))[..., None, :]
    d *= lengths[:, None, None, 1:] / np.maximum(norm, 1e-8)
    fixed = local[..., :1, :] + np.tensordot(d, _CHAIN, axes=([-1], [1])).swapaxes(-1, -2)  # (B, T, J, 3)
    out[..., LAYOUT.positions] = fixed.reshape(*feats.shape[:-1], -1)
    out[..., LAYOUT.contacts] = np.round(np.clip(out[..., LAYOUT.contacts], 0, 1))
    return out
