"""Properties: the operators' options (defined once), the bone map and controls stored on the armature object and
the add-on preferences."""

from __future__ import annotations

import importlib.util
import textwrap

import bpy
from bpy.props import (
    BoolProperty,
    CollectionProperty,
    EnumProperty,
    FloatProperty,
    IntProperty,
    PointerProperty,
    StringProperty,
)

from ..model_core.motion.conventions import JOINTS
from ..model_core.ops import options as opts
from . import engine_bridge

ADDON_ID = __package__.rpartition(".")[0]  # the extension's module, e.g. bl_ext.user_default.strnn_motion
TAIL_JOINTS = ("hips", "l_toe", "r_toe", "l_fingertip", "r_fingertip")  # an MMD model's hips: its lower body's tail


# ------------------------------------------------------------------ options
# Each option lives on its operator: the sidebar shows and edits the operator's remembered values
# (``WindowManager.operator_properties_last``), which are also what F3, the menus and the redo panel
# use. The options the batch CLI also takes are declared once in ``model_core/ops/options.py``.

def frames_to_add():
    return IntProperty(**opts.EXTEND_FRAMES.blender())


def context_frames():
    return IntProperty(**opts.CONTEXT_FRAMES.blender())


def follow_clip():
    return BoolProperty(**opts.FOLLOW_CLIP.blender())


def follow_take():
    return BoolProperty(**opts.FOLLOW_TAKE.blender())


def from_current():
    return BoolProperty(name="From Current Frame", default=False,
                        description="Continue after the current frame instead of the action's last, replacing "
                                    "the mapped bones' keys after it (before it, with Before the Start)")


def before_start():
    return BoolProperty(**opts.BEFORE_START.blender())


def scene_range():
    return BoolProperty(name="Extend Scene Range", default=True,
                        description="Move the scene's end frame to the new action's end when it goes beyond it (its "
                                    "start frame to the new start, frames added before it); the report says so either "
                                    "way")


def only_selected():
    return BoolProperty(name="Only Selected Bones", default=False,
                        description="Write new keys only on the selected bones; the others keep their keys exactly")


def foot_lock(operator: str):
    """``operator``: the operator's name (``extend_clip``, ...), whose default :data:`options.FOOT_LOCK` gives."""
    return BoolProperty(name="Foot Lock", default=opts.FOOT_LOCK[operator], description=opts.FOOT_LOCK_TIP)


def strength():
    return FloatProperty(subtype="FACTOR", **opts.STRENGTH.blender())


def output():
    return EnumProperty(name="Result", default="ACTION",
                        items=[("ACTION", "New Action", "Assign the result as a new action in place of the active one "
                                "(which is kept)"),
                               ("NLA", "NLA Strip", "Put the result on a new NLA track as a strip; the active action "
                                "stays active and unchanged")],
                        description="Where the result goes")


def simplify():
    return FloatProperty(name="Simplify Keys", default=0.0, min=0.0, soft_max=5.0, precision=2,
                         description="Keep only the keys that hold every joint within this many centimetres of the "
                                     "full result (Clean Curves measured on the joints); 0: a key on every frame")


def use_range(verb: str):
    """``verb``: what the operator does to the frames, e.g. "Denoise"."""
    return BoolProperty(name="Frame Range", default=False,
                        description=f"{verb} only Start to End instead of the whole action")


def range_start(verb: str):
    return IntProperty(name="Start", default=1, description=f"First frame to {verb.lower()}")


def range_end(verb: str):
    return IntProperty(name="End", default=250, description=f"Last frame to {verb.lower()}")


def lock_blend():
    return FloatProperty(unit="TIME_ABSOLUTE", **opts.LOCK_BLEND.blender())


def loop_blend():
    return FloatProperty(unit="TIME_ABSOLUTE", **opts.LOOP_BLEND.blender())


def loop_match():
    return BoolProperty(**opts.LOOP_MATCH.blender())


def loop_in_place():
    return BoolProperty(**opts.LOOP_IN_PLACE.blender())


def root_motion():
    return BoolProperty(**opts.ROOT_MOTION.blender())


def curve_frames():
    return IntProperty(**opts.CURVE_FRAMES.blender())


def curve_speed():
    return FloatProperty(unit="VELOCITY", **opts.CURVE_SPEED.blender())


def _objects_of(kind: str, exclude_active: bool = False, exclude_body: bool = False):
    """A search list of the scene's objects of ``kind`` (for a name option's drop-down); ``exclude_body``: not the
    meshes the active armature deforms (its own body)."""

    def search(self, context, edit_text):
        from .scene.ground import deforms

        active = context.active_object if exclude_active else None
        body = context.active_object if exclude_body else None
        found = [o.name for o in context.scene.objects
                 if o.type == kind and o is not active and edit_text.lower() in o.name.lower()
                 and not (body is not None and deforms(body, o))]
        if exclude_body:  # the ground: a collection of meshes as well (a floor and the stairs on it)
            found += [c.name for c in bpy.data.collections if edit_text.lower() in c.name.lower()
                      and any(o.type == kind and not deforms(body, o) for o in c.all_objects)]
        return found

    return search


def curve_name():
    return StringProperty(name="Curve", default="", search=_objects_of("CURVE"),
                          description="The curve object to walk along (Bezier, NURBS or poly; its centre line); "
                                      "empty: the selected curve")


def ground_name(walk: bool = False):
    what = ("the motion goes up and down with its surface under the hips, and Foot Lock pins each heel and toe "
            "on it" if walk else "each heel and toe is pinned on its surface under the foot")
    return StringProperty(name="Ground", default="", search=_objects_of("MESH", exclude_body=True),
                          description=f"A mesh the feet stand on (stairs, a slope, terrain), or a collection of "
                                      f"meshes: {what}, as they stand at the current frame; empty: one flat floor, "
                                      "the take's own")


def source_name():
    return StringProperty(name="Source", default="", search=_objects_of("ARMATURE", exclude_active=True),
                          description="The armature to take the motion from; empty: the other selected armature")


def joint_label(joint: str) -> str:
    """``"l_upleg"`` -> ``"Left Upleg"``."""
    side = {"l": "Left ", "r": "Right "}.get(joint[:1], "") if joint[1:2] == "_" else ""
    word = joint[2:] if side else joint
    return side + word.replace("1", " 1").title()


def _map_annotations() -> dict:
    ann = {}
    for joint in JOINTS:
        ann[joint] = StringProperty(name=joint_label(joint), override={"LIBRARY_OVERRIDABLE"},
                                    description=f"Bone whose head is the canonical {joint_label(joint)} joint")
    for joint in TAIL_JOINTS:
        ann[f"{joint}_tail"] = BoolProperty(
            name="Tail", description=f"The {joint_label(joint)} joint is the bone's tail, not its head",
            override={"LIBRARY_OVERRIDABLE"})
    ann["family"] = StringProperty(name="Rig Family", description="The rig family the last auto-map recognised",
                                   override={"LIBRARY_OVERRIDABLE"})
    return ann


STRNN_PG_bone_map = type("STRNN_PG_bone_map", (bpy.types.PropertyGroup,), {
    "__annotations__": _map_annotations(),
    "__doc__": "Which bone carries each of the 21 canonical joints (saved with the armature object)",
})


# The roles of model_core/rig/controls.py's ROLES, as the Controls list offers them (icons shown in the list).
CONTROL_ROLES = [
    ("FK", "FK", "Keyed always, or with a Switch where its limb is animated in FK", "BONE_DATA", 0),
    ("MOVE", "Move", "Moved, never turned, keyed as FK is (a centre that carries the body while the bones below it "
                     "turn it: an MMD model's センター)", "EMPTY_ARROWS", 5),
    ("IK_END", "IK End", "The IK chain's end (the foot or hand IK control): moved and turned where its limb is in IK "
                         "(with no Switch: always, a limb that never leaves IK)", "CON_KINEMATIC", 1),
    ("IK_BASE", "IK Base", "The IK chain's base (thigh or upper arm IK): turned about its own axis to set the knee's "
                           "or elbow's plane, where its limb is in IK and its pole is not used", "CON_ROTLIKE", 2),
    ("IK", "IK", "Another control of the IK limb (a toe), turned where its limb is in IK", "CON_ROTLIKE", 3),
    ("POLE", "Pole", "The IK pole: moved in front of the knee or elbow where its limb is in IK",
     "EMPTY_SINGLE_ARROW", 4)]


class STRNN_PG_control(bpy.types.PropertyGroup):
    """A control bone and the mapped bone it drives (results are keyed on the control)"""

    bone: StringProperty(name="Control", description="The bone the animator keys", override={"LIBRARY_OVERRIDABLE"})
    drives: StringProperty(name="Drives", override={"LIBRARY_OVERRIDABLE"},
                           description="The mapped bone (or the bone between two mapped ones) that follows it")
    location: BoolProperty(name="Moves", default=False, override={"LIBRARY_OVERRIDABLE"},
                           description="Also key the control's location (the body's root control)")
    role: EnumProperty(
        name="Role", default="FK", override={"LIBRARY_OVERRIDABLE"}, items=CONTROL_ROLES,
        description="What the control is for: keyed always (or, with a Switch, where its limb is in FK), or one of "
                    "the IK controls keyed where its limb is animated in IK")
    switch: StringProperty(name="Switch", override={"LIBRARY_OVERRIDABLE"},
                           description="The bone of the IK/FK switch (in the switch list) of the limb this control "
                                       "belongs to; empty: it is keyed always, in its role (an IK control of a limb "
                                       "that never leaves IK, as an MMD model's legs)")


class STRNN_PG_switch(bpy.types.PropertyGroup):
    """A custom property keyed to a value on the written frames (e.g. an IK/FK switch set to FK)"""

    bone: StringProperty(name="Bone", description="The bone holding the property", override={"LIBRARY_OVERRIDABLE"})
    prop: StringProperty(name="Property", description="The custom property's name, e.g. IK_FK",
                         override={"LIBRARY_OVERRIDABLE"})
    value: FloatProperty(name="Value", default=1.0, override={"LIBRARY_OVERRIDABLE"},
                         description="The value it is keyed to on the written frames (where its limb has no IK "
                                     "controls in the list, or is animated in FK)")
    ik_value: FloatProperty(name="IK Value", default=0.0, override={"LIBRARY_OVERRIDABLE"},
                            description="The value that puts its limb in IK: where the action leaves the switch "
                                        "nearer it, the limb's IK controls are keyed and the switch kept there")
    pole_prop: StringProperty(name="Pole Property", override={"LIBRARY_OVERRIDABLE"},
                              description="The property of the same bone that turns the limb's pole on (Rigify's "
                                          "pole_vector); empty: the limb's Pole control, if any, is always used")


def _engines(self, context):
    items = [("NUMPY", "NumPy", "Run the model with NumPy (works in every Blender)")]
    # Found, not imported: reading this setting must not load PyTorch (some 170 MB) when NumPy runs the model.
    if importlib.util.find_spec("torch") is not None:
        items.append(("TORCH", "PyTorch", "Run the model with PyTorch (installed in this Blender)"))
    return items


class STRNN_AP_preferences(bpy.types.AddonPreferences):
    bl_idname = ADDON_ID

    model_folder: StringProperty(
        name="Model Folder", subtype="DIR_PATH", default="",
        description="Folder with model.safetensors and model.json; empty: the bundled model")
    denoise_model_folder: StringProperty(
        name="Denoise Model Folder", subtype="DIR_PATH", default="",
        description="Model that Denoise uses; empty: the bundled denoising model (or the Model Folder's "
                    "model when the extension ships none)")
    engine: EnumProperty(name="Engine", items=_engines, description="Which library runs the model")
    threads: IntProperty(name="Threads", default=0, min=0, max=256,
                         description="CPU threads for the model; 0: as many as Blender uses")

    def draw(self, context):
        col = self.layout.column()
        col.prop(self, "model_folder")
        col.prop(self, "denoise_model_folder")
        col.prop(self, "engine")
        col.prop(self, "threads")
        draw_models(self.layout, self)


def draw_models(layout, prefs) -> None:
    """Which model each operation uses, and its licence (the bundled ones are non-commercial)."""
    box = layout.box()
    for ops, purpose, setting in (("Extend, Follow Curve", "generate", "Model Folder"),
                                  ("Denoise", "denoise", "Denoise Model Folder")):
        folder = engine_bridge.model_used(prefs, purpose)
        if not folder:
            box.label(text=f"{ops}: no model in the {setting}", icon="ERROR")
            continue
        card = engine_bridge.model_card(folder)
        box.label(text=f"{ops}: {card['name']}", icon="OUTLINER_DATA_ARMATURE")
        col = box.column(align=True)
        if card["non_commercial"]:
            col.label(text="Non-commercial use only (its training data's licence)", icon="ERROR")
        for line in textwrap.wrap(f"Licence: {card['licence']}", 90):
            col.label(text=line)


def preferences(context):
    """This add-on's preferences, or None when not registered as an add-on (tests import it bare)."""
    addon = context.preferences.addons.get(ADDON_ID)
    return addon.preferences if addon else None


classes = (STRNN_PG_bone_map, STRNN_PG_control, STRNN_PG_switch, STRNN_AP_preferences)


def register_properties():
    bpy.types.Object.strnn_map = PointerProperty(type=STRNN_PG_bone_map, override={"LIBRARY_OVERRIDABLE"})
    bpy.types.Object.strnn_controls = CollectionProperty(
        type=STRNN_PG_control, override={"LIBRARY_OVERRIDABLE", "USE_INSERTION"},
        description="The controls results are keyed on (empty: the shipped preset the rig fits, if any)")
    bpy.types.Object.strnn_switches = CollectionProperty(
        type=STRNN_PG_switch, override={"LIBRARY_OVERRIDABLE", "USE_INSERTION"},
        description="Custom properties keyed on the written frames so that the controls act")
    bpy.types.Object.strnn_control_index = IntProperty(default=0, override={"LIBRARY_OVERRIDABLE"})
    bpy.types.Object.strnn_keys_per_second = FloatProperty(
        name="Keys per Second", default=0.0, min=0.0, soft_max=240.0, override={"LIBRARY_OVERRIDABLE"},
        description="How many of the action's frames make one second of its motion, when it differs from the "
                    "scene's frame rate (a 60 fps take imported at 24 fps: 60); 0: the scene's rate")


def unregister_properties():
    del bpy.types.Object.strnn_keys_per_second
    del bpy.types.Object.strnn_control_index
    del bpy.types.Object.strnn_switches
    del bpy.types.Object.strnn_controls
    del bpy.types.Object.strnn_map
