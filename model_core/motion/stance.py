"""Root steps that keep planted feet where they are, and rollouts whose stances stand still.

A foot that is down should not move over the ground. In raw features (:data:`conventions.LAYOUT`) a heel or toe
at ground position ``L_t`` in frame ``t``'s root frame stays put from frame ``t`` to ``t + 1`` when the root steps
``L_t - R(yaw rate_t) L_{t+1}`` (expressed in frame ``t``'s root frame, as the velocity channels are).
:func:`planted_steps` solves that, weighted by the contact channels, against a step the caller trusts otherwise
(the path's, Follow Curve; the model's own, :func:`settle_stances`).

:func:`settle_stances` is for open-loop rollouts: window after window, a rollout of motion the model no longer
follows settles into an idle stance, and the model's root keeps the pace it had, so that the stance glides over
the floor with both feet down (0.23 m/s on the test split's standing seeds, model card "A stance stands"). In the
rollout's later windows where every heel and toe is down almost throughout, the root steps are the planted
feet's. The features fed back to the model are not changed (taking the planted steps inside the loop stopped
walks and runs too): only what comes out.

:func:`ground` keeps a rollout's feet out of the floor the clip stood on. The model places the hips for the bodies
it learnt, and a rollout put back on another body's bones sinks window after window: the unseen subject's lowest
heel or toe went 5.4 to 6.4 cm under its floor (model card, "Feet out of the floor"). Each frame that would go
under is lifted, the lift eased over a few frames; nothing is pushed down (a hop stays a hop), and again only
what comes out changes (lifting the windows fed back slowed the rollouts). Like the stances, the first two windows
are not lifted (they continue the clip, and lifting them cost martial arts 0.4 cm at 400 ms: its fighters' predicted
feet dip under the floor where the hips are right); the lift eases in over the third window. Their feet are kept
out of the floor by the legs alone (:func:`ops.footlock.legs_out_of_floor`, :meth:`Engine.ground`).
"""

from __future__ import annotations

import numpy as np

from .conventions import CONTACT_JOINTS, LAYOUT
from .geometry import rotate_ground

PLANT_TRUST = 0.25  # weight of the trusted step against a planted heel's or toe's (weight 1) in planted_steps
# settle_stances: a window is a stance when every heel and toe is down (contact over 0.5) in at least this share of
# its frames, and windows from SETTLE_FROM on (the first two continue the clip, where the model's own steps carry
# its momentum: a performer about to walk off). Chosen on the held-out groups (model card, "A stance stands").
STANCE_SHARE, SETTLE_FROM = 0.9, 2
# ground: the lift needed at each frame is held over this many frames either side and averaged over as many, so
# that it eases in and out (chosen on the held-out groups against 0 and 4: model card, "Feet out of the floor").
GROUND_EASE = 2


def planted_steps(window: np.ndarray, control: np.ndarray, trust: float = PLANT_TRUST) -> np.ndarray:
    """Root steps ``[n, 2]`` (ground velocity in each frame's root frame, metres per frame) for raw features
    ``[n, C]`` (yaw rates already set) that keep its contact feet where they are from each frame to the next
    and otherwise follow the ``control`` steps ``[n, 2]``: per frame, the least-squares step between the
    step each heel and toe would need to stay planted, weighted by the window's contact channels, and the control's
    step, weighted by ``trust``. The last frame's next is not known yet: it repeats the step before it (the
    control's step there would be a jump in the stride's pace that a caller scaling the steps to a pace then
    scales with the rest, a pop of the hips at every window's seam)."""
    n = len(window)
    steps = np.array(control, np.float64)
    if n < 2:
        return steps
    local = window[:, LAYOUT.positions].reshape(n, -1, 3)[:, CONTACT_JOINTS][..., [0, 2]]  # (n, 4, 2)
    planted = local[:-1] - rotate_ground(window[:-1, LAYOUT.yaw_rate][:, None], local[1:])  # (n - 1, 4, 2)
    weight = np.clip(window[:-1, LAYOUT.contacts], 0.0, 1.0)[..., None]  # (n - 1, 4, 1)
    steps[:-1] = ((weight * planted).sum(1) + trust * steps[:-1]) / (weight.sum(1) + trust)
    steps[-1] = steps[-2]
    return steps


def settle_stances(feats: np.ndarray, n: int, first: int = SETTLE_FROM, share: float = STANCE_SHARE) -> np.ndarray:
    """A rollout's raw features ``[F, C]`` or ``[B, F, C]`` (its windows of ``n`` frames from the first) with the
    root steps of each window from ``first`` on that is a stance (every heel and toe down in ``share`` of its
    frames) taken from its planted feet (:func:`planted_steps`, the model's own step trusted as ever): a stance
    stands where it is instead of gliding. Other windows, and every other channel, are as they were."""
    feats = np.asarray(feats)
    single = feats.ndim == 2
    out = np.array(feats[None] if single else feats)
    down = (out[..., LAYOUT.contacts] > 0.5).all(-1)  # (B, F)
    for b in range(len(out)):
        for s in range(first * n, out.shape[1], n):
            if down[b, s:s + n].mean() >= share:
                window = out[b, s:s + n]
                window[:, LAYOUT.velocity] = planted_steps(window, window[:, LAYOUT.velocity])
    return out[0] if single else out


def held_and_eased(x: np.ndarray, ease: int) -> np.ndarray:
    """``x`` ``[..., F]`` with each value held for ``ease`` frames either side (a running maximum) and averaged over
    as many, so that a rise is reached and left smoothly and never undercut (at least ``x`` on every frame)."""
    x = np.asarray(x)
    if ease <= 0 or x.shape[-1] < 2:
        return x

    def spread(v, reduce):
        padded = np.pad(v, [(0, 0)] * (v.ndim - 1) + [(ease, ease)], mode="edge")
        return reduce(np.lib.stride_tricks.sliding_window_view(padded, 2 * ease + 1, axis=-1), -1)

    return spread(spread(x, np.max), np.mean)


def lift_needed(lowest: np.ndarray, floor: float | np.ndarray, ease: int = GROUND_EASE) -> np.ndarray:
    """How far ``[B, F]`` each frame must rise for its lowest point ``lowest`` ``[B, F]`` (Y up) not to be under
    ``floor`` (a height, or one per clip ``[B]``; NaN: none), held ``ease`` frames either side and averaged over as
    many (:func:`held_and_eased`), so that a lift eases in and out: :func:`ground`'s, and each leg's in
    :func:`ops.footlock.legs_out_of_floor`."""
    floors = np.broadcast_to(np.asarray(floor, np.float64), (len(lowest),))
    need = np.maximum(0.0, floors[:, None] - lowest)
    need[np.isnan(need)] = 0.0
    return held_and_eased(need, ease)


def ground(pos: np.ndarray, floor: float | np.ndarray, ease: int = GROUND_EASE, start: int = 0,
           ramp: int = 0) -> np.ndarray:
    """Joints ``[F, 21, 3]`` or ``[B, F, 21, 3]`` (Y up) lifted, frame by frame, so that the lowest heel or toe is
    not under ``floor`` (a height, or one per clip ``[B]``; NaN: that clip is left as it is); the lift each frame
    needs is held for ``ease`` frames either side and averaged over as many, so the body rises and settles
    smoothly. Frames above the floor that need no lift stay where they are: nothing is pushed down. Frames before
    ``start`` are left as they are, and the lift grows in over the ``ramp`` frames from it."""
    pos = np.asarray(pos)
    single = pos.ndim == 3
    out = np.array(pos[None] if single else pos)
    lift = lift_needed(out[..., CONTACT_JOINTS, 1].min(-1), floor, ease)  # (B, F)
    lift *= np.clip((np.arange(lift.shape[1]) - start + 1) / (ramp + 1), 0.0, 1.0)
    out[..., 1] += lift[..., None].astype(out.dtype)
    return out[0] if single else out
