"""The one place that states the conventions every other module takes from.

Glossary
--------
- Axes: model_core is **Y-up**, metres, right-handed (BVH's own convention).
  Conversion to Blender's Z-up happens only at the Blender boundary
  (`strnn_addon`), through :func:`yup_to_zup` / :func:`zup_to_yup`.
- Motion: ``float32 [frames, joints, 3]`` global joint positions in metres.
- Quaternions: ``[..., 4]`` in (w, x, y, z) order, Blender's order.
- Frame rate: the model runs at :data:`MODEL_FPS`; every clip is resampled to it.
- Canonical skeleton: the 21 joints of :data:`JOINTS`, parents in :data:`PARENTS`.
- Features: one frame is a vector laid out as :data:`LAYOUT` describes
  (root-local joint positions, root ground velocity, yaw rate, foot contacts).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

MODEL_FPS = 30.0
MIN_MODEL_FRAMES = 20  # the context every operation reads, in model frames


def min_scene_frames(fps: float) -> int:
    """Frames at ``fps`` needed to span :data:`MIN_MODEL_FRAMES` frames at the model's rate."""
    return max(MIN_MODEL_FRAMES, int(math.ceil((MIN_MODEL_FRAMES - 1) * fps / MODEL_FPS - 1e-6)) + 1)
UP_AXIS = 1  # Y is up in model_core
GROUND_AXES = (0, 2)  # X and Z span the ground plane

# Standard leg length (hip joint to ankle, metres) every skeleton is scaled to,
# so that units (cm, CMU units, metres) and body sizes agree across data sets.
STANDARD_LEG_LENGTH = 0.87

JOINTS: tuple[str, ...] = (
    "hips", "spine", "spine1", "neck", "head",
    "l_upleg", "l_knee", "l_foot", "l_toe",
    "r_upleg", "r_knee", "r_foot", "r_toe",
    "l_arm", "l_elbow", "l_wrist", "l_fingertip",
    "r_arm", "r_elbow", "r_wrist", "r_fingertip",
)
PARENT_NAMES: dict[str, str | None] = {
    "hips": None, "spine": "hips", "spine1": "spine", "neck": "spine1", "head": "neck",
    "l_upleg": "hips", "l_knee": "l_upleg", "l_foot": "l_knee", "l_toe": "l_foot",
    "r_upleg": "hips", "r_knee": "r_upleg", "r_foot": "r_knee", "r_toe": "r_foot",
    "l_arm": "spine1", "l_elbow": "l_arm", "l_wrist": "l_elbow", "l_fingertip": "l_wrist",
    "r_arm": "spine1", "r_elbow": "r_arm", "r_wrist": "r_elbow", "r_fingertip": "r_wrist",
}
NUM_JOINTS = len(JOINTS)
JOINT_INDEX = {name: i for i, name in enumerate(JOINTS)}
PARENTS = np.array([-1 if PARENT_NAMES[j] is None else JOINT_INDEX[PARENT_NAMES[j]] for j in JOINTS])
ROOT = JOINT_INDEX["hips"]

# Foot contact channels: (name, joint). Heel contact is read at the ankle joint.
CONTACTS: tuple[tuple[str, str], ...] = (
    ("l_heel", "l_foot"), ("l_toe", "l_toe"), ("r_heel", "r_foot"), ("r_toe", "r_toe"),
)
CONTACT_JOINTS = np.array([JOINT_INDEX[j] for _, j in CONTACTS])

# Body groups of the spatial encoder (DESIGN.md).
BODY_GROUPS: dict[str, tuple[str, ...]] = {
    "torso": ("spine", "spine1", "neck", "head"),
    "l_arm": ("l_arm", "l_elbow", "l_wrist", "l_fingertip"),
    "r_arm": ("r_arm", "r_elbow", "r_wrist", "r_fingertip"),
    "l_leg": ("l_upleg", "l_knee", "l_foot", "l_toe"),
    "r_leg": ("r_upleg", "r_knee", "r_foot", "r_toe"),
}
LIMBS = ("l_arm", "r_arm", "l_leg", "r_leg")


@dataclass(frozen=True)
class FeatureLayout:
    """Channel layout of one feature frame.

    ``[0, 3J)``      root-local joint positions (x, y, z per joint, metres)
    ``[3J, 3J+2)``   root ground velocity in the root's local frame (m / frame)
    ``3J+2``         root yaw rate about +Y (radians / frame)
    ``[3J+3, 3J+7)`` foot contacts (0 or 1) in :data:`CONTACTS` order
    """

    joints: int = NUM_JOINTS

    @property
    def positions(self) -> slice:
        return slice(0, 3 * self.joints)

    @property
    def velocity(self) -> slice:
        return slice(3 * self.joints, 3 * self.joints + 2)

    @property
    def yaw_rate(self) -> int:
        return 3 * self.joints + 2

    @property
    def root(self) -> slice:
        """Velocity and yaw rate together (the root group)."""
        return slice(3 * self.joints, 3 * self.joints + 3)

    @property
    def contacts(self) -> slice:
        return slice(3 * self.joints + 3, 3 * self.joints + 3 + len(CONTACTS))

    @property
    def size(self) -> int:
        return 3 * self.joints + 3 + len(CONTACTS)

    def joint_channels(self, names: tuple[str, ...]) -> np.ndarray:
        """Feature indices of the x, y, z channels of the named joints."""
        idx = [3 * JOINT_INDEX[n] + k for n in names for k in range(3)]
        return np.array(idx, dtype=np.int64)


LAYOUT = FeatureLayout()


def yup_to_zup(p: np.ndarray) -> np.ndarray:
    """Y-up (x, y, z) -> Blender Z-up (x, -z, y). Shape ``[..., 3]``."""
    return np.stack([p[..., 0], -p[..., 2], p[..., 1]], axis=-1)


def zup_to_yup(p: np.ndarray) -> np.ndarray:
    """Blender Z-up (x, y, z) -> Y-up (x, z, -y). Shape ``[..., 3]``."""
    return np.stack([p[..., 0], p[..., 2], -p[..., 1]], axis=-1)


def group_channels() -> dict[str, list[int]]:
    """Feature channels of each spatial-encoder group: the body groups, ``root``
    (hips position + root motion) and ``contacts``."""
    groups = {name: LAYOUT.joint_channels(joints).tolist() for name, joints in BODY_GROUPS.items()}
    groups["root"] = LAYOUT.joint_channels(("hips",)).tolist() + list(range(LAYOUT.root.start, LAYOUT.root.stop))
    groups["contacts"] = list(range(LAYOUT.contacts.start, LAYOUT.contacts.stop))
    return groups
