"""How familiar a clip is to the model: how well it reconstructs the clip's own frames.

The model's decoder rebuilds each 20-frame window it reads. On motion like its training data it
does so closely; on motion it never learnt (another style, an action it never saw) the error
grows, and so does the risk that a continuation drifts away from the clip. The error is judged
against the model's own usual error, measured on held-back takes and kept in its model.json
(``familiarity.reconstruction_cm_p90``: 90 % of such windows reconstruct better), so the
operators can say when to trust a result less: a clip that rebuilds more than ``UNFAMILIAR_RATIO`` times
worse than that is called unfamiliar. Extend and Fill Gap also let an unfamiliar context's momentum carry
on into the new frames (:func:`momentum_shares`, :func:`seam.blend_seam`).

It is the motion that is judged, not the body: a clip is first moved onto the model's own body
(:func:`on_model_body`: the bone lengths of the training takes, the clip's bone directions), so that a
familiar walk on a rig of other proportions (a generated Rigify rig reads its spine and legs quite
differently) reads as familiar.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..motion.conventions import LAYOUT, MODEL_FPS
from ..motion.features import learnt_seed, positions_to_features
from .normalise import fit_normalisation, model_frames_available, sample_at
from .seam import momentum_share
from .transfer import retarget

KEY = "familiarity"
# A clip reads as unfamiliar when it rebuilds this many times worse than the 90th percentile. Chosen with
# a model trained without the held-out groups (model card, "Familiarity"): their clips' median errors were
# 0.7 x (another style: familiar), 1.4 x (an unseen CMU subject) and 2.2 x (an unseen action family), and
# the first seconds of test takes (starts, a fall) ranged 0.4 to 1.9 x but for one fall.
UNFAMILIAR_RATIO = 1.25


@dataclass(frozen=True)
class Familiarity:
    error_cm: float  # mean reconstruction error of the clip's windows
    usual_cm: float | None  # 90 % of the model's held-back windows reconstruct better than this

    @property
    def ratio(self) -> float | None:
        return self.error_cm / self.usual_cm if self.usual_cm else None

    @property
    def unfamiliar(self) -> bool:
        return self.ratio is not None and self.ratio > UNFAMILIAR_RATIO

    def note(self) -> str:
        """A sentence for an operator's report; empty when the clip is familiar."""
        return self._said("This motion", "the result may drift from the clip's style, so check it")

    def denoised_note(self) -> str:
        """:meth:`note` for Denoise, which judges its result (:func:`denoise.result_familiarity`)."""
        return self._said("The denoised motion", "the take is motion it does not know, or noise is left, so compare "
                          "the result with the original action (kept) and lower Strength where the style changed")

    def _said(self, what: str, meaning: str) -> str:
        if not self.unfamiliar:
            return ""
        return (f"{what} is unlike what the model learnt (it rebuilds it {self.ratio:.1f} x worse than 90 % of the "
                f"motion it knows): {meaning}")


def model_body(engine) -> np.ndarray | None:
    """The body the model learnt, ``[21, 3]`` (model units): the first frame of the release's seed window whose
    bone lengths are nearest the seeds' median (seeds are training windows); None for a release without seeds."""
    seeds = getattr(engine, "seeds", None)
    k = learnt_seed(seeds)
    return None if k is None else np.asarray(seeds[k][0, LAYOUT.positions], np.float64).reshape(-1, 3)


def on_model_body(engine, pos: np.ndarray) -> np.ndarray:
    """Positions ``[F, 21, 3]`` (model units) moved onto :func:`model_body` (:func:`transfer.retarget`: its bone
    lengths, ``pos``'s bone directions and path), so that familiarity judges the motion, not the proportions."""
    body = model_body(engine)
    return np.asarray(pos) if body is None else retarget(pos, body).astype(np.float32)


def reconstruction_cm(engine, pos: np.ndarray, stride: int | None = None) -> np.ndarray:
    """Per-window reconstruction error (cm, root-local joints) of positions ``[F, 21, 3]`` (model
    units and rate, F >= m), on the model's own body (:func:`on_model_body`): each ``m``-frame window
    through the model and back."""
    feats, _ = positions_to_features(on_model_body(engine, pos))
    m = engine.m
    starts = sorted(set(range(0, len(feats) - m + 1, stride or m // 2)) | {len(feats) - m})
    return _window_errors_cm(engine, np.stack([feats[s:s + m] for s in starts]))


def _window_errors_cm(engine, windows: np.ndarray) -> np.ndarray:
    r = getattr(engine, "r", engine.m)  # the window's last frames the model reconstructs
    decoded = engine.forward(windows)[:, :r]
    local = (decoded - windows[:, -r:])[..., LAYOUT.positions].reshape(len(windows), r, -1, 3)
    return 100.0 * np.linalg.norm(local, axis=-1).mean((1, 2))


def usual_cm(engine) -> float | None:
    """The model's usual reconstruction error (its calibration's 90th percentile), None without one."""
    meta = getattr(getattr(engine, "ckpt", None), "meta", None) or {}
    return meta.get(KEY, {}).get("reconstruction_cm_p90")


def context_ratios(engine, contexts: np.ndarray) -> np.ndarray | None:
    """Familiarity ratio (reconstruction error over the usual) of the last ``m`` frames of each context
    ``[W, C, 21, 3]`` (model units and rate, C >= m), in one batch; None for a model without calibration."""
    usual = usual_cm(engine)
    if not usual or np.shape(contexts)[1] < engine.m:
        return None
    windows = np.stack([positions_to_features(on_model_body(engine, np.asarray(c)[-engine.m:]))[0] for c in contexts])
    return _window_errors_cm(engine, windows) / usual


def momentum_shares(engine, contexts: np.ndarray) -> list[float]:
    """How much of its clip's momentum the continuation of each context ``[W, C, 21, 3]`` (model units and
    rate) keeps (:func:`seam.momentum_share`): none where the model knows the motion, or has no calibration."""
    ratios = context_ratios(engine, contexts)
    return [0.0] * len(contexts) if ratios is None else [momentum_share(float(r)) for r in ratios]


def assess(engine, pos: np.ndarray) -> Familiarity:
    """:class:`Familiarity` of positions ``[F, 21, 3]`` (model units and rate) to ``engine``'s model."""
    return Familiarity(float(reconstruction_cm(engine, pos).mean()), usual_cm(engine))


def calibrate(engine, clips: list[np.ndarray]) -> dict:
    """The :data:`KEY` record of a model from held-back clips ``[F, 21, 3]`` (model units and rate)."""
    errors = np.concatenate([reconstruction_cm(engine, c) for c in clips if len(c) >= engine.m])
    return {"reconstruction_cm_p50": round(float(np.percentile(errors, 50)), 3),
            "reconstruction_cm_p90": round(float(np.percentile(errors, 90)), 3), "windows": int(len(errors))}


def clip_familiarity(engine, pos: np.ndarray, fps: float) -> Familiarity:
    """How familiar a clip ``[F, 21, 3]`` (Y-up, scene units, ``fps``; at least the model's context)
    is to the model (:mod:`familiarity`), read at the model's rate and scale as Extend reads it."""
    n = model_frames_available(len(pos), fps)
    clip = sample_at(pos, fps, (len(pos) - 1) / fps - np.arange(n)[::-1] / MODEL_FPS)
    return assess(engine, fit_normalisation(clip).to_model(clip))
