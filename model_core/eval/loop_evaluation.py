"""Make Loop's seams (``scripts/evaluate.py --loops``): how smoothly a cycle made from a take repeats.

For each clip that moves over the ground (the hips faster than :data:`LOCOMOTION_SPEED` over the stretch), a stretch
of :data:`STRETCH_S` seconds from its middle is made into a cycle and played :data:`CYCLES` times (the travel added
each time), its seam found where the pose comes round again (``matched``) or at the stretch's last frame
(``forced``, Match the Start off), by:

Every way starts from the stretch as Make Loop turns it (:func:`loop.unwound`: a stretch that turns is unwound so
that the seam faces as the first frame does); they differ in the blend:

- ``none``: the seam as it is;
- ``offset``: the gap at the seam (the next cycle's first pose less the seam's) eased in over the blend;
- ``cross_fade``: the blend's frames cross-faded (smoothstep) into the take's frames that lead into the stretch,
  moved by the travel;
- ``model``: the in-betweener alone (Make Loop where the stretch starts the action);
- ``make_loop``: Make Loop as it makes it (:func:`loop.loop_positions` with the take before the stretch).

Each blend is foot-locked as Make Loop's Foot Lock does (but ``none``). Measured at the model's rate on the standard
body: the largest acceleration of any joint from the blend to just after each seam against the take's own (the 99th
percentile of its per-frame joint accelerations), the body's fastest turn there (its heading's rate) against the
take's own 99th percentile, and the mean foot skate of contacts there (cm a frame). Positions are metres, Y-up, 30
fps.
"""

from __future__ import annotations

import numpy as np

from ..motion.conventions import GROUND_AXES, MODEL_FPS, ROOT
from ..motion.features import heading
from ..ops.footlock import SETTLE_PASSES, FootLockSettings, detect_foot_contacts, foot_lock, foot_skate_cm
from ..ops.loop import BLEND_S, cross_fade, loop_positions, unwound

STRETCH_S = 2.0
CYCLES = 3
LOCOMOTION_SPEED = 0.3  # m/s of the hips over the ground
METHODS = ("none", "offset", "cross_fade", "model", "make_loop")


def _played(cycle: np.ndarray, travel: np.ndarray, times: int = CYCLES) -> np.ndarray:
    """``cycle`` ``[L + 1, J, 3]`` (its seam frame last) played ``times`` times, the travel added each time."""
    return np.concatenate([cycle[:-1] + k * travel for k in range(times)] + [cycle[-1:] + (times - 1) * travel])


def _made(engine, pos: np.ndarray, start: int, span: int, blend: int, match: bool) -> tuple[dict, object]:
    """Each method's cycle of ``pos[start:start + span + 1]``, and the in-betweener's :class:`loop.Loop` (its seam,
    travel and how far the seam's pose was from the first's)."""
    stretch, lead = pos[start:start + span + 1], pos[max(0, start - 20):start]
    alone = loop_positions(engine, stretch, MODEL_FPS, blend, match)
    shipped = loop_positions(engine, stretch, MODEL_FPS, blend, match, lead=lead)
    seam, travel = alone.seam, alone.travel
    stretch = unwound(stretch, seam)[0]  # as Make Loop turns it before its blend: the ways differ in the blend alone
    nxt = stretch[:seam] + travel
    base = np.concatenate([stretch[:seam], nxt[:1]])
    s = np.clip((np.arange(seam + 1) - (seam - blend)) / blend, 0.0, 1.0)
    offset = base + (s * s * (3 - 2 * s))[:, None, None] * (nxt[0] - stretch[seam])
    fade = base.copy()
    fade[seam - blend:seam] = cross_fade(base[seam - blend:seam], pos[start - blend:start] + travel)
    fixed = alone.fixed()  # as Make Loop's Foot Lock: the blend, or a stretch unwound, the whole cycle
    settings = FootLockSettings(passes=SETTLE_PASSES)
    made = {"none": base}
    for name, cycle in (("offset", offset), ("cross_fade", fade), ("model", alone.positions),
                        ("make_loop", shipped.positions)):
        made[name] = foot_lock(cycle, MODEL_FPS, fixed=fixed, settings=settings)
    return made, alone


def evaluate_loops(engine, clips: list, blend_s: float = BLEND_S) -> dict:
    """The seams of cycles made from ``clips`` (``dataset.Clip`` or positions ``[F, 21, 3]``: metres, Y-up, 30
    fps) by each of :data:`METHODS`, matched and forced (see the module): per method the mean and worst peak
    acceleration near the seams against the take's own, how many cycles go over 1.5 x it, and the mean foot skate
    there; per case how far the seam's pose is from the first's on average (``seam_pose_cm``, cm a joint)."""
    blend, span = int(round(blend_s * MODEL_FPS)), int(round(STRETCH_S * MODEL_FPS))
    ground = list(GROUND_AXES)
    out = {"blend_s": blend_s, "stretch_s": STRETCH_S, "cycles": CYCLES}
    for case, match in (("matched", True), ("forced", False)):
        rows, takes, seam_cm, own_skate = {m: [] for m in METHODS}, 0, [], []
        for clip in clips:
            pos = np.asarray(getattr(clip, "positions", clip), np.float64)
            start = (len(pos) - span) // 2
            if start < blend:
                continue
            hips = pos[start:start + span + 1, ROOT][:, ground]
            if np.linalg.norm(np.diff(hips, axis=0), axis=-1).mean() * MODEL_FPS < LOCOMOTION_SPEED:
                continue
            stretch = pos[start:start + span + 1]
            own = np.percentile(np.linalg.norm(np.diff(stretch, 2, axis=0), axis=-1).max(1), 99)
            own_turn = np.percentile(np.abs(np.diff(heading(stretch))), 99)
            own_skate.append(foot_skate_cm(stretch, detect_foot_contacts(stretch, MODEL_FPS)))
            made, loop = _made(engine, pos, start, span, blend, match)
            seam, travel = loop.seam, loop.travel
            takes += 1
            seam_cm.append(loop.match_cm)
            near = np.concatenate([np.arange(k * seam - blend - 3, k * seam + 3) for k in range(1, CYCLES)])
            for name, cycle in made.items():
                p = _played(cycle, travel)
                acc = np.linalg.norm(np.diff(p, 2, axis=0), axis=-1).max(1)
                lo, hi = seam - blend, (CYCLES - 1) * seam + 1
                skate = foot_skate_cm(p[lo:hi], detect_foot_contacts(p[lo:hi], MODEL_FPS))
                whole = foot_skate_cm(p[:seam + 1], detect_foot_contacts(p[:seam + 1], MODEL_FPS))
                turning = np.abs(np.diff(heading(p)))[near].max() / max(own_turn, 1e-9)
                rows[name].append((acc[near].max() / own, skate, turning, whole))
        out[case] = {"takes": takes, "seam_pose_cm": float(np.mean(seam_cm)) if takes else float("nan"), **{name: {
            "peak_accel_ratio_mean": float(np.mean([r[0] for r in rows[name]])) if takes else float("nan"),
            "peak_accel_ratio_worst": float(np.max([r[0] for r in rows[name]])) if takes else float("nan"),
            "over_1_5": int(sum(r[0] > 1.5 for r in rows[name])),
            "skate_cm": float(np.mean([r[1] for r in rows[name]])) if takes else float("nan"),
            "turn_rate_ratio_mean": float(np.mean([r[2] for r in rows[name]])) if takes else float("nan"),
            "turn_rate_over_1_5": int(sum(r[2] > 1.5 for r in rows[name])),
            "skate_cycle_cm": float(np.mean([r[3] for r in rows[name]])) if takes else float("nan")}
            for name in METHODS}}
        out[case]["take_skate_cm"] = float(np.mean(own_skate)) if takes else float("nan")
    return out
