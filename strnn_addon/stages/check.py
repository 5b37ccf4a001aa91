"""Check Motion: how familiar an armature's motion is to the model, before any operation runs on it.

The judgement is Extend's report's (``familiarity.clip_familiarity``: how well the model rebuilds the motion, against
the motion it knows), made on the last :data:`CHECK_S` seconds of the action instead of the context Extend reads,
with the operators' other warnings about the take itself (strides at a pace people do not walk: keys at another rate
than the take's; a body lying along another axis than up); it changes nothing in the file. The batch's ``inspect``
says the same for each take of a file.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...model_core.ops.familiarity import Familiarity
from .. import engine_bridge
from ..scene import pipeline
from .common import model_call, pace_record, prefs

CHECK_S = 10.0  # the last this many seconds of the action are judged


@dataclass(frozen=True)
class Checked:
    """What Check Motion found: the model's judgement of the action's frames ``first`` to ``last``."""

    found: Familiarity
    first: int
    last: int
    notes: tuple[str, ...] = ()  # what else the operators' reports would warn of: the keys' rate, the body's axis
    suggested_rate: float | None = None  # the Keys per Second the pace's note suggests

    @property
    def unfamiliar(self) -> bool:
        return self.found.unfamiliar

    @property
    def warns(self) -> bool:
        """Whether the report is a warning: the motion is unfamiliar, or another note says what to fix first."""
        return self.unfamiliar or bool(self.notes)

    def message(self) -> str:
        """What was found, as the batch's ``inspect`` says it (:meth:`report`, the operator's): the familiarity, then
        the other notes."""
        return "; ".join((self._familiarity(), *self.notes))

    def _familiarity(self) -> str:
        ratio = self.found.ratio
        if ratio is None:
            return (f"the model rebuilds this motion within {self.found.error_cm:.1f} cm (its model folder carries "
                    "no calibration to judge that by)")
        if self.unfamiliar:
            return (f"this motion is unlike what the model learnt (it rebuilds it {ratio:.1f} x worse than 90 % of "
                    "the motion it knows): Extend, Fill Gap and Denoise may drift from its style, so check what they "
                    "make of it")
        return (f"motion the model knows (its rebuild error is {ratio:.1f} x the one 90 % of the motion it knows "
                "stays under)")

    def report(self, action_name: str) -> str:
        """The operator's report: the action and the frames judged, then :meth:`message`."""
        return f"{action_name!r}, frames {self.first}-{self.last}: {self.message()}"


def check_motion(context, obj) -> Checked:
    """Judge the motion of ``obj``'s action (its last :data:`CHECK_S` seconds); raises
    :class:`pipeline.UserError` where the operations could not take it (the rig does not map, the action is shorter
    than the model reads...)."""
    clip = pipeline.prepare(context, obj)
    need = pipeline.min_scene_frames(clip.fps)
    if clip.last - clip.first + 1 < need:
        raise pipeline.UserError(
            f"The action {clip.action.name!r} has {clip.last - clip.first + 1} frames; judging its motion needs at "
            f"least {need} at {clip.fps:g} fps (the model reads {pipeline.MIN_MODEL_FRAMES} frames at 30 fps): "
            "use a longer action")
    first = max(clip.first, clip.last - round(CHECK_S * clip.fps))
    positions = pipeline.joint_positions(context, clip, np.arange(first, clip.last + 1))
    found = model_call(engine_bridge.run_familiarity, prefs(context), positions, clip.fps)
    record = pace_record(context, clip)  # the strides' pace at the keys' rate, and the axis the body stands along
    notes = tuple(entry["note"] for entry in record.values() if entry.get("note"))
    return Checked(found, first, clip.last, notes, record.get("pace", {}).get("suggested_keys_per_second"))
