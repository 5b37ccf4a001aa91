"""Operators: thin wrappers that gather options and hand them to the stages (``stages/``)."""

from __future__ import annotations

import bpy

from ..model_core.ops.loop import UNWOUND_LOCK_DEG
from . import props as options
from .props import joint_label
from .scene import anim, controls, mapping
from .scene.curves import find_curve
from .scene.pipeline import BAKED_BONES, OWN_BONES, UserError, check_object, rig_of
from .scene.simplify import simplify_keys
from .stages.check import check_motion
from .stages.common import RECORD, STAGES, Unwritten, report_note, run
from .stages.denoise import denoise_steps
from .stages.extend import extend_steps
from .stages.follow import follow_curve_steps
from .stages.footlock import foot_lock_steps
from .stages.inbetween import inbetween_steps
from .stages.loop import loop_steps
from .stages.transfer import transfer_steps

POOR_MATCH_CM = 15.0  # Make Loop's report says the seam was not found where the pose comes round (cm a joint)


class _Staged:
    """Runs a worker generator (see stages/common.py): all at once in ``execute`` (scripts, redo panel),
    stage by stage from a timer in ``modal`` when invoked from the UI, with progress in the status
    bar and Esc to cancel between stages, or between the steps of a stage that yields its fraction
    done as it goes (Follow Curve's model windows, a control rig's bake). Nothing is written before the last stage,
    and Esc within it puts back what it wrote.

    With ``many`` the operation runs on every selected armature, the active one first (a crowd, a cast: as
    Blender's own operators act on the selection): each is read and computed before any is written, so an
    error on the active armature or Esc leaves every one as it was. Another selected armature the operation
    cannot take (no action, not a rig it can map, too few frames...) is left as it was and the report says why."""

    need_action = True  # the active armature must have an action (Follow Curve can start one)
    many = False  # every selected armature, not only the active one

    @classmethod
    def poll(cls, context):
        """Greyed out, with the reason, unless the active object is an armature the stage can take."""
        problem = check_message(context.active_object, cls.need_action)
        if problem:
            cls.poll_message_set(problem)
        return not problem

    def range_from_scene(self, context) -> None:
        """With Frame Range off, or a Start nobody set (a script's call), Start and End are the scene's
        preview range, or else its frame range, as Blender's Bake Action takes them: turning Frame Range
        on (redo panel, sidebar) starts from the range the animator works in. A range set with Frame
        Range on is kept: handed by a script, or remembered (the sidebar's), which Blender hands to a run
        from a button, F3 or a menu."""
        props = self.properties
        if "frame_start" not in props.bl_rna.properties:
            return
        if self.use_range and props.is_property_set("frame_start"):
            return
        scene = context.scene
        preview = scene.use_preview_range
        self.frame_start = scene.frame_preview_start if preview else scene.frame_start
        self.frame_end = scene.frame_preview_end if preview else scene.frame_end

    def steps(self, context, obj):
        raise NotImplementedError

    def done(self, action) -> str:
        raise NotImplementedError

    def objects(self, context) -> tuple[list, list[str]]:
        """The armatures to run on, the active one first (with ``many``, then the other selected armatures by
        name), and why each selected armature left out was: one that :func:`check_message` refuses."""
        active = context.active_object
        if not self.many:
            return [active], []
        taken, left = [active], []
        others = sorted((o for o in context.selected_objects if o.type == "ARMATURE" and o is not active),
                        key=lambda o: o.name)
        for obj in others:
            problem = check_message(obj, self.need_action)
            if problem:
                left.append(f"{obj.name!r} ({problem})")
            else:
                taken.append(obj)
        return taken, left

    def work(self, context):
        """Every armature's stages up to its writing, then each one's writing: a generator of the stages (their
        names, or fractions done) like one armature's, which returns ``[(armature, new action)]``. While it runs,
        ``self._at`` is the armature it is on ``(index, count, name)``; ``self._left`` says which selected
        armatures it left as they were, and why."""
        objs, self._left = self.objects(context)
        ready, count = [], len(objs)
        try:
            for i, obj in enumerate(objs):
                self._at = (i, count, obj.name)
                steps = self.steps(context, obj)
                try:
                    stage = next(steps)
                    while stage != "write":
                        yield stage
                        stage = next(steps)
                except StopIteration as stop:  # a stage with no writing of its own: it is done
                    ready.append((obj, None, stop.value))
                    continue
                except UserError as e:
                    if i == 0:  # the armature asked for: nothing is changed
                        raise UserError(f"{obj.name!r}: {e}" if count > 1 else str(e)) from e
                    self._left.append(f"{obj.name!r} ({e})")
                    continue
                ready.append((obj, steps, None))
            made, kept = [], [Unwritten(context, obj) for obj, _, _ in ready]
            try:
                for i, (obj, steps, result) in enumerate(ready):
                    self._at = (i, len(ready), obj.name)
                    if steps is not None:
                        yield "write"
                        result = yield from steps  # a control rig's bake yields its fractions done
                    made.append((obj, result))
            except BaseException:  # Esc or a failure while writing: the armatures written before are put back
                for (_, action), unwritten in reversed(list(zip(made, kept))):
                    unwritten.undo(action)
                raise
            return made
        finally:
            for _, steps, _ in ready:
                if steps is not None:
                    steps.close()

    def finished(self, context, made, left=()) -> None:
        """Thin the keys (``simplify``), deliver each new action as asked (``output``), report what was done
        (a warning with a note: the take's pace suggests its keys are read at another rate than captured, or
        its motion is unlike what the model learnt; or a selected armature was ``left`` as it was)."""
        said = []  # (warn, text)
        for obj, action in made:
            note = report_note(action)
            text = self.done(action) + note
            if getattr(self, "simplify", 0.0) > 0.0:
                text += simplified(context, obj, action, self.simplify)
            if getattr(self, "output", "ACTION") == "NLA":
                track = as_nla_strip(obj, action)
                text += f"; put on NLA track {track.name!r}, the active action unchanged"
            said.append((bool(note), text if len(made) == 1 and not left else f"{obj.name!r}: {text}"))
        if len(made) > 1 or left:  # each armature's line first (the Info editor keeps them), then the summary the
            names = ", ".join(repr(obj.name) for obj, _ in made)  # status bar shows
            summary = f"{self.bl_label} on {len(made)} armature{'s' if len(made) > 1 else ''} ({names})"
            if left:
                summary += f"; left as {'they were' if len(left) > 1 else 'it was'}: " + "; ".join(left)
            said.append((bool(left) or any(w for w, _ in said), summary))
        for warn, text in said:
            self.report({"WARNING"} if warn else {"INFO"}, text)

    def _progress(self, wm, stage) -> None:
        """The progress bar over every armature's stages."""
        i, count, _ = self._at
        at = STAGES.index(stage if isinstance(stage, str) else self._stage)
        done = 0.0 if isinstance(stage, str) else float(stage)
        wm.progress_begin(0, len(STAGES) * count)
        wm.progress_update(i * len(STAGES) + at + done)

    def execute(self, context):
        self.range_from_scene(context)
        wm = context.window_manager
        self._at, self._left = (0, 1, ""), []
        try:
            made = run(self.work(context), lambda stage: self._progress(wm, stage))
        except UserError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        finally:
            wm.progress_end()
        self.finished(context, made, self._left)
        return {"FINISHED"}

    def invoke(self, context, event):
        self.range_from_scene(context)
        if context.window is None:
            return self.execute(context)
        self._at, self._left = (0, 1, ""), []
        self._steps, self._stage = self.work(context), "read"
        return self._advance(context) or self._start(context)

    def _start(self, context):
        wm = context.window_manager
        self._timer = wm.event_timer_add(0.01, window=context.window)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        if event.type == "ESC":
            self._stop(context)
            self.report({"WARNING"}, "Cancelled; nothing was changed")
            return {"CANCELLED"}
        if event.type != "TIMER":
            return {"RUNNING_MODAL"}  # hold other input until the work is done
        return self._advance(context) or {"RUNNING_MODAL"}

    def _advance(self, context):
        """Run the next stage; the operator's final result when the work ends, else None."""
        try:
            stage = next(self._steps)
        except StopIteration as stop:
            self._stop(context)
            self.finished(context, stop.value, self._left)
            return {"FINISHED"}
        except UserError as e:
            self._stop(context)
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        if isinstance(stage, str):
            self._stage, done = stage, ""
        else:  # the fraction of the current stage done so far
            done = f" {stage:.0%}"
        self._progress(context.window_manager, stage)
        if context.workspace:
            i, count, name = self._at
            which = f"{name!r} ({i + 1} of {count}), " if count > 1 else ""
            context.workspace.status_text_set(f"STRNN {self.bl_label}: {which}{self._stage}{done}... (Esc to cancel)")
        return None

    def _stop(self, context):
        self._steps.close()
        wm = context.window_manager
        if getattr(self, "_timer", None):
            wm.event_timer_remove(self._timer)
            self._timer = None
        wm.progress_end()
        if context.workspace:
            context.workspace.status_text_set(None)


class STRNN_OT_extend_clip(_Staged, bpy.types.Operator):
    """Continue the action of the active armature (and of every other selected one) with the motion model; writes
    a new action"""

    bl_idname = "strnn.extend_clip"
    bl_label = "Extend Clip"
    bl_options = {"REGISTER", "UNDO"}
    many = True

    frames: options.frames_to_add()
    context_frames: options.context_frames()
    follow_clip: options.follow_clip()
    from_current: options.from_current()
    foot_lock: options.foot_lock("extend_clip")
    ground: options.ground_name(walk=True)
    before_start: options.before_start()
    scene_range: options.scene_range()
    output: options.output()
    simplify: options.simplify()

    def steps(self, context, obj):
        start = context.scene.frame_current if self.from_current else None
        return extend_steps(context, obj, frames=self.frames, context_frames=self.context_frames,
                            follow_clip=self.follow_clip, foot_lock=self.foot_lock, from_frame=start,
                            scene_range=self.scene_range, before_start=self.before_start, ground=self.ground)

    def done(self, action) -> str:
        stepped = stepped_note(action)
        if action[RECORD].get("in_place"):
            stepped += " (in place: the clip steps on the spot, so the new frames stay where it is)"
        if "cycles_baked" in action[RECORD].to_dict():
            span = action[RECORD]["cycles_baked"]
            played = f"has the cycles it played over frames {span[0]}-{span[1]} as keys and " if len(span) else ""
            stepped += (f"; the action repeated by Cycles modifiers: the new one {played}repeats no more, so the new "
                        "frames follow")
        where = "before" if self.before_start else "after"
        if self.from_current:
            return (f"Continued {where} frame {bpy.context.scene.frame_current} with {self.frames} new frames in new "
                    f"action {action.name!r}{stepped}{range_note(action, self.before_start)}")
        added = " before its first frame" if self.before_start else ""
        return (f"Added {self.frames} frames{added} in new action {action.name!r}{stepped}"
                f"{range_note(action, self.before_start)}")


class STRNN_OT_fill_gap(_Staged, bpy.types.Operator):
    """Fill the frames between the keys before and after a gap with the motion model, on the active armature (and
    every other selected one); writes a new action"""

    bl_idname = "strnn.inbetween"
    bl_label = "Fill Gap"
    bl_options = {"REGISTER", "UNDO"}
    many = True

    use_range: options.use_range("Fill")
    frame_start: options.range_start("Fill")
    frame_end: options.range_end("Fill")
    follow_take: options.follow_take()
    foot_lock: options.foot_lock("inbetween")
    output: options.output()
    simplify: options.simplify()

    def steps(self, context, obj):
        start, end = (self.frame_start, self.frame_end) if self.use_range else (None, None)
        return inbetween_steps(context, obj, frame_start=start, frame_end=end,
                               follow_take=self.follow_take, foot_lock=self.foot_lock)

    def done(self, action) -> str:
        record = action.get(RECORD, {}).get("settings", {})
        return (f"Filled frames {record.get('frame_start')}-{record.get('frame_end')} in new action "
                f"{action.name!r}{stepped_note(action)}")


class STRNN_OT_denoise_action(_Staged, bpy.types.Operator):
    """Clean the action of the active armature (and of every other selected one) with the denoising model; writes a
    new action"""

    bl_idname = "strnn.denoise_action"
    bl_label = "Denoise Action"
    bl_options = {"REGISTER", "UNDO"}
    many = True

    strength: options.strength()
    use_range: options.use_range("Denoise")
    frame_start: options.range_start("Denoise")
    frame_end: options.range_end("Denoise")
    foot_lock: options.foot_lock("denoise_action")
    only_selected: options.only_selected()
    output: options.output()
    simplify: options.simplify()

    def steps(self, context, obj):
        start, end = (self.frame_start, self.frame_end) if self.use_range else (None, None)
        return denoise_steps(context, obj, frame_start=start, frame_end=end,
                             strength=self.strength, foot_lock=self.foot_lock, only_selected=self.only_selected)

    def done(self, action) -> str:
        return f"Denoised into new action {action.name!r}{stepped_note(action)}"


class STRNN_OT_foot_lock(_Staged, bpy.types.Operator):
    """Pin the feet of the active armature (and of every other selected one) on the ground while they touch it
    (leg IK); writes a new action"""

    bl_idname = "strnn.foot_lock"
    bl_label = "Foot Lock"
    bl_options = {"REGISTER", "UNDO"}
    many = True

    blend: options.lock_blend()
    use_range: options.use_range("Lock")
    frame_start: options.range_start("Lock")
    frame_end: options.range_end("Lock")
    only_selected: options.only_selected()
    ground: options.ground_name()
    output: options.output()
    simplify: options.simplify()

    def steps(self, context, obj):
        start, end = (self.frame_start, self.frame_end) if self.use_range else (None, None)
        return foot_lock_steps(context, obj, frame_start=start, frame_end=end, blend=self.blend,
                               only_selected=self.only_selected, ground=self.ground)

    def done(self, action) -> str:
        on = f" on {self.ground!r}" if self.ground else ""
        return f"Locked the feet{on} into new action {action.name!r}{stepped_note(action)}"


class STRNN_OT_make_loop(_Staged, bpy.types.Operator):
    """Make a stretch of the action a cycle that repeats without a seam (a walk, a run, an idle), on the active
    armature (and every other selected one); writes a new cyclic action"""

    bl_idname = "strnn.make_loop"
    bl_label = "Make Loop"
    bl_options = {"REGISTER", "UNDO"}
    many = True

    use_range: options.use_range("Loop")
    frame_start: options.range_start("Loop")
    frame_end: options.range_end("Loop")
    match: options.loop_match()
    blend: options.loop_blend()
    in_place: options.loop_in_place()
    foot_lock: options.foot_lock("make_loop")
    output: options.output()
    simplify: options.simplify()

    def steps(self, context, obj):
        start, end = (self.frame_start, self.frame_end) if self.use_range else (None, None)
        return loop_steps(context, obj, frame_start=start, frame_end=end, blend=self.blend, match=self.match,
                          in_place=self.in_place, foot_lock=self.foot_lock)

    def done(self, action) -> str:
        cycle = action[RECORD]["cycle"]
        first, seam = cycle["first"], cycle["seam"]
        moves = ("in place" if action[RECORD]["settings"].get("in_place") else
                 f"travelling {length(cycle['travel'])} a cycle")
        made = (f"; the last {cycle['blend_keys']} keys before the seam made again to flow into the start"
                if cycle["blend_keys"] else "")
        settings = action[RECORD]["settings"]
        if settings.get("match") and cycle["match_cm"] > POOR_MATCH_CM:
            made += (f"; no frame of the range's second half comes round to the first frame's pose (the nearest "
                     f"{cycle['match_cm']:.0f} cm a joint off), so the blend carries it there: a range of a whole "
                     "stride or two loops more cleanly")
        turn = cycle.get("turn_deg", 0.0)
        if abs(turn) > UNWOUND_LOCK_DEG:
            locked = ", its feet locked over it" if action[RECORD]["settings"].get("foot_lock") else ""
            made += (f"; the take turns {abs(turn):.0f} degrees {'left' if turn > 0 else 'right'} over the cycle, "
                     f"unwound so that it repeats in a straight line{locked}")
        return (f"Looped frames {first}-{seam} ({cycle['frames']} frames, {cycle['seconds']:.2f} s, {moves}) in new "
                f"cyclic action {action.name!r}: frame {seam} starts the next cycle, Cycles modifiers repeat it"
                f"{made}{stepped_note(action)}")


class STRNN_OT_follow_curve(_Staged, bpy.types.Operator):
    """Make the active armature walk along a curve with the motion model; writes a new action"""

    bl_idname = "strnn.follow_curve"
    need_action = False
    bl_label = "Follow Curve"
    bl_options = {"REGISTER", "UNDO"}

    curve: options.curve_name()
    frames: options.curve_frames()
    speed: options.curve_speed()
    foot_lock: options.foot_lock("follow_curve")
    ground: options.ground_name(walk=True)
    scene_range: options.scene_range()
    output: options.output()
    simplify: options.simplify()

    def steps(self, context, obj):
        return follow_curve_steps(context, obj, curve=self.curve, frames=self.frames, speed=self.speed,
                                  foot_lock=self.foot_lock, scene_range=self.scene_range, ground=self.ground)

    def done(self, action) -> str:
        curve = find_curve(bpy.context, self.curve)
        others = len(curve.data.splines) - 1
        note = f" (it followed the first of the curve's {others + 1} splines)" if others else ""
        over = f" over {self.ground!r}" if self.ground else ""
        return (f"Walked the curve {curve.name!r}{over} into new action {action.name!r}{note}{stepped_note(action)}"
                f"{range_note(action)}")


class STRNN_OT_transfer_motion(_Staged, bpy.types.Operator):
    """Move the motion of the other selected armature onto the active one (its proportions, feet on the floor);
    with Source named, onto every selected armature but the source; writes a new action"""

    bl_idname = "strnn.transfer_motion"
    need_action = False
    bl_label = "Transfer Motion"
    bl_options = {"REGISTER", "UNDO"}
    many = True  # with Source named: a cast given one take

    def objects(self, context) -> tuple[list, list[str]]:
        """With Source named, the active armature and every other selected one but the source, each given its
        motion; else the active one alone (the other selected armature is the source)."""
        if not self.source:
            return [context.active_object], []
        taken, left = super().objects(context)
        return [taken[0]] + [o for o in taken[1:] if o.name != self.source], left

    source: options.source_name()
    foot_lock: options.foot_lock("transfer_motion")
    ground: options.ground_name(walk=True)
    root_motion: options.root_motion()
    scene_range: options.scene_range()
    output: options.output()
    simplify: options.simplify()

    def steps(self, context, obj):
        return transfer_steps(context, obj, source=self.source, foot_lock=self.foot_lock,
                              scene_range=self.scene_range, ground=self.ground, root_motion=self.root_motion)

    def done(self, action) -> str:
        record = action.get(RECORD, {}).get("settings", {})
        return (f"Moved the motion of {record.get('source')!r} onto {record.get('target')!r} in new action "
                f"{action.name!r}{stepped_note(action)}{range_note(action)}")


class STRNN_OT_auto_map(bpy.types.Operator):
    """Map the active armature's bones to the model's 21 joints from their names and hierarchy"""

    bl_idname = "strnn.auto_map"
    bl_label = "Auto-Map Bones"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        obj = context.active_object
        if obj is None or obj.type != "ARMATURE":
            cls.poll_message_set("Select an armature to map its bones")
            return False
        return True

    def execute(self, context):
        obj = context.active_object
        if obj is None or obj.type != "ARMATURE":
            self.report({"ERROR"}, "Select an armature to map its bones")
            return {"CANCELLED"}
        if obj.library is not None:
            self.report({"ERROR"}, f"The object {obj.name!r} is linked: add a library override (Object > Library "
                                   "Override > Make) to store a bone map")
            return {"CANCELLED"}
        family, found = mapping.auto_map(obj)
        mapping.store_map(obj, found, family)
        missing = [joint_label(j) for j in mapping.bonemap.missing(found)]
        if missing:
            self.report({"WARNING"}, f"Mapped {21 - len(missing)} of 21 joints; pick these by hand: "
                                     + ", ".join(missing))
            return {"FINISHED"}
        placed = mapping.bonemap.placed(found)
        mapped = "all 21" if not placed else str(21 - len(placed))
        try:
            found_controls = rig_of(obj)[3]
        except UserError as e:
            self.report({"WARNING"}, f"Mapped {mapped} joints ({family} rig), but: {e}")
            return {"FINISHED"}
        keyed = f"; results are keyed on its {found_controls.name} controls" if found_controls else ""
        if found_controls is not None and found_controls.name == OWN_BONES:
            keyed = ("; results are keyed on its bones by a visual bake (bones that do not simply follow their "
                     "parents, or NLA strips under its action)")
        if found_controls is not None and found_controls.name == BAKED_BONES:
            keyed = ("; it is a control rig an exporter baked (its controls drive nothing), so results are keyed on "
                     "its deform bones, the rest of its skin (a face, a pelvis) carried with the deform bone it moves "
                     "with")
        if placed:  # a chest or a neck, or both (both then lie between the spine and the head)
            below, above, _ = next(iter(placed.values()))
            keyed += (f"; it has no {' or '.join(joint_label(j) for j in placed)} bone, so "
                      f"{'that joint is' if len(placed) == 1 else 'those joints are'} placed between "
                      f"{joint_label(below)} and {joint_label(above)}")
        across = mapping.tails_across(obj, found)
        if any(j.endswith("fingertip") for j in across):  # solve.tips_along_the_limb
            keyed += ("; its hands have no finger bone and their tails point across them, so the finger tips are "
                      "taken along the forearms")
        if any(mapping.bonemap.at_the_foot_tail(found, j) for j in across):
            keyed += ("; its feet have no toe bone and their tails point across them, so the toes are placed forward "
                      "of the ankles, the way the body faces")  # solve.tips_along_the_limb
        toes = [j for j in across if j.endswith("toe") and not mapping.bonemap.at_the_foot_tail(found, j)]
        if toes:  # a toe bone's tail picked in the map, turned across it (an FBX import's)
            bones = ", ".join(f"{joint_label(j)} ({found[j][0]!r})" for j in toes)
            self.report({"WARNING"}, f"Mapped {mapped} joints ({family} rig){keyed}; but these sit at a bone's "
                                     f"tail that points across the bone: {bones} (an FBX imported without Automatic "
                                     "Bone Orientation?), so the foot would turn to put them there: re-import with "
                                     "Automatic Bone Orientation on, or pick a toe bone for them in the Bone Map "
                                     "panel")
            return {"FINISHED"}
        self.report({"INFO"}, f"Mapped {mapped} joints ({family} rig){keyed}")
        return {"FINISHED"}


CHECKED: dict = {}  # checked_key -> (a warning?, the last Check Motion's message), shown in the sidebar


class STRNN_OT_check_motion(bpy.types.Operator):
    """Say how familiar the active armature's motion is to the model, so you know how far to trust Extend, Fill Gap
    and Denoise on it; changes nothing"""

    bl_idname = "strnn.check_motion"
    bl_label = "Check Motion"
    bl_options = {"REGISTER"}  # nothing changes: no undo step

    @classmethod
    def poll(cls, context):
        problem = check_message(context.active_object)
        if problem:
            cls.poll_message_set(problem)
        return not problem

    def execute(self, context):
        obj = context.active_object
        try:
            checked = check_motion(context, obj)
        except UserError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        said = checked.report(obj.animation_data.action.name)
        CHECKED[checked_key(obj)] = (checked.warns, said)
        self.report({"WARNING"} if checked.warns else {"INFO"}, said)
        return {"FINISHED"}


def checked_key(obj) -> tuple:
    """Which action a Check Motion's message is for: the armature and its action as this Blender session knows them
    (``session_uid``: not their names, which another file opened later may reuse) and the action's frame range."""
    action = obj.animation_data.action
    return obj.session_uid, action.session_uid, tuple(round(f, 3) for f in action.frame_range)


class STRNN_OT_clear_map(bpy.types.Operator):
    """Forget the active armature's bone map"""

    bl_idname = "strnn.clear_map"
    bl_label = "Clear Bone Map"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        obj = context.active_object
        return obj is not None and obj.type == "ARMATURE" and obj.library is None

    def execute(self, context):
        mapping.store_map(context.active_object, {})
        return {"FINISHED"}


class _EditControls:
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        obj = context.active_object
        if obj is None or obj.type != "ARMATURE" or obj.library is not None:
            cls.poll_message_set("Select an armature (local, or a library override)")
            return False
        return True


class STRNN_OT_control_add(_EditControls, bpy.types.Operator):
    """Add a control: a bone the animator keys and the mapped bone it drives"""

    bl_idname = "strnn.control_add"
    bl_label = "Add Control"

    def execute(self, context):
        obj = context.active_object
        item = obj.strnn_controls.add()
        active = context.active_pose_bone
        item.bone = active.name if active is not None and active.id_data is obj else ""
        obj.strnn_control_index = len(obj.strnn_controls) - 1
        return {"FINISHED"}


class STRNN_OT_control_remove(_EditControls, bpy.types.Operator):
    """Remove the selected control from the list"""

    bl_idname = "strnn.control_remove"
    bl_label = "Remove Control"

    def execute(self, context):
        obj = context.active_object
        if not 0 <= obj.strnn_control_index < len(obj.strnn_controls):
            self.report({"ERROR"}, "No control is selected in the list")
            return {"CANCELLED"}
        obj.strnn_controls.remove(obj.strnn_control_index)
        obj.strnn_control_index = max(0, obj.strnn_control_index - 1)
        return {"FINISHED"}


class STRNN_OT_controls_from_preset(_EditControls, bpy.types.Operator):
    """Fill the control list (and switches) from the shipped preset this rig fits, to edit it"""

    bl_idname = "strnn.controls_from_preset"
    bl_label = "Controls from Preset"

    def execute(self, context):
        obj = context.active_object
        preset = controls.rig_controls.preset_for(obj.pose.bones.keys())
        if preset is None:
            names = ", ".join(dict.fromkeys(p.name for p in controls.rig_controls.PRESETS.values()))
            self.report({"ERROR"}, f"No shipped preset fits {obj.name!r} (presets: {names}): add its controls one by "
                                   "one")
            return {"CANCELLED"}
        rows, switches = controls.rig_controls.as_rows(preset)
        obj.strnn_controls.clear()
        obj.strnn_switches.clear()
        for row in rows:
            item = obj.strnn_controls.add()
            item.bone, item.drives, item.location, item.role, item.switch = (
                row.bone, row.drives, row.location, row.role, row.switch)
        for sw in switches:
            item = obj.strnn_switches.add()
            item.bone, item.prop, item.value, item.ik_value, item.pole_prop = (
                sw.bone, sw.prop, sw.value, sw.ik_value, sw.pole_prop)
        obj.strnn_control_index = 0
        ik = controls.rig_controls.IK_ROLES
        switched = sum(row.role in ik and bool(row.switch) for row in rows)
        always = sum(row.role in ik and not row.switch for row in rows)
        parts = ([f"{len(rows) - switched - always} FK"] if switched or always else []) + (
            [f"{switched} keyed where their limb is animated in IK"] if switched else []) + (
            [f"{always} on limbs always in IK, keyed always"] if always else [])
        parts = f" ({', '.join(parts)})" if parts else ""
        self.report({"INFO"}, f"{len(rows)} controls{parts} and {len(switches)} switches from the "
                              f"{preset.name} preset")
        return {"FINISHED"}


def length(value: float) -> str:
    """A distance in scene units as the scene shows lengths (its unit system and scale)."""
    units = bpy.context.scene.unit_settings
    if units.system == "NONE":
        return f"{value:.2f} units"
    return bpy.utils.units.to_string(units.system, "LENGTH", value * units.scale_length, precision=2)


def stepped_note(action) -> str:
    """Where an operation read and wrote an action keyed on twos (or threes, ...) at its keys, so say; and where it
    keyed a root bone carrying the travel (root motion), which."""
    step = action.get(RECORD, {}).get("key_step", 1)
    root = action.get(RECORD, {}).get("root_motion")
    return ((f" (keyed every {step} frames with Constant interpolation, as the action is)" if step > 1 else "")
            + (f"; the root {root['bone']!r} carries the travel, keyed with the body" if root else ""))


def simplified(context, obj, action, tolerance_cm: float) -> str:
    """Simplify the keys ``action`` got on ``obj`` (its record's ``frames_written``) and say how it went."""
    first, last = action[RECORD]["frames_written"]
    try:
        found = simplify_keys(context, obj, int(first), int(last), tolerance_cm)
    except UserError as e:
        return f"; keys not simplified ({e})"
    if found is None:
        return "; keys not simplified: this rig is keyed on its controls, which keep a key on every frame"
    action[RECORD]["simplify"] = {"tolerance_cm": tolerance_cm, **found}
    return (f"; simplified to {found['keys']:,} of {found['full']:,} keys, joints within "
            f"{found['max_error_cm']:.2f} cm of the full result")


def as_nla_strip(obj, action):
    """Put ``action`` (just assigned to ``obj``) on a new NLA track as a strip at its first frame, and
    make the action it was made from active again (none for a result that started from none)."""
    ad = obj.animation_data
    source = bpy.data.actions.get(action.get(RECORD, {}).get("source_action", ""))
    slot = getattr(ad, "action_slot", None)
    identifier = slot.identifier if slot is not None else None
    ad.action = None
    track = ad.nla_tracks.new()
    track.name = action.name
    strip = track.strips.new(action.name, int(round(action.frame_range[0])), action)
    if identifier and hasattr(strip, "action_slot"):
        strip.action_slot = next((s for s in action.slots if s.identifier == identifier), strip.action_slot)
    if source is not None and source is not action:
        anim.assign_action(obj, source, identifier)
    return track


def range_note(action, start: bool = False) -> str:
    """What happened to the scene's range: widened to the new action's end, or left short of it; with ``start``,
    to its start (frames added before it)."""
    if start:
        scene, first = bpy.context.scene, int(round(action.frame_range[0]))
        if scene.frame_start == first:
            return f"; the scene now starts at frame {first}"
        if scene.frame_start > first:
            return f"; the scene still starts at frame {scene.frame_start} (the new action starts at {first})"
        return ""
    scene, last = bpy.context.scene, int(round(action.frame_range[1]))
    if scene.frame_end == last:
        return f"; the scene now ends at frame {last}"
    if scene.frame_end < last:
        return f"; the scene still ends at frame {scene.frame_end} (the new action runs to {last})"
    return ""


def check_message(obj, need_action: bool = True) -> str:
    """Why the operators would refuse ``obj`` ('' when they would run); without ``need_action``,
    why Follow Curve would, which also starts an armature that has no action."""
    try:
        check_object(obj, need_action)
    except UserError as e:
        return str(e)
    return ""


classes = (STRNN_OT_extend_clip, STRNN_OT_fill_gap, STRNN_OT_denoise_action, STRNN_OT_foot_lock,
           STRNN_OT_make_loop, STRNN_OT_follow_curve, STRNN_OT_transfer_motion, STRNN_OT_check_motion,
           STRNN_OT_auto_map,
           STRNN_OT_control_add, STRNN_OT_control_remove, STRNN_OT_controls_from_preset, STRNN_OT_clear_map)
