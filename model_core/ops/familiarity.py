"""How familiar a clip is to the model: how well it reconstructs the clip's own frames.

The model's decoder rebuilds each 20-frame window it reads. On motion like its training data it
does so closely; on motion it never learnt (another style, an action it never saw) the error
grows, and so does the risk that a continuation drifts away from the clip. The error is judged
against the model's own usual error, measured on held-back takes and kept in its model.json
(``familiarity.reconstruction_cm_p90``: 90 % of such windows reconstruct better), so the
operators can say when to trust a result less: a clip that rebuilds more than ``UNFAMILIAR_RATIO`` times
worse than that is called unfamiliar.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..motion.conventions import LAYOUT, MODEL_FPS
from ..motion.features import positions_to_features
from .normalise import fit_normalisation, model_frames_available, sample_at

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
        if not self.unfamiliar:
            return ""
        return (f"This motion is unlike what the model learnt (it rebuilds it {self.ratio:.1f} x worse than 90 % of "
                f"the motion it knows): the result may drift from the clip's style, so check it")


def reconstruction_cm(engine, pos: np.ndarray, stride: int | None = None) -> np.ndarray:
    """Per-window reconstruction error (cm, root-local joints) of positions ``[F, 21, 3]`` (model
    units and rate, F >= m): each ``m``-frame window through the model and back."""
    feats, _ = positions_to_features(pos)
    m = engine.m
    starts = sorted(set(range(0, len(feats) - m + 1, stride or m // 2)) | {len(feats) - m})
    windows = np.stack([feats[s:s + m] for s in starts])
    decoded = engine.forward(windows)[:, :m]
    local = (decoded - windows)[..., LAYOUT.positions].reshape(len(windows), m, -1, 3)
    return 100.0 * np.linalg.norm(local, axis=-1).mean((1, 2))


def assess(engine, pos: np.ndarray) -> Familiarity:
    """:class:`Familiarity` of positions ``[F, 21, 3]`` (model units and rate) to ``engine``'s model."""
    usual = engine.ckpt.meta.get(KEY, {}).get("reconstruction_cm_p90")
    return Familiarity(float(reconstruction_cm(engine, pos).mean()), usual)


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
