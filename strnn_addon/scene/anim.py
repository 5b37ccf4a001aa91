"""Actions across Blender versions, and keys written in bulk.

Blender 4.2 keeps F-curves on ``action.fcurves`` (legacy actions). From 4.4 actions are
layered: F-curves live in a channelbag per slot (``layers[0].strips[0].channelbag(slot)``);
5.0 has only that API. :class:`Channels` hides the difference.
"""

from __future__ import annotations

import bpy
import numpy as np


def is_layered(action) -> bool:
    """Whether ``action`` keeps its F-curves in slots and channelbags."""
    if not hasattr(action, "slots"):
        return False  # Blender 4.2
    return bpy.app.version >= (5, 0, 0) or bool(getattr(action, "is_action_layered", False))


class Channels:
    """The F-curves an object's action drives: ``fcurves`` (a collection) and, for layered
    actions, the ``channelbag`` that owns them (where groups live)."""

    def __init__(self, action, anim_data, ensure: bool = False):
        self.action = action
        self.channelbag = None
        if not is_layered(action):
            self.fcurves = action.fcurves
            return
        slot = _slot_for(action, anim_data)
        from bpy_extras import anim_utils

        if ensure:
            if slot is None:
                slot = action.slots.new(id_type="OBJECT", name="STRNN")
            self.channelbag = ensure_channelbag(action, slot)
        else:
            self.channelbag = anim_utils.action_get_channelbag_for_slot(action, slot) if slot else None
        self.fcurves = self.channelbag.fcurves if self.channelbag else ()

    def find(self, data_path: str, index: int):
        return next((fc for fc in self.fcurves if fc.data_path == data_path and fc.array_index == index), None)

    def ensure(self, data_path: str, index: int, group: str):
        """The F-curve for ``data_path[index]``, created in ``group`` if missing."""
        fc = self.find(data_path, index)
        if fc is not None:
            return fc
        if self.channelbag is None:
            return self.action.fcurves.new(data_path, index=index, action_group=group)
        fc = self.channelbag.fcurves.new(data_path, index=index)
        grp = self.channelbag.groups.get(group) or self.channelbag.groups.new(group)
        fc.group = grp
        return fc


def bone_path(bone: str, prop: str) -> str:
    """The F-curve data path of a pose bone's property."""
    return f'pose.bones["{bpy.utils.escape_identifier(bone)}"].{prop}'


def active_fcurves(obj) -> list:
    """The F-curves of ``obj``'s active action on its slot (none where it has no action)."""
    ad = obj.animation_data
    return list(Channels(ad.action, ad).fcurves) if ad is not None and ad.action is not None else []


def _slot_for(action, anim_data):
    """The slot of ``action`` the object of ``anim_data`` animates through: its own slot where ``action`` is its
    action; in a copy of its action not yet assigned (a new action being written), the slot named like its own,
    so that an action shared by several objects, each on a slot of its own, gets the keys in the right one; else
    the first slot (None where there is none)."""
    current = getattr(anim_data, "action_slot", None) if anim_data else None
    if current is not None:
        if anim_data.action == action:
            return current
        same = next((s for s in action.slots if s.identifier == current.identifier), None)
        if same is not None:
            return same
    return action.slots[0] if len(action.slots) else None


def ensure_channelbag(action, slot):
    """The channelbag of ``slot`` in ``action``'s first keyframe strip, made if missing (Blender 5.0 has
    ``anim_utils.action_ensure_channelbag_for_slot``; 4.4 and 4.5 have the layer and strip API only)."""
    from bpy_extras import anim_utils

    if hasattr(anim_utils, "action_ensure_channelbag_for_slot"):
        return anim_utils.action_ensure_channelbag_for_slot(action, slot)
    layer = action.layers[0] if len(action.layers) else action.layers.new("Layer")
    strip = layer.strips[0] if len(layer.strips) else layer.strips.new(type="KEYFRAME")
    return strip.channelbag(slot, ensure=True)


def slot_of(obj):
    """The action slot an object uses (None before Blender 4.4)."""
    ad = obj.animation_data
    return getattr(ad, "action_slot", None) if ad else None


def assign_action(obj, action, slot_identifier: str | None) -> None:
    """Make ``action`` the object's active action, on the slot named like the old one."""
    ad = obj.animation_data or obj.animation_data_create()
    ad.action = action
    if slot_identifier and hasattr(ad, "action_slot"):
        slot = next((s for s in action.slots if s.identifier == slot_identifier), None)
        if slot is not None:
            ad.action_slot = slot


def _read_keys(fc) -> dict[str, np.ndarray]:
    """All key attributes of an F-curve that matter for its shape, as arrays."""
    n = len(fc.keyframe_points)
    out = {}
    for attr, width, dtype in (("co", 2, np.float32), ("handle_left", 2, np.float32),
                               ("handle_right", 2, np.float32), ("interpolation", 1, np.int32),
                               ("handle_left_type", 1, np.int32), ("handle_right_type", 1, np.int32)):
        buf = np.empty(n * width, dtype=dtype)
        fc.keyframe_points.foreach_get(attr, buf)
        out[attr] = buf.reshape(n, width) if width > 1 else buf
    return out


def write_keys(fc, frames: np.ndarray, values: np.ndarray, replace: tuple[float, float] | None = None,
               interpolation: str = "") -> None:
    """Key ``values`` ``[F]`` at ``frames`` ``[F]`` in bulk.

    Existing keys stay, except those in the closed frame range ``replace`` (and any at the
    new frames). New keys take ``interpolation`` (e.g. ``"LINEAR"``), else that of the curve's
    last key (linear if none).
    """
    if replace is None and not interpolation and _append(fc, frames, values):
        return
    old = _read_keys(fc)
    x = old["co"][:, 0]
    drop = np.isin(np.round(x, 3), np.round(frames, 3))
    if replace is not None:
        drop |= (x >= replace[0] - 1e-3) & (x <= replace[1] + 1e-3)
    keep = {k: v[~drop] for k, v in old.items()}
    interp = int(old["interpolation"][-1]) if len(x) else 1  # 1 = LINEAR
    if interpolation:
        interp = bpy.types.Keyframe.bl_rna.properties["interpolation"].enum_items[interpolation].value
    co = np.stack([frames, values], -1).astype(np.float32)
    new = {"co": co, "handle_left": co, "handle_right": co,
           "interpolation": np.full(len(frames), interp, np.int32),
           "handle_left_type": np.full(len(frames), _auto_clamped(), np.int32),
           "handle_right_type": np.full(len(frames), _auto_clamped(), np.int32)}
    merged = {k: np.concatenate([keep[k], new[k]]) for k in new}
    order = np.argsort(merged["co"][:, 0], kind="stable")
    points = fc.keyframe_points
    points.clear()
    points.add(len(order))
    for attr, arr in merged.items():
        points.foreach_set(attr, np.ascontiguousarray(arr[order]).ravel())
    fc.update()
    _keep_handles(fc, keep)


def keep_between(fc, first: float, last: float) -> None:
    """Delete the keys of ``fc`` before frame ``first`` and after ``last`` in bulk; the rest stay as they were (their
    handles too)."""
    old = _read_keys(fc)
    x = old["co"][:, 0]
    inside = (x >= first - 1e-3) & (x <= last + 1e-3)
    if inside.all():
        return
    points = fc.keyframe_points
    points.clear()
    points.add(int(inside.sum()))
    for attr, arr in old.items():
        points.foreach_set(attr, np.ascontiguousarray(arr[inside]).ravel())
    fc.update()


def _append(fc, frames: np.ndarray, values: np.ndarray) -> bool:
    """Fast path of :func:`write_keys` when every new key lies after the last one: add the points,
    set positions and interpolation, and let Blender recompute the automatic handles."""
    points = fc.keyframe_points
    n = len(points)
    co = np.empty(2 * n, dtype=np.float32)
    points.foreach_get("co", co)
    if n and frames[0] <= co[-2] + 1e-3:
        return False
    before = _read_keys(fc)
    interp = np.empty(n, dtype=np.int32)
    points.foreach_get("interpolation", interp)
    new_interp = int(interp[-1]) if n else 1  # 1 = LINEAR
    points.add(len(frames))
    new_co = np.stack([frames, values], -1).astype(np.float32).ravel()
    points.foreach_set("co", np.concatenate([co, new_co]))
    points.foreach_set("interpolation", np.concatenate([interp, np.full(len(frames), new_interp, np.int32)]))
    for attr in ("handle_left", "handle_right"):  # start the new handles on their keys; update() smooths them
        buf = np.empty(2 * (n + len(frames)), dtype=np.float32)
        points.foreach_get(attr, buf)
        buf[2 * n:] = new_co
        points.foreach_set(attr, buf)
    fc.update()
    _keep_handles(fc, before)
    return True


def _keep_handles(fc, kept: dict[str, np.ndarray]) -> None:
    """Give the keys of ``kept`` (:func:`_read_keys` of the keys that were there before) back the handles they had,
    where Blender's automatic handles moved them because a neighbour came or went: the curve between two kept keys
    then stays as it was (a hand-keyed pass keeps its last stretch when keys follow it). Such a key's handles
    become free (they no longer follow their neighbours)."""
    if not len(kept["co"]):
        return
    now = _read_keys(fc)
    at = np.searchsorted(now["co"][:, 0], kept["co"][:, 0])
    at = np.clip(at, 0, len(now["co"]) - 1)
    same = np.abs(now["co"][at, 0] - kept["co"][:, 0]) < 1e-3
    moved = same & ((np.abs(now["handle_left"][at] - kept["handle_left"]).max(1) > 1e-6)
                    | (np.abs(now["handle_right"][at] - kept["handle_right"]).max(1) > 1e-6))
    if not moved.any():
        return
    free = bpy.types.Keyframe.bl_rna.properties["handle_left_type"].enum_items["FREE"].value
    idx = at[moved]
    for attr in ("handle_left_type", "handle_right_type"):
        now[attr][idx] = free
    for attr in ("handle_left", "handle_right"):
        now[attr][idx] = kept[attr][moved]
    points = fc.keyframe_points
    for attr in ("handle_left_type", "handle_right_type", "handle_left", "handle_right"):
        points.foreach_set(attr, np.ascontiguousarray(now[attr]).ravel())


def _auto_clamped() -> int:
    items = bpy.types.Keyframe.bl_rna.properties["handle_left_type"].enum_items
    return items["AUTO_CLAMPED"].value
