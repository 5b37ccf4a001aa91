"""Simplify Keys: thin the keys an operation wrote on every frame to those its joints need
(``model_core/rig/simplify.py``), measured on the curves Blender evaluates through the kept keys."""

from __future__ import annotations

import numpy as np

from ...model_core.rig.simplify import refine
from ...model_core.rig.solve import anchor_positions, fk
from . import anim, pipeline, rig_io

ROTATIONS = ("rotation_quaternion", "rotation_euler", "rotation_axis_angle")


class _Channels:
    """The written bones' keyed channels of a clip over some frames, and the joints they pose."""

    def __init__(self, clip: pipeline.Clip, frames: np.ndarray):
        self.clip, self.frames = clip, frames
        names = {clip.rig.names[b] for b in pipeline.written_bones(clip)}
        chans = rig_io.bone_channels(clip.channels.fcurves)
        self.curves, self.slots = [], []  # F-curves, and (bone index, property, array index) of each
        for (bone, prop), curves in chans.items():
            if bone in names and (prop == "location" or prop in ROTATIONS):
                for i, fc in sorted(curves.items()):
                    self.curves.append(fc)
                    self.slots.append((clip.rig.names.index(bone), prop, i))
        self.loc, self.rot, self.scale = rig_io.read_local_pose(clip.obj, clip.rig, clip.channels.fcurves, frames)
        self.rotation = {}  # bone -> (mode, full current values [F, n], {array index: column})
        for col, (b, prop, i) in enumerate(self.slots):
            if prop in ROTATIONS:
                pb = clip.obj.pose.bones[clip.rig.names[b]]
                entry = self.rotation.setdefault(b, (pb.rotation_mode, rig_io.rotation_values(chans, pb, frames), {}))
                entry[2][i] = col

    def values(self) -> np.ndarray:
        """The channels as the curves give them at every frame ``[F, C]``."""
        return np.stack([rig_io.sample_fcurve(fc, self.frames) for fc in self.curves], 1)

    def joints(self, index: np.ndarray, values: np.ndarray) -> np.ndarray:
        """Canonical joints ``[N, 21, 3]`` (armature space) of frames ``index`` posed with ``values`` ``[N, C]``."""
        loc, rot = self.loc[index].copy(), self.rot[index].copy()
        for col, (b, prop, i) in enumerate(self.slots):
            if prop == "location":
                loc[:, b, i] = values[:, col]
        for b, (mode, current, cols) in self.rotation.items():
            raw = current[index].copy()
            for i, col in cols.items():
                raw[:, i] = values[:, col]
            rot[:, b] = rig_io.rotation_matrices(mode, raw)
        return anchor_positions(self.clip.rig, self.clip.anchors, fk(self.clip.rig, loc, rot, self.scale[index]))


def _reach(chans: _Channels, baked: np.ndarray) -> np.ndarray:
    """For each channel, how far (armature units) a joint it moves can be from its bone's head: a turn of
    one radian moves a joint that far at most (a location channel moves its joints one for one)."""
    rig, anchors = chans.clip.rig, chans.clip.anchors
    pose = fk(rig, chans.loc[:1], chans.rot[:1], chans.scale[:1])[0]
    out = np.ones(len(chans.slots))
    for col, (b, prop, _) in enumerate(chans.slots):
        if prop != "location":
            below = [j for j in range(len(anchors.bone)) if rig.is_ancestor(b, int(anchors.bone[j]))]
            head = pose[b, :3, 3]
            out[col] = max([float(np.linalg.norm(baked[0, j] - head)) for j in below] + [1e-6])
    return out


def simplify_keys(context, obj, first: int, last: int, tolerance_cm: float) -> dict | None:
    """Keep only the keys of frames ``first``..``last`` on ``obj``'s written bones that hold its joints
    within ``tolerance_cm`` of the full bake; None on a rig keyed on its controls (left as it is).

    Each channel is thinned on its own to the value tolerance that keeps the joints it moves within
    the tolerance (:func:`_reach`); while the joints together stray further, every channel's tolerance
    is tightened. Returns ``{"keys": keys kept, "full": keys before, "max_error_cm": as evaluated}``."""
    clip = pipeline.prepare(context, obj)
    if clip.controls is not None:
        return None
    frames = np.arange(first, last + 1, dtype=np.float64)
    chans = _Channels(clip, frames)
    if not chans.curves or len(frames) < 3:
        return {"keys": len(frames) * len(chans.curves), "full": len(frames) * len(chans.curves), "max_error_cm": 0.0}
    per_cm = 0.01 / pipeline.world_scale(clip)  # armature units per cm
    tol = tolerance_cm * per_cm
    full = chans.values()
    everything = np.arange(len(frames))
    baked = chans.joints(everything, full)
    quaternion = np.array([prop == "rotation_quaternion" for _, prop, _ in chans.slots])
    budget = tol / _reach(chans, baked) / np.where(quaternion, 2.0, 1.0)  # a quaternion moves half the angle
    span = (float(first), float(last))
    kept_of = {}
    for _ in range(6):
        for col, fc in enumerate(chans.curves):
            def error_of(kept, col=col, fc=fc):
                anim.write_keys(fc, frames[kept], full[kept, col], replace=span)
                return np.abs(rig_io.sample_fcurve(fc, frames) - full[:, col])

            kept_of[col], _ = refine(len(frames), error_of, budget[col], start_every=max(2, len(frames)))
            anim.write_keys(fc, frames[kept_of[col]], full[kept_of[col], col], replace=span)
        err = np.linalg.norm(chans.joints(everything, chans.values()) - baked, axis=-1).max(1)
        if err.max() <= tol:
            break
        budget *= 0.6
    if err.max() > tol:  # give up thinning: every frame keyed again
        for col, fc in enumerate(chans.curves):
            kept_of[col] = everything
            anim.write_keys(fc, frames, full[:, col], replace=span)
        err = np.zeros(len(frames))
    keys = int(sum(len(k) for k in kept_of.values()))
    return {"keys": keys, "full": len(frames) * len(chans.curves), "max_error_cm": round(float(err.max()) / per_cm, 3)}
