"""The editing operations' options, each declared once: its label, default, limits and description.

The Blender operators build their properties from these (``strnn_addon/props.py``; the sidebar shows
the operators' own remembered values) and the batch CLI its arguments (``scripts/strnn_batch.py``), so
a name, default or limit never differs between them. Plain data: no bpy here.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass


@dataclass(frozen=True)
class Option:
    name: str  # the label in Blender
    default: float | int | bool
    description: str
    min: float | None = None
    max: float | None = None
    soft_max: float | None = None

    def blender(self) -> dict:
        """Keyword arguments for a ``bpy.props`` property."""
        return {k: v for k, v in asdict(self).items() if v is not None}

    def help(self, unit: str = "") -> str:
        """The text of a command-line argument: the description and the default."""
        return f"{self.description} (default: {self.default:g}{unit})" if not isinstance(self.default, bool) \
            else self.description


EXTEND_FRAMES = Option("Frames", 120, "How many frames to add after the last frame (before the first, with Before "
                       "the Start)", min=1, soft_max=2000)
CONTEXT_FRAMES = Option("Context", 0, "Frames before the end the model reads; 0: just enough (20 at 30 fps)",
                        min=0, soft_max=600)
FOLLOW_CLIP = Option("Follow the Clip", True,
                     "Lean on the clip's own motion wherever the continuation comes back to something the clip did "
                     "(a walk keeps its gait; from the first frame where the model does not know the motion); off: "
                     "the model alone")
BEFORE_START = Option("Before the Start", False,
                      "Add the frames before the action's first frame (before the current frame, with From Current "
                      "Frame) instead of after its last: a lead-in, or a simulation's pre-roll; the clip is read "
                      "backwards in time")
FOLLOW_TAKE = Option("Follow the Take", True,
                     "Lean on the rest of the action where it did what the gap must (a walk's other steps, a "
                     "drill's repeated kick), up to 20 s either side; off: the models alone")
STRENGTH = Option("Strength", 1.0, "Blend between the original (0) and the model's output (1)", min=0.0, max=1.0)
LOCK_BLEND = Option("Blend", 0.15, "Seconds over which each lock fades in before a contact and out after it",
                    min=0.0, max=2.0, soft_max=0.5)
CURVE_FRAMES = Option("Frames", 0, "How many frames to make; 0: until the curve ends (one lap if cyclic)",
                      min=0, soft_max=5000)
CURVE_SPEED = Option("Speed", 0.0, "Walking speed along the curve; 0: the motion's own speed", min=0.0,
                     soft_max=5.0)

LOOP_BLEND = Option("Blend", 0.4, "Seconds before the seam made again by the model, so the cycle flows on into its "
                    "start; 0: the seam as it is", min=0.0, max=4.0, soft_max=1.0)
LOOP_MATCH = Option("Match the Start", True,
                    "End the cycle where the pose comes round to the first frame's again (the best match in the "
                    "range's second half); off: the range's last frame starts the next cycle")
LOOP_IN_PLACE = Option("In Place", False,
                       "Take the travel off, so the cycle repeats on the spot with its sway kept (as game engines "
                       "take root motion apart); off: each cycle walks on from where the last ended")
ROOT_MOTION = Option("Root Motion", False,
                     "Key the travel and the heading on the bone above the hips (a game rig's root, as Unreal's "
                     "root), on the floor under the body, the hips moving against it, as game engines take root "
                     "motion; off: the hips carry the travel")

# Whether each operation locks the feet unless told otherwise (Foot Lock's own operator always does).
FOOT_LOCK = {"extend_clip": False, "denoise_action": False, "inbetween": True, "follow_curve": True,
             "transfer_motion": True, "make_loop": True}
FOOT_LOCK_TIP = "Then pin the feet on the ground while they touch it (leg IK against foot sliding)"
