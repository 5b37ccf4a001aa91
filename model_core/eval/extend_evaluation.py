"""Long extensions as Extend Clip makes them (``scripts/evaluate.py --long-extend``).

Each clip's first :data:`TAKE_S` seconds are extended by :data:`EXTEND_S` seconds with
:func:`extend.extend_positions`, once following the clip (the clip as the memory Extend Clip reads,
:class:`inference.memory.ClipMemory`) and once with the model alone; the last :data:`LAST_S` seconds are
measured against the take: joint speed (joints relative to the hips), the share of frames with both feet
more than 5 cm off the take's floor, and how far the feet swing past each other along the way walked (the
standard deviation of the left foot's lead over the right). A take *walks* when its feet swing 10 cm or more;
a continuation of one *steps* when its feet swing at least 0.4 x as far as the take's, it moves at 0.4 x the
take's speed or more, and it is not *hopping* (both feet off the floor in more than 3 % of the frames where the
take is not). Positions are metres, Y-up, 30 fps.
"""

from __future__ import annotations

import numpy as np

from ..motion.conventions import GROUND_AXES, JOINT_INDEX, MODEL_FPS
from ..motion.features import floor_height
from ..ops.extend import extend_positions
from .metrics import airborne_fraction

TAKE_S, EXTEND_S, LAST_S = 10.0, 20.0, 5.0
CONTEXT = 20  # the frames the model reads; the rest of the take is what Extend follows
HOP_SHARE = 0.03  # both feet off the floor (metrics.airborne_fraction) in more of the frames than this: a hop
STEP_SHARE, SLOW, WALKING_M = 0.4, 0.4, 0.1
SETTINGS = ("follow", "alone")


def limb_speed(pos: np.ndarray) -> float:
    """Mean speed of the joints relative to the hips (m per frame) of ``[F, 21, 3]``."""
    return float(np.linalg.norm(np.diff(pos - pos[:, :1], axis=0), axis=-1).mean())


def feet_lead(pos: np.ndarray) -> float:
    """How far the feet swing past each other along the way walked (m, the sd of the left foot's lead)."""
    ground = list(GROUND_AXES)
    way = pos[-1, 0, ground] - pos[0, 0, ground]
    way = way / (np.linalg.norm(way) + 1e-9)
    lead = (pos[:, JOINT_INDEX["l_foot"]][:, ground] - pos[:, JOINT_INDEX["r_foot"]][:, ground]) @ way
    return float(lead.std())


def evaluate_long_extend(engine, clips, count: int = 20) -> dict:
    """Figures over up to ``count`` clips (evenly spread) long enough for the model to follow (its context and
    a window more)."""
    usable = sorted((c for c in clips if len(c.positions) >= CONTEXT + 2 * 20), key=lambda c: c.name)
    picks = [usable[i] for i in np.linspace(0, len(usable) - 1, min(count, len(usable))).round().astype(int)] \
        if usable else []
    out = {"take_s": TAKE_S, "extend_s": EXTEND_S, "last_s": LAST_S, "clips": [c.name for c in picks],
           "take_airborne_fraction": [], "take_feet_lead_m": []}
    for key in SETTINGS:
        out[key] = {"speed_ratio": [], "airborne_fraction": [], "feet_lead_ratio": []}
    last, frames = int(LAST_S * MODEL_FPS), int(EXTEND_S * MODEL_FPS)
    for clip in picks:
        take = np.asarray(clip.positions[:int(TAKE_S * MODEL_FPS)], np.float64)
        floor = floor_height(take)
        lead = feet_lead(take[-last:])
        out["take_airborne_fraction"].append(airborne_fraction(take, floor))
        out["take_feet_lead_m"].append(lead)
        for key in SETTINGS:
            new = extend_positions(engine, take[-CONTEXT:], MODEL_FPS, frames,
                                   memory=take if key == "follow" else None)[-last:]
            out[key]["speed_ratio"].append(limb_speed(new) / limb_speed(take))
            out[key]["airborne_fraction"].append(airborne_fraction(new, floor))
            out[key]["feet_lead_ratio"].append(feet_lead(new) / max(lead, 1e-3))
    take_air = np.array(out["take_airborne_fraction"])
    walking = np.array(out["take_feet_lead_m"]) >= WALKING_M
    out["walking_takes"] = int(walking.sum())
    for key in SETTINGS:
        r = {k: np.array(v) for k, v in out[key].items()}
        hop = (r["airborne_fraction"] > HOP_SHARE) & (take_air <= HOP_SHARE)
        out[key]["slowed"] = int((r["speed_ratio"] < SLOW).sum())
        out[key]["hopping"] = int(hop.sum())
        out[key]["stepping"] = int((walking & (r["feet_lead_ratio"] >= STEP_SHARE) & (r["speed_ratio"] >= SLOW)
                                    & ~hop).sum())
    return out
