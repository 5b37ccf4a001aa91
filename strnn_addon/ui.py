"""The STRNN tab in the 3D Viewport sidebar (Object and Pose mode)."""

from __future__ import annotations

import textwrap

import bpy

from ..model_core.motion.conventions import JOINTS
from ..model_core.rig.solve import placed_between
from . import operators
from .operators import check_message
from .props import CONTROL_ROLES, TAIL_JOINTS, joint_label
from .scene import anim, controls
from .stages.common import RECORD, record_notes


class _Sidebar:
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "STRNN"

    @classmethod
    def poll(cls, context):
        return context.mode in {"OBJECT", "POSE"}


class STRNN_PT_main(_Sidebar, bpy.types.Panel):
    bl_label = "STRNN Motion"

    def draw(self, context):
        obj = context.active_object
        problem = check_message(obj)
        col = self.layout.column()
        if problem and not check_message(obj, need_action=False):  # an armature without an action
            col.label(text=f"{obj.name}: no action", icon="INFO")
            col.label(text="Follow Curve can start one; the others need an action")
            return
        if problem:
            col.label(text=problem.split(":")[0], icon="ERROR")
            return
        action = obj.animation_data.action
        first, last = (int(round(f)) for f in action.frame_range)
        col.label(text=f"{obj.name}: {action.name} (frames {first}-{last})", icon="ACTION")
        if any(m.type == "CYCLES" and not m.mute for fc in anim.Channels(action, obj.animation_data).fcurves
               for m in fc.modifiers):  # it plays on past its keys: Extend goes on after what plays
            col.label(text="Repeats (Cycles modifiers) past its keys", icon="FILE_REFRESH")
        others = [o for o in context.selected_objects if o is not obj and o.type == "ARMATURE" and not check_message(o)]
        if others:  # the operations that run on every selected armature say so before they are run
            many = [cls.bl_label for cls in operators.classes if getattr(cls, "many", False) and cls.need_action]
            col.label(text=f"+ {len(others)} more selected armature{'s' if len(others) > 1 else ''} with an action",
                      icon="OUTLINER_OB_ARMATURE")
            col.label(text=f"{', '.join(many[:-1])} and {many[-1]} run on each")
        col.prop(obj, "strnn_keys_per_second")
        col.operator("strnn.check_motion", icon="VIEWZOOM")
        checked = operators.CHECKED.get(operators.checked_key(obj))
        if checked is not None:  # the last check of this action, kept in view after its report has gone
            wrapped(col, context, checked[1], icon="ERROR" if checked[0] else "CHECKMARK")
        made_by_note(col, action, context)


def made_by_note(col, action, context) -> None:
    """Under the action: which operation made it and, where its report warned (the motion unlike what the model
    learnt, a first window held, the keys' rate), the same notes, wrapped to the sidebar's width, so they stay in
    view after the report has gone from the status bar."""
    record = action.get(RECORD)
    if record is None or "operation" not in record:
        return
    notes = record_notes(action)
    col.label(text=f"Made by {record['operation']}{': check it' if notes else ''}",
              icon="ERROR" if notes else "INFO")
    for note in notes:
        wrapped(col, context, note)


def wrapped(col, context, text: str, icon: str = "NONE") -> None:
    """``text`` as labels wrapped to the sidebar's width, ``icon`` before the first."""
    region = getattr(context, "region", None)
    scale = context.preferences.view.ui_scale if context.preferences else 1.0
    width = max(24, int(region.width / (7.0 * scale)) - 4) if region is not None and region.width > 1 else 48
    for k, line in enumerate(textwrap.wrap(text, width)):
        col.label(text=line, icon=icon if k == 0 else "NONE")


def remembered(context, idname: str):
    """The options operator ``idname`` remembers: what a button, F3, a menu and the redo panel run it
    with. The sidebar shows and edits these, so there is one set of options per operator."""
    return context.window_manager.operator_properties_last(idname)


def _frame_range(col, opts) -> None:
    """The Frame Range toggle and its Start / End (greyed out while off)."""
    col.prop(opts, "use_range")
    row = col.row(align=True)
    row.active = opts.use_range
    row.prop(opts, "frame_start")
    row.prop(opts, "frame_end")


class _OperatorPanel(_Sidebar):
    """A sidebar panel that shows an operator's remembered options and its button, which runs with them
    (the button sets nothing itself: Blender fills a button's unset options from the remembered ones)."""

    bl_parent_id = "STRNN_PT_main"
    operator = ""
    icon = "NONE"

    def draw_options(self, col, opts, context) -> None:
        raise NotImplementedError

    def draw(self, context):
        opts = remembered(context, self.operator)
        self.draw_options(self.layout.column(align=True), opts, context)
        col = self.layout.column(align=True)
        col.row(align=True).prop(opts, "output", expand=True)
        col.prop(opts, "simplify")
        self.layout.operator(self.operator, icon=self.icon)


class STRNN_PT_extend(_OperatorPanel, bpy.types.Panel):
    bl_label = "Extend"
    operator, icon = "strnn.extend_clip", "TRACKING_FORWARDS"

    def draw_options(self, col, opts, context):
        col.prop(opts, "frames")
        col.prop(opts, "context_frames")
        col.prop(opts, "follow_clip")
        col.prop(opts, "from_current")
        col.prop(opts, "before_start")
        col.prop(opts, "foot_lock")
        col.prop(opts, "ground", icon="OUTLINER_OB_MESH")


class STRNN_PT_fill_gap(_OperatorPanel, bpy.types.Panel):
    bl_label = "Fill Gap"
    operator, icon = "strnn.inbetween", "IPO_EASE_IN_OUT"

    def draw_options(self, col, opts, context):
        col.label(text="The gap around the current frame, or the first", icon="INFO")
        _frame_range(col, opts)
        col.prop(opts, "follow_take")
        col.prop(opts, "foot_lock")


class STRNN_PT_denoise(_OperatorPanel, bpy.types.Panel):
    bl_label = "Denoise"
    operator, icon = "strnn.denoise_action", "MOD_SMOOTH"

    def draw_options(self, col, opts, context):
        col.prop(opts, "strength", slider=True)
        _frame_range(col, opts)
        col.prop(opts, "only_selected")
        col.prop(opts, "foot_lock")


class STRNN_PT_foot_lock(_OperatorPanel, bpy.types.Panel):
    bl_label = "Foot Lock"
    operator, icon = "strnn.foot_lock", "SNAP_ON"

    def draw_options(self, col, opts, context):
        col.prop(opts, "blend")
        _frame_range(col, opts)
        col.prop(opts, "only_selected")
        col.prop(opts, "ground", icon="OUTLINER_OB_MESH")


class STRNN_PT_loop(_OperatorPanel, bpy.types.Panel):
    bl_label = "Make Loop"
    bl_options = {"DEFAULT_CLOSED"}
    operator, icon = "strnn.make_loop", "FILE_REFRESH"

    def draw_options(self, col, opts, context):
        _frame_range(col, opts)
        col.prop(opts, "match")
        col.prop(opts, "blend")
        col.prop(opts, "in_place")
        col.prop(opts, "foot_lock")


class STRNN_PT_follow_curve(_OperatorPanel, bpy.types.Panel):
    bl_label = "Follow Curve"
    operator, icon = "strnn.follow_curve", "CURVE_PATH"

    def draw_options(self, col, opts, context):
        col.prop(opts, "curve", icon="OUTLINER_OB_CURVE")
        col.prop(opts, "frames")
        col.prop(opts, "speed")
        col.prop(opts, "foot_lock")
        col.prop(opts, "ground", icon="OUTLINER_OB_MESH")


class STRNN_PT_transfer(_OperatorPanel, bpy.types.Panel):
    bl_label = "Transfer Motion"
    bl_options = {"DEFAULT_CLOSED"}
    operator, icon = "strnn.transfer_motion", "ARMATURE_DATA"

    def draw_options(self, col, opts, context):
        col.prop(opts, "source", icon="OUTLINER_OB_ARMATURE")
        if not opts.source:
            col.label(text="Or select the source, then the target", icon="INFO")
        elif sum(o.type == "ARMATURE" and o.name != opts.source for o in context.selected_objects) > 1:
            col.label(text="Onto each selected armature but the source", icon="INFO")
        col.prop(opts, "foot_lock")
        col.prop(opts, "ground", icon="OUTLINER_OB_MESH")
        col.prop(opts, "root_motion")


class _ArmatureSidebar(_Sidebar):
    """A sidebar panel shown for an active armature."""

    @classmethod
    def poll(cls, context):
        obj = context.active_object
        return super().poll(context) and obj is not None and obj.type == "ARMATURE"


class STRNN_PT_bone_map(_ArmatureSidebar, bpy.types.Panel):
    bl_label = "Bone Map"
    bl_parent_id = "STRNN_PT_main"
    bl_options = {"DEFAULT_CLOSED"}


    def draw(self, context):
        obj = context.active_object
        arm = obj.data
        props = obj.strnn_map
        layout = self.layout
        row = layout.row(align=True)
        row.operator("strnn.auto_map", icon="AUTOMERGE_ON")
        row.operator("strnn.clear_map", text="", icon="X")
        present = {j for j in JOINTS if getattr(props, j) and getattr(props, j) in arm.bones}
        placed = placed_between(present)
        missing = [j for j in JOINTS if j not in present and j not in placed]
        if missing:
            layout.label(text=f"Missing: {', '.join(joint_label(j) for j in missing)}", icon="ERROR")
        else:
            layout.label(text=f"{'All 21' if not placed else len(present)} joints mapped"
                              f"{f' ({props.family})' if props.family else ''}", icon="CHECKMARK")
        for joint, (below, above, _) in placed.items() if not missing else ():
            layout.label(text=f"No {joint_label(joint)} bone: placed between {joint_label(below)} and "
                              f"{joint_label(above)}", icon="INFO")
        col = layout.column(align=True)
        for joint in JOINTS:
            row = col.row(align=True)
            row.prop_search(props, joint, arm, "bones", text=joint_label(joint))
            if joint in TAIL_JOINTS:
                row.prop(props, f"{joint}_tail", text="", icon="BONE_DATA", toggle=True)


_ROLE_ICONS = {role[0]: role[3] for role in CONTROL_ROLES}


class STRNN_UL_controls(bpy.types.UIList):
    """Control bone -> the mapped bone it drives, with its Moves toggle; its role's icon first."""

    def draw_item(self, context, layout, data, item, icon, active_data, active_property, index=0, flt_flag=0):
        arm = data.data
        row = layout.row(align=True)
        row.label(icon=_ROLE_ICONS.get(item.role, "BONE_DATA"))
        row.prop_search(item, "bone", arm, "bones", text="")
        row.label(icon="FORWARD")
        row.prop_search(item, "drives", arm, "bones", text="")
        row.prop(item, "location", text="", icon="ORIENTATION_GLOBAL", toggle=True)


class STRNN_PT_controls(_ArmatureSidebar, bpy.types.Panel):
    """Which bones results are keyed on, for rigs whose mapped bones follow controls."""

    bl_label = "Controls"
    bl_parent_id = "STRNN_PT_bone_map"
    bl_options = {"DEFAULT_CLOSED"}


    def draw(self, context):
        obj = context.active_object
        layout = self.layout
        found, problems = controls.listed(obj)
        if not len(obj.strnn_controls):
            text = (f"Keys go on the {found.name} preset's {len(found.controls)} controls" if found
                    else "No controls: keys go on the mapped bones")
            layout.label(text=text, icon="INFO")
        for problem in problems:
            wrapped(layout.column(align=True), context, problem, "ERROR")
        keyed = controls.as_animated(obj, found) if found is not None else None
        if keyed is not None and keyed.keyed_ik:
            layout.label(text=f"In IK, keyed on their IK controls: {', '.join(keyed.keyed_ik)}", icon="CON_KINEMATIC")
        kept = {c.bone for c in keyed.controls} if keyed is not None else set()
        always = [c.bone for c in found.controls if c.end and c.bone in kept] if found is not None else []
        if always:  # IK controls of no switch: limbs that never leave IK (an MMD model's legs), their IK on
            layout.label(text=f"Always in IK, keyed on: {', '.join(always)}", icon="CON_KINEMATIC")
        row = layout.row()
        row.template_list("STRNN_UL_controls", "", obj, "strnn_controls", obj, "strnn_control_index", rows=3)
        col = row.column(align=True)
        col.operator("strnn.control_add", text="", icon="ADD")
        col.operator("strnn.control_remove", text="", icon="REMOVE")
        if 0 <= obj.strnn_control_index < len(obj.strnn_controls):
            item = obj.strnn_controls[obj.strnn_control_index]
            row = layout.row(align=True)
            row.prop(item, "role", text="")
            row.prop_search(item, "switch", obj.data, "bones", text="", icon="CON_ACTION")
        layout.operator("strnn.controls_from_preset", icon="PRESET")
        if len(obj.strnn_switches):
            box = layout.box()
            box.label(text="Switches keyed on the new frames (value: FK; IK value, pole property)")
            for sw in obj.strnn_switches:
                col = box.column(align=True)
                row = col.row(align=True)
                row.prop(sw, "bone", text="")
                row.prop(sw, "prop", text="")
                row.prop(sw, "value", text="")
                if any(c.switch == sw.bone and c.role in controls.rig_controls.IK_ROLES for c in obj.strnn_controls):
                    row = col.row(align=True)
                    row.prop(sw, "ik_value", text="IK")
                    row.prop(sw, "pole_prop", text="", icon="EMPTY_SINGLE_ARROW")


class STRNN_MT_menu(bpy.types.Menu):
    """STRNN operators in the Object > Animation and Pose menus (so F3 search finds them)."""

    bl_label = "STRNN Motion"

    def draw(self, context):
        layout = self.layout
        layout.operator("strnn.extend_clip", icon="TRACKING_FORWARDS")
        layout.operator("strnn.inbetween", icon="IPO_EASE_IN_OUT")
        layout.operator("strnn.denoise_action", icon="MOD_SMOOTH")
        layout.operator("strnn.foot_lock", icon="SNAP_ON")
        layout.operator("strnn.make_loop", icon="FILE_REFRESH")
        layout.operator("strnn.follow_curve", icon="CURVE_PATH")
        layout.operator("strnn.transfer_motion", icon="ARMATURE_DATA")
        layout.separator()
        layout.operator("strnn.check_motion", icon="VIEWZOOM")
        layout.operator("strnn.auto_map", icon="AUTOMERGE_ON")


def menu_entry(self, context):
    self.layout.menu("STRNN_MT_menu")


def key_menu_entry(self, context):
    """Extend, Fill Gap, Foot Lock and Make Loop where animators key and time: the Dope Sheet's and Graph
    Editor's Key menus and the NLA's strip menu."""
    layout = self.layout
    layout.separator()
    layout.operator("strnn.extend_clip", icon="TRACKING_FORWARDS")
    layout.operator("strnn.inbetween", icon="IPO_EASE_IN_OUT")
    layout.operator("strnn.foot_lock", icon="SNAP_ON")
    layout.operator("strnn.make_loop", icon="FILE_REFRESH")


def smoothing_menu_entry(self, context):
    """Denoise beside Blender's own smoothing filters (Graph Editor > Key > Smoothing)."""
    self.layout.separator()
    self.layout.operator("strnn.denoise_action", icon="MOD_SMOOTH")


# (menu, entry): the Object/Pose menus, the editors' Key menus, the NLA strip menu (its 4.2 name
# was NLA_MT_edit) and the Graph Editor's Smoothing menu. A menu a Blender version lacks is skipped.
MENUS = (("VIEW3D_MT_object_animation", menu_entry), ("VIEW3D_MT_pose", menu_entry),
         ("DOPESHEET_MT_key", key_menu_entry), ("GRAPH_MT_key", key_menu_entry),
         ("NLA_MT_strips", key_menu_entry), ("NLA_MT_edit", key_menu_entry),
         ("GRAPH_MT_key_smoothing", smoothing_menu_entry))


def register_menus():
    for name, entry in MENUS:
        if hasattr(bpy.types, name):
            getattr(bpy.types, name).append(entry)


def unregister_menus():
    for name, entry in MENUS:
        if hasattr(bpy.types, name):
            getattr(bpy.types, name).remove(entry)


classes = (STRNN_PT_main, STRNN_PT_extend, STRNN_PT_fill_gap, STRNN_PT_denoise, STRNN_PT_foot_lock,
           STRNN_PT_loop, STRNN_PT_follow_curve, STRNN_PT_transfer, STRNN_PT_bone_map, STRNN_UL_controls,
           STRNN_PT_controls, STRNN_MT_menu)

