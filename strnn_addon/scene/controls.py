"""Write a solved pose on a control rig's controls: a visual bake (see ``model_core/rig/controls.py``).

For each frame the rig is evaluated by Blender, and each control is turned (the body's root
control also moved) by the correction that takes the bone it drives from where it is to where
the solve put it. Controls are set in waves (:class:`Waves`): a control waits for the controls
that move its driven bone (found once per bake by nudging each control, so that constraints count
as well as parents), but for those it rides on rigidly (an FK forearm on its upper arm), which
carry it where they set it; the rig is evaluated once per wave. The controls are set through a
stand-in action of one key per channel (:class:`rig_io.StandIn`), which Blender evaluates at the cost of
the pose alone. The result is read back off the controls' local transforms and keyed; the action,
the controls and switches are put back as they were, so until the new action is assigned nothing
in the file has changed.
"""

from __future__ import annotations

from contextlib import nullcontext
from dataclasses import dataclass

import bpy
import numpy as np
from mathutils import Matrix

from ...model_core.inference.steps import drive
from ...model_core.motion.geometry import nearest_rotation, unit
from ...model_core.rig import controls as rig_controls
from ...model_core.rig.controls import ControlSet
from . import anim, mapping, rig_io

TOLERANCE = 2e-3  # armature units (metres on most rigs): a frame whose driven bones are further off is baked again
MAX_SWEEPS = 3


@dataclass
class Baked:
    """Local transforms of each control over the frames: ``loc`` ``[F, K, 3]``, ``rot`` ``[F, K, 3, 3]``,
    and the largest distance of a driven bone's head or tail from its target (armature units)."""

    loc: np.ndarray
    rot: np.ndarray
    error: float


def control_set(obj) -> ControlSet | None:
    """The controls of ``obj``: those set in its Bone Map panel, else the shipped preset its bones fit."""
    return listed(obj)[0]


def listed(obj) -> tuple[ControlSet | None, list[str]]:
    """(:func:`control_set`, what is wrong with the list set in the Bone Map panel: sentences saying how to fix
    it, none for a preset). A rig no bone of which follows a constraint takes no preset: a control rig back from an
    FBX, glTF or USD exporter has its controls' names, but they drive nothing (each bone is baked on its own)."""
    stored = getattr(obj, "strnn_controls", None)
    if stored is not None and len(stored):
        return rig_controls.from_rows(
            "custom", [rig_controls.Row(c.bone, c.drives, c.location, c.role, c.switch) for c in stored],
            [rig_controls.SwitchRow(s.bone, s.prop, s.value, s.ik_value, s.pole_prop)
             for s in getattr(obj, "strnn_switches", ())])
    if mapping.baked(obj):  # its controls drive nothing
        return None, []
    return rig_controls.preset_for(obj.pose.bones.keys()), []


def as_animated(obj, control_set_: ControlSet) -> ControlSet:
    """The controls to key on ``obj``: each limb of the set that can be keyed on IK controls keyed on them where its
    switch stands nearer IK at its action's last frame (with no action, or a switch the action does not animate: as
    the switch stands now), that is where the animator animates it in IK; a limb always in IK (an IK End of no
    switch) whose IK constraints are all off (muted or of no influence: an MMD model's leg IK toggled off) keyed on
    FK (:meth:`ControlSet.ik_off`)."""
    control_set_ = _ik_off(obj, control_set_)
    if not control_set_.ik_limbs:
        return control_set_
    ad = obj.animation_data
    channels = anim.Channels(ad.action, ad) if ad is not None and ad.action is not None else None
    frame = ad.action.frame_range[1] if channels is not None else None
    values = {}
    for limb in control_set_.ik_limbs:
        pb = obj.pose.bones.get(limb.switch.bone)
        for prop in (limb.switch.prop, limb.pole_prop):
            if pb is None or not prop or prop not in pb:
                continue
            path = f'pose.bones["{bpy.utils.escape_identifier(pb.name)}"]["{prop}"]'
            fc = channels.find(path, 0) if channels is not None else None
            values[(pb.name, prop)] = float(fc.evaluate(frame)) if fc is not None else float(pb[prop])
    return control_set_.keyed(values)


def _ik_off(obj, control_set_: ControlSet) -> ControlSet:
    """``control_set_`` with each IK End of no switch whose IK constraints (those aimed at it) are all off left out,
    and the chain bases in those constraints' chains keyed whole (:meth:`ControlSet.ik_off`)."""
    ends, chains = set(), set()
    wanted = {c.bone for c in control_set_.controls if c.end}
    if not wanted:  # no limb always in IK
        return control_set_
    aiming: dict[str, list] = {}
    for pb in obj.pose.bones:
        for con in pb.constraints:
            if con.type == "IK" and getattr(con, "subtarget", "") in wanted:
                aiming.setdefault(con.subtarget, []).append((pb, con))
    for end in sorted(wanted):
        aimed = aiming.get(end, [])
        if not aimed or any(not con.mute and con.influence > 0 for _, con in aimed):
            continue
        ends.add(end)
        for pb, con in aimed:  # the bones the constraint moves: its owner and chain_count - 1 above (0: all)
            for _ in range(con.chain_count or len(obj.pose.bones)):
                if pb is None:
                    break
                chains.add(pb.name)
                pb = pb.parent
    return control_set_.ik_off(ends, chains)


def _matrix(pb) -> np.ndarray:
    return np.array(pb.matrix, dtype=np.float64)


def _tail(pb, m: np.ndarray) -> np.ndarray:
    """Where bone ``pb``'s tail is with pose matrix ``m`` (armature space), the bone as long as it plays now (an IK
    chain that may stretch plays shorter than its bones: a length no control sets)."""
    return (m @ np.array([0.0, pb.length / max(_scale(m), 1e-12), 0.0, 1.0]))[:3]


def _scale(m: np.ndarray) -> float:
    """How much pose matrix ``m`` scales along its bone (its Y axis)."""
    return float(np.linalg.norm(m[:3, 1]))


# A nudge of a control that turns it about every axis (and moves a control that moves along each): what one control
# does to the bones of others is read off it once per bake.
_NUDGE_AXIS = (0.2673, 0.5345, 0.8018)
_NUDGE_MOVE = (0.01, 0.02, 0.03)
RIGID = 1e-5  # armature units: a bone that moved with a nudged control's driven bone within this rides on it


def _plain(c) -> bool:
    """Whether control ``c`` is set by the correction of its driven bone alone (not an IK chain's end, pole or
    twist, whose setting reads the chain)."""
    return not (c.end or c.pole or c.twist)


def _carried_by(bones, c) -> tuple[str, ...]:
    """What must move with a control for it to ride on another: its driven bone, itself and its parent (the
    space its local transform is set in)."""
    pb = bones[c.bone]
    return (c.drives, c.bone) + ((pb.parent.name,) if pb.parent is not None else ())


class Waves:
    """``chosen`` controls grouped so that no control's driven bone moves with a control of its own wave but one it
    rides on, or with a later wave (found by nudging each control once at the current frame); where two controls
    move each other's bones, the one lower in the hierarchy waits, and a second sweep settles them. A control
    rides on another that moves its driven bone, itself and its parent rigidly, as that moves its own driven bone
    (an FK forearm on its upper arm, the arms on the chest): it is set in the same wave, after it, from where that
    one's setting puts it (:func:`_place`), so Blender evaluates the rig once for the chain. ``moves``: {control:
    the driven bones it moves}; ``rides``: {control: the controls of its wave riding on it}."""

    def __init__(self, obj, chosen: list, update):
        bones = obj.pose.bones
        update()
        watched = {n for c in chosen for n in _carried_by(bones, c)}
        before = {n: _matrix(bones[n]) for n in watched}
        moves: dict[int, set[str]] = {}
        rides: dict[int, set[int]] = {}
        for k, c in enumerate(chosen):
            pb = bones[c.bone]
            keep = pb.matrix_basis.copy()
            pb.matrix_basis = keep @ Matrix.Rotation(0.3, 4, _NUDGE_AXIS) @ Matrix.Translation(
                tuple(c.location * x for x in _NUDGE_MOVE))
            update()
            after = {n: _matrix(bones[n]) for n in watched}
            moved = {n for n in watched if np.abs(after[n] - before[n]).max() > 1e-6}
            moves[k] = {d.drives for d in chosen if d.drives in moved}
            turn = after[c.drives] @ np.linalg.inv(before[c.drives])
            rigid = {n for n in watched if np.abs(after[n] - turn @ before[n]).max() < RIGID}
            rides[k] = {j for j, d in enumerate(chosen) if j != k and d.drives in moved and _plain(d)
                        and rigid.issuperset(_carried_by(bones, d))} if _plain(c) and c.bone in rigid else set()
            pb.matrix_basis = keep
        update()
        rank = [(_depth(bones[c.bone]), k) for k, c in enumerate(chosen)]  # a cycle (neck and head) is cut here
        depth = [0] * len(chosen)
        for k in sorted(range(len(chosen)), key=lambda k: rank[k]):
            above = [depth[j] + (k not in rides[j]) for j in range(len(chosen))
                     if rank[j] < rank[k] and chosen[k].drives in moves[j]]
            depth[k] = max([0] + above)
        order = sorted(range(len(chosen)), key=lambda k: rank[k])  # in a wave, a control after those it rides on
        self.waves = [wave for d in range(max(depth, default=0) + 1)
                      if (wave := [chosen[k] for k in order if depth[k] == d])]
        self.moves = {c.bone: moves[k] for k, c in enumerate(chosen)}
        self.rides = {c.bone: {chosen[j].bone for j in rides[k] if depth[j] == depth[k] and rank[k] < rank[j]}
                      for k, c in enumerate(chosen)}


def _depth(pb) -> int:
    """How many parents a pose bone has."""
    n = 0
    while pb.parent is not None:
        pb, n = pb.parent, n + 1
    return n


def _error(obj, chosen: list, targets: dict[str, np.ndarray]) -> tuple[float, set[str]]:
    """Largest distance of a driven bone's head or tail from its target, and the controls whose driven bones are
    :data:`TOLERANCE` or further off."""
    worst, off = 0.0, set()
    for c in chosen:
        pb = obj.pose.bones[c.drives]
        now, want = _matrix(pb), targets[c.drives]
        err = max(float(np.linalg.norm(now[:3, 3] - want[:3, 3])),
                  float(np.linalg.norm(_tail(pb, now) - _tail(pb, want))))
        worst = max(worst, err)
        if err >= TOLERANCE:
            off.add(c.bone)
    return worst, off


def _untwisted(obj, c, target: np.ndarray) -> bool:
    """Whether twist control ``c``'s chain is already turned as ``target`` asks: turning it again would move its
    bend (the knee) less than a quarter of :data:`TOLERANCE`, so what is left off is the chain's length, which Blender
    plays (an IK chain that may stretch plays shorter than its bones) and no turn changes."""
    pb = obj.pose.bones[c.drives]
    driven = _matrix(pb)
    reach = float(np.linalg.norm(_tail(pb, driven) - driven[:3, 3]))
    return abs(_bend_turn(pb, driven, target)) * reach < TOLERANCE / 4


def _reached(off: set[str], chosen: list, moves: dict[str, set[str]]) -> set[str]:
    """The controls ``off`` and every control whose driven bone they move, and so on: what setting them again
    may disturb."""
    out, grown = set(off), True
    while grown:
        more = {c.bone for c in chosen if c.bone not in out and any(c.drives in moves[b] for b in out)}
        out, grown = out | more, bool(more)
    return out


def _place(obj, c, target: np.ndarray, first: bool, put, carried: np.ndarray | None = None) -> np.ndarray | None:
    """Turn (and, for a root control, move) control ``c`` so its driven bone goes to ``target``,
    taking the rig as last evaluated (``first``: the frame's first sweep), and set it by ``put(pose bone, local
    matrix)``. ``carried``: where controls it rides on were set since (:class:`Waves`), the move (armature space)
    they gave it and its driven bone and parent. Returns the control's own move (armature space), which carries
    the controls riding on it (None for a twist, which carries none)."""
    bones = obj.pose.bones
    pb = bones[c.bone]
    carried = np.eye(4) if carried is None else carried
    driven = carried @ _matrix(bones[c.drives])
    delta = target @ np.linalg.inv(driven)
    now = carried @ _matrix(pb)
    want = now.copy()
    if c.end and first:  # where the chain may not reach it yet: as the control and the bone stand at rest
        want = target @ np.linalg.inv(np.array(bones[c.drives].bone.matrix_local)) @ np.array(pb.bone.matrix_local)
    elif c.pole:
        want[:3, 3] = _pole_at(bones[c.drives], driven, target, now)
    elif c.twist:  # the knee's turn about the line from hip to ankle that the solve asks for, added to the chain
        # base's own turn about its axis (on its keyed transform: the chain takes that turn as its start)
        put(pb, pb.matrix_basis @ Matrix.Rotation(_bend_turn(bones[c.drives], driven, target), 4, "Y"))
        return None
    elif c.location and not c.turns:  # moved as far as its driven bone is off, not turned
        want[:3, 3] = now[:3, 3] + target[:3, 3] - driven[:3, 3]
    elif c.location:
        want = delta @ now
    else:
        want[:3, :3] = delta[:3, :3] @ now[:3, :3]
    # its parent is where the last evaluation put it, carried as it rides: set against that
    put(pb, obj.convert_space(pose_bone=pb, matrix=Matrix((np.linalg.inv(carried) @ want).tolist()),
                              from_space="POSE", to_space="LOCAL"))
    return want @ np.linalg.inv(now)


def _bend_turn(pb, driven: np.ndarray, target: np.ndarray) -> float:
    """The angle (radians) about the line from the head of an IK chain's base bone ``pb`` (the hip) to the end of
    the chain (the ankle: the tail of its child that starts at its tail) that takes the bend (its tail, the knee)
    from where it is (``driven``) to where ``target`` puts it; 0 where the chain is straight."""
    hip, knee, want = driven[:3, 3], _tail(pb, driven), _tail(pb, target)
    child = min(pb.children, key=lambda ch: float(np.linalg.norm(_matrix(ch)[:3, 3] - knee)), default=None)
    if child is None:
        return 0.0
    axis = unit(_tail(child, _matrix(child)) - hip)
    now, to = ((v - hip) - axis * np.dot(v - hip, axis) for v in (knee, want))
    if min(np.linalg.norm(now), np.linalg.norm(to)) < 1e-6:
        return 0.0
    return float(np.arctan2(np.dot(axis, np.cross(now, to)), np.dot(now, to)))


def _pole_at(pb, driven: np.ndarray, target: np.ndarray, now: np.ndarray) -> np.ndarray:
    """Where an IK pole goes (armature space) for the chain's middle bone ``pb`` to take ``target``: in front of the
    bend (target's head) in the plane of the chain from the bone above it to target's tail, as far from the bend as
    the pole is now from the bone's head; where the chain is straight, where it is now."""
    bend, end = target[:3, 3], _tail(pb, target)
    start = _matrix(pb.parent)[:3, 3] if pb.parent is not None else bend
    line = end - start
    out = bend - (start + line * np.dot(bend - start, line) / max(float(np.dot(line, line)), 1e-12))
    if np.linalg.norm(out) < 1e-4 * max(float(np.linalg.norm(line)), 1e-6):
        return now[:3, 3]
    return bend + unit(out) * float(np.linalg.norm(now[:3, 3] - driven[:3, 3]))


def bake(context, obj, control_set_: ControlSet, frames: np.ndarray, targets: dict[str, np.ndarray]) -> Baked:
    """:func:`bake_steps` run to the end."""
    return drive(bake_steps(context, obj, control_set_, frames, targets))


def bake_steps(context, obj, control_set_: ControlSet, frames: np.ndarray, targets: dict[str, np.ndarray]):
    """The controls' local transforms that put each driven bone on ``targets`` {bone: ``[F, 4, 4]``
    armature-space pose matrices} at scene ``frames``, with the switches on. Only controls whose
    driven bone is in ``targets`` move (in the order of ``control_set_.controls``).

    A step generator: yields the fraction of the frames baked about every :data:`rig_io.STEP_SECONDS`, so that an
    operator can show progress and stop on Esc; returns the :class:`Baked`. In between, the meshes the rig deforms are
    deformed again (they are paused only while the frames are baked, :func:`rig_io.skin_paused`) and the rig shows the
    frame reached; closed part way (Esc), or on any failure, the action, controls, switches and frame are put back.
    A rig that plays alone (:func:`rig_io.plays_alone`) is evaluated alone at each frame, its stand-in's keys changed
    and the scene's frame left as it is; any other by setting the scene to each frame."""
    scene, bones = context.scene, obj.pose.bones
    chosen = [c for c in control_set_.controls if c.drives in targets]
    switches = [s for s in control_set_.switches if s.bone in bones and s.prop in bones[s.bone]]
    fcurves = anim.active_fcurves(obj)
    if not switches and all(c.bone == c.drives and c.turns and _plain(c) for c in chosen) \
            and not rig_io.pose_needs_evaluation(obj, fcurves):  # each bone its own control, on a rig that plays
        return bake_closed(obj, chosen, fcurves, frames, targets)  # as its curves say (one an exporter baked)
    keep_frame = (scene.frame_current, scene.frame_subframe)
    keep_basis = {c.bone: bones[c.bone].matrix_basis.copy() for c in chosen}
    keep_switch = {(s.bone, s.prop): bones[s.bone].get(s.prop) for s in switches}
    layer, alone = context.view_layer, rig_io.plays_alone(obj)
    loc = np.zeros((len(frames), len(chosen), 3))
    rot = np.zeros((len(frames), len(chosen), 3, 3))
    worst = 0.0

    def bake_frame(i: int) -> None:
        nonlocal worst
        f = frames[i]
        stand_in.at(i)
        if alone:  # the rig alone evaluated, not every animated object of the scene
            layer.update()
        else:
            scene.frame_set(int(np.floor(f)), subframe=float(f - np.floor(f)))
        worst = max(worst, _bake_frame(obj, chosen, waves, {d: m[i] for d, m in targets.items()}, stand_in, layer))
        for k, c in enumerate(chosen):
            basis = np.array(bones[c.bone].matrix_basis, dtype=np.float64)
            loc[i, k], rot[i, k] = basis[:3, 3], basis[:3, :3]

    try:
        with rig_io.skin_paused(context, obj):  # the meshes it deforms are not evaluated with it meanwhile
            if not alone:
                scene.frame_set(int(frames[0]))
            for s in switches:
                bones[s.bone][s.prop] = s.value
            if not alone:
                waves = Waves(obj, chosen, layer.update)
        stand_in = rig_io.StandIn(obj, chosen, switches, frames)
        try:
            with rig_io.evaluated_alone(context, obj) if alone else nullcontext(layer) as layer:
                if alone:  # the rig alone at the first frame, its controls nudged there
                    stand_in.at(0)
                    waves = Waves(obj, chosen, layer.update)
                yield from rig_io.in_steps(context, obj, len(frames), bake_frame)
        finally:
            stand_in.close()
    finally:
        for name, basis in keep_basis.items():
            bones[name].matrix_basis = basis
        for (bone, prop), value in keep_switch.items():
            bones[bone][prop] = value
        rig_io.back_in_its_scene(context, obj, None if alone else keep_frame)
    return Baked(loc, nearest_rotation(rot), worst)


def _bake_frame(obj, chosen: list, waves: Waves, want: dict[str, np.ndarray], stand_in: rig_io.StandIn,
                layer) -> float:
    """Set the ``chosen`` controls, wave by wave, so that their driven bones go to ``want`` {bone: armature-space
    matrix} on the frame Blender has evaluated, sweeping again while that brings them nearer; the worst distance
    left (:func:`_error`)."""
    last, again = np.inf, None
    for sweep in range(MAX_SWEEPS):
        for wave in waves.waves:
            layer.update()  # nothing to evaluate where the wave before set nothing
            carried: dict[str, np.ndarray] = {}
            for c in wave:
                if again is None or c.bone in again:
                    move = _place(obj, c, want[c.drives], sweep == 0, stand_in.put, carried.get(c.bone))
                    for rider in waves.rides[c.bone] if move is not None else ():
                        carried[rider] = move @ carried.get(rider, np.eye(4))
        layer.update()
        err, off = _error(obj, chosen, want)
        off -= {c.bone for c in chosen if c.twist and c.bone in off and _untwisted(obj, c, want[c.drives])}
        if err < TOLERANCE or last - err < TOLERANCE / 4 or not off:  # there, or no nearer than the sweep before,
            break  # or off only where setting it again would not bring it nearer
        # the next sweep sets again only the controls still off and those they move (a control within the tolerance
        # is left as the first sweep set it, as on a frame where every control is)
        last, again = err, _reached(off, chosen, waves.moves)
    return err


def bake_closed(obj, chosen: list, fcurves, frames: np.ndarray, targets: dict[str, np.ndarray]) -> Baked:
    """:func:`bake` without Blender's evaluation, where each control is the bone it drives and no bone of ``obj``
    follows anything but its parent: its pose at ``frames`` as the action of ``fcurves`` plays it, each control set
    in turn, parents first (:func:`rig_controls.placed_on_targets`)."""
    names = [c.bone for c in chosen]
    rig = rig_io.with_bones_above(rig_io.read_rig(obj), names)
    loc, rot, scale = rig_io.read_local_pose(obj, rig, fcurves, np.asarray(frames, np.float64))
    index = {n: b for b, n in enumerate(rig.names)}
    at = sorted(range(len(chosen)), key=lambda k: index[names[k]])  # parents first
    loc_k, rot_k, worst = rig_controls.placed_on_targets(
        rig, loc, rot, scale, [index[names[k]] for k in at], [chosen[k].location for k in at],
        np.stack([targets[chosen[k].drives] for k in at], axis=1))
    back = np.argsort(at)
    return Baked(loc_k[:, back], rot_k[:, back], worst)


def key_switches(channels: anim.Channels, obj, control_set_: ControlSet, frames: np.ndarray, edges: np.ndarray):
    """Key each switch at its value on ``frames`` with constant interpolation, and at its present value on
    ``edges`` (frames just outside, inside the action) when the action did not animate it yet."""
    for s in control_set_.switches:
        pb = obj.pose.bones.get(s.bone)
        if pb is None or s.prop not in pb:
            continue
        path = f'pose.bones["{bpy.utils.escape_identifier(s.bone)}"]["{s.prop}"]'
        fc = channels.find(path, 0)
        if fc is None:
            fc = channels.ensure(path, 0, s.bone)
            if len(edges):
                anim.write_keys(fc, edges, np.full(len(edges), float(pb[s.prop])), interpolation="CONSTANT")
        anim.write_keys(fc, frames, np.full(len(frames), float(s.value)), interpolation="CONSTANT")
