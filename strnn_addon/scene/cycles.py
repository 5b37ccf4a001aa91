"""Actions that repeat. An action made cyclic (Make Loop): every F-curve of the armature's slot repeats its keys
from the cycle's first frame to its seam by a Cycles modifier, and the action's manual frame range, marked cyclic, is
the cycle. An action that repeats already (a walk cycle keyed with Cycles modifiers) and is extended: the cycles it
plays up to where the new frames start are baked into keys and the modifiers removed (:func:`bake_cycles`), so the new
frames follow what played, once.

The written curves (the solved bones, or a control rig's controls) hold the cycle already, its seam key the next
cycle's first pose. Every other curve (bones outside the bone map such as fingers, custom properties, the object's
own transform) is closed too: where its value at the seam differs from the first frame's, that difference is eased
in over the frames the model made again before the seam (at least the last tenth of the cycle), so that it repeats
without a pop. Locations repeat with their offset (a walk's travel, on the hips or on the object), every
other channel as it is.
"""

from __future__ import annotations

import numpy as np

from ...model_core.motion.conventions import JOINT_INDEX
from ...model_core.motion.geometry import closing_weights
from ...model_core.rig.controls import closed_cycle, visual_local
from ...model_core.rig.rigs import leg_length
from ...model_core.rig.solve import anchor_positions, fk
from . import anim, pipeline, rig_io


def close(fc, frames: np.ndarray, blend: int) -> bool:
    """Make the curve ``fc`` (not one the solve wrote) end the cycle ``frames`` ``[L + 1]`` (its first frame to the
    seam) on its first frame's value, eased in over the last ``blend`` frames (at least a tenth of the cycle), and
    keep only its keys in the cycle;
    whether it had to be changed. A location keeps its value at the seam (it repeats with its offset)."""
    values = np.array([fc.evaluate(float(f)) for f in frames])
    gap = values[0] - values[-1]
    if not fc.data_path.endswith("location") and abs(gap) > 1e-6 * max(1.0, float(np.abs(values).max())):
        anim.write_keys(fc, frames, values + gap * closing_weights(len(frames), blend), (-np.inf, np.inf))
        return True
    anim.write_keys(fc, frames[[0, -1]], values[[0, -1]])  # its ends pinned where they are, the keys between kept
    anim.keep_between(fc, frames[0], frames[-1])
    return False


def add_cycles(fc) -> None:
    """A Cycles modifier on ``fc`` (its own, where it has one) that repeats its keys before and after them; a
    location repeats with its offset (each cycle goes on from where the last ended)."""
    mod = next((m for m in fc.modifiers if m.type == "CYCLES"), None) or fc.modifiers.new("CYCLES")
    mod.mode_before = mod.mode_after = "REPEAT_OFFSET" if fc.data_path.endswith("location") else "REPEAT"
    mod.mute = False


def close_baked(clip, action, frames: np.ndarray, blend: int) -> set[str]:
    """On a control rig an exporter baked (:data:`pipeline.BAKED_BONES`), make every bone of ``action`` end the cycle
    ``frames`` where it began carried by the cycle's travel (the hips'), its keys set anew where they change
    (:func:`controls.closed_cycle`): the bones its keys were set against (Rigify's ``torso``) travel as far as the take
    did, and the carried and loose bones' locations keyed against them would repeat that offset too, their skin
    drifting off the deform bones cycle after cycle. Such a rig has no constraints: the action's curves are its pose.
    Returns the data paths keyed anew."""
    full = rig_io.read_rig(clip.obj)
    channels = anim.Channels(action, clip.obj.animation_data)
    chans = rig_io.bone_channels(channels.fcurves)
    frames = np.asarray(frames, np.float64)
    loc, rot, size = rig_io.read_local_pose(clip.obj, full, channels.fcurves, frames)
    pose = fk(full, loc, rot, size)
    index = {n: b for b, n in enumerate(full.names)}
    hips = index[clip.rig.names[int(clip.anchors.bone[JOINT_INDEX["hips"]])]]
    travel = pose[-1, hips, :3, 3] - pose[0, hips, :3, 3]
    kept = np.isin(full.names, [clip.rig.names[b] for b in pipeline.written_bones(clip)])
    props = [rig_io.rotation_property(clip.obj.pose.bones[n]) for n in full.names]
    turned = np.array([(n, props[b]) in chans for b, n in enumerate(full.names)])
    placed = np.array([(n, "location") in chans for n in full.names]) & ~full.connected
    leg = leg_length(anchor_positions(clip.rig, clip.anchors, clip.rig.rest[None]))
    out = closed_cycle(full, pose, travel, blend, kept, turned, placed, leg)
    new_loc, new_rot = visual_local(full, out)
    paths = set()
    for b, name in enumerate(full.names):
        if np.abs(new_rot[:, b] - rot[:, b]).max() < 1e-9 and np.abs(new_loc[:, b] - loc[:, b]).max() < 1e-9 * leg:
            continue  # nor it nor anything above it moved
        pb = clip.obj.pose.bones[name]
        keys = []
        if turned[b]:
            previous = rig_io.rotation_values(chans, pb, frames[:1])[0]
            keys.append(pipeline.encode_rotation(pb.rotation_mode, new_rot[:, b], previous))
        if placed[b]:
            keys.append(("location", new_loc[:, b]))
        for prop, values in keys:
            for i, fc in chans[(name, prop)].items():
                anim.write_keys(fc, frames, values[:, i], (frames[0], frames[-1]))
            paths.add(anim.bone_path(name, prop))
    return paths


def make_cyclic(clip, action, frames: np.ndarray, blend: int, written: set[str]) -> int:
    """Make ``action`` (the new action of ``clip``'s armature, keyed on ``frames`` ``[L + 1]``: the cycle's first
    frame to its seam) cyclic (see the module); the curves in ``written`` (data paths) hold the cycle already. Returns
    how many other curves had to be closed."""
    if clip.controls is not None and clip.controls.name == pipeline.BAKED_BONES:
        written = written | close_baked(clip, action, frames, blend)
    channels = anim.Channels(action, clip.obj.animation_data)
    closed = 0
    for fc in list(channels.fcurves):
        if fc.data_path in written:
            anim.keep_between(fc, frames[0], frames[-1])
        else:
            closed += close(fc, frames, blend)
        add_cycles(fc)
    action.use_frame_range = True
    action.frame_start, action.frame_end = float(frames[0]), float(frames[-1])
    action.use_cyclic = True
    return closed


def repeats(clip, back: bool = False) -> bool:
    """Whether a curve of a bone the operations key (:func:`pipeline.keyed_names`) repeats beyond its keys by a
    Cycles modifier: after the last (``back``: before the first), where the action plays on without keys."""
    names = set(pipeline.keyed_names(clip))
    for (bone, _prop), by_index in rig_io.bone_channels(clip.channels.fcurves).items():
        if bone in names and any(m.type == "CYCLES" and not m.mute and (m.mode_before if back else m.mode_after)
                                 != "NONE" for fc in by_index.values() for m in fc.modifiers):
            return True
    return False


def bake_cycles(channels, frames: np.ndarray) -> int:
    """Key every curve of ``channels`` that a Cycles modifier repeats with the values it plays on ``frames`` (whole
    frames beyond its keys; none: nothing to key) and remove the modifier, so that it plays those and no more;
    how many curves."""
    frames = np.asarray(frames, np.float64)
    baked = 0
    for fc in list(channels.fcurves):
        mods = [m for m in fc.modifiers if m.type == "CYCLES"]
        if not mods:
            continue
        values = np.array([fc.evaluate(float(f)) for f in frames])
        for m in mods:
            fc.modifiers.remove(m)
        if len(frames):
            anim.write_keys(fc, frames, values)
        baked += 1
    return baked
