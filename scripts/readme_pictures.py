#!/usr/bin/env python3
"""Pictures of each operator for the README, made by the real extension inside Blender.

Installs the built extension zip into the ``bpy`` module (a temporary user repository, as
scripts/strnn_batch.py does), imports motion-capture clips with Blender's own BVH importer,
runs the operators (strnn.extend_clip, strnn.denoise_action, strnn.foot_lock,
strnn.follow_curve) on the armatures, reads the bones back in world space frame by frame and
draws them (matplotlib) into --out:

- extend.png: the clip (grey) and its continuation (blue), seen from the side and above;
- denoise.png: a clip with Gaussian jitter of 1.5 degrees on every rotation channel, denoised,
  against the clean clip (a wrist's height over time and the error per frame, measured here);
- inbetween.png: a 30-frame gap cut out of a take, filled by Blender's own F-curve interpolation
  and by Fill Gap, beside the true motion;
- footlock.png: a foot's ground speed and path before and after the lock;
- follow.png: a walk along a figure-eight curve, from above and from the side;
- ground.png: a walk along a straight line over a hill, the hill as Follow Curve's Ground;
- bonemap.png: what Auto-Map Bones finds on BVH imports of three rig families.

The clips come from the project's own test split (``--data``, default data/mocap, unpacked
from ../shared/mocap); the printed figures are measured in the same run.

    .venv/bin/python scripts/readme_pictures.py --out docs/images
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "scripts"))

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from model_core.eval.plots import body_view, joint_colour
from model_core.motion.conventions import JOINTS, PARENTS
from model_core.motion.features import detect_contacts
from model_core.ops.footlock import foot_skate_cm

PICTURES = ("extend", "inbetween", "denoise", "footlock", "loop", "follow", "ground", "bonemap", "your_rig")
BANDAI_SCALE = 0.01  # the Bandai-Namco files are in centimetres: import them in metres
EXTEND_CLIP = "bandai-namco/dataset-2/dataset-2_walk-turn-right_normal_004.bvh"
DENOISE_CLIP = "bandai-namco/dataset-2/dataset-2_wave-left-hand_feminine_018.bvh"
FOLLOW_CLIP = "bandai-namco/dataset-2/dataset-2_walk_active_011.bvh"
BONE_MAP_CLIPS = (("Bandai-Namco", "bandai-namco/dataset-2/dataset-2_walk_active_011.bvh", BANDAI_SCALE),
                  ("CMU, iClone CC_Base", "cmu/iclone/002_01.bvh", 1.0),
                  ("CMU, acRNN 43 joints", "cmu/acrnn-dance/indian/04.bvh", 1.0))
NEW = "#1f77b4"


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", type=Path, default=REPO / "data" / "mocap", help="unpacked motion-capture folder")
    p.add_argument("--out", type=Path, default=REPO / "docs" / "images", help="folder for the PNG files")
    p.add_argument("--extension", type=Path, default=None, help="extension zip (default: built into a temp folder)")
    p.add_argument("--seed", type=int, default=0, help="noise seed of the denoise picture")
    p.add_argument("--only", nargs="+", choices=PICTURES, default=list(PICTURES), metavar="NAME",
                   help=f"make only these pictures (of: {', '.join(PICTURES)})")
    return p.parse_args(argv)


# ------------------------------------------------------------------ Blender side
def start_blender(zip_path: Path, user_dir: Path):
    import batch_worker
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    batch_worker.install_extension(bpy, str(zip_path), user_dir)
    return bpy


def import_bvh(bpy, path: Path, scale: float = 1.0):
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.import_anim.bvh(filepath=str(path), global_scale=scale, update_scene_fps=True,
                            update_scene_duration=True)
    obj = bpy.context.view_layer.objects.active
    obj.select_set(True)
    return obj


def action_range(obj) -> tuple[int, int]:
    start, end = obj.animation_data.action.frame_range
    return int(round(start)), int(round(end))


def sample(bpy, obj, start: int, end: int) -> tuple[np.ndarray, list[str]]:
    """World-space bone heads and tails ``[F, bones, 2, 3]`` (Blender Z-up metres) and the bone names."""
    scene = bpy.context.scene
    names = [b.name for b in obj.pose.bones]
    out = np.empty((end - start + 1, len(names), 2, 3))
    for i, frame in enumerate(range(start, end + 1)):
        scene.frame_set(frame)
        m = obj.matrix_world
        for j, pb in enumerate(obj.pose.bones):
            out[i, j, 0], out[i, j, 1] = m @ pb.head, m @ pb.tail
    return out, names


# ------------------------------------------------------------------ drawing
COLOURS = [joint_colour(j) for j in JOINTS]


def draw_pose(ax, joints: np.ndarray, axes=(0, 2), alpha=1.0, colour=None, lw=1.4):
    """One skeleton ``[21, 3]`` (Z-up) projected on two world ``axes``, coloured by side (left blue, right red)."""
    for j, parent in enumerate(PARENTS):
        if parent >= 0:
            a, b = joints[parent], joints[j]
            ax.plot([a[axes[0]], b[axes[0]]], [a[axes[1]], b[axes[1]]], color=colour or COLOURS[j], alpha=alpha,
                    lw=lw, solid_capstyle="round")


def ghosts(ax, joints: np.ndarray, every: int, axes, colour=None, alpha=(0.25, 1.0)):
    idx = list(range(0, len(joints), every)) + [len(joints) - 1]
    for k, i in enumerate(idx):
        a = alpha[0] + (alpha[1] - alpha[0]) * k / max(len(idx) - 1, 1)
        draw_pose(ax, joints[i], axes, a, colour)


def filmstrip(ax, joints: np.ndarray, frames: list[int], spacing: float, colour=None, first_slot: int = 0):
    """Skeletons ``[F, 21, 3]`` (Z-up) side by side, each seen from its own side
    (:func:`model_core.eval.plots.body_view`), hips at slot * ``spacing``."""
    flat = body_view(z_up_to_model(joints))[frames]  # (len(frames), 21, 2)
    for slot, pose in enumerate(flat, first_slot):
        draw_pose(ax, np.stack([pose[:, 0] + slot * spacing, np.zeros(len(pose)), pose[:, 1]], -1), (0, 2), 1.0,
                  colour)


def joints_z_up(obj, poses: np.ndarray, names: list[str]) -> np.ndarray:
    """The 21 canonical joints ``[F, 21, 3]`` in Blender's axes (Z-up) through the extension's bone map."""
    bone_map = obj.strnn_map
    cols = [(names.index(getattr(bone_map, j)), int(getattr(bone_map, f"{j}_tail", False))) for j in JOINTS]
    return np.stack([poses[:, b, end] for b, end in cols], 1)


def z_up_to_model(z_up: np.ndarray) -> np.ndarray:
    """Blender's axes (Z-up) -> the model's (Y-up): ``[..., 3]``."""
    return np.stack([z_up[..., 0], z_up[..., 2], -z_up[..., 1]], -1)


def canonical(obj, poses: np.ndarray, names: list[str]) -> np.ndarray:
    """The 21 canonical joints ``[F, 21, 3]`` in the model's axes (Y-up metres)."""
    return z_up_to_model(joints_z_up(obj, poses, names))


def bone_of(obj, names: list[str], joint: str) -> int:
    """Index in ``names`` of the bone the extension's bone map (filled by the operators) gives ``joint``."""
    return names.index(getattr(obj.strnn_map, joint))


def finish(fig, path: Path):
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)
    print(f"wrote {path}")


# ------------------------------------------------------------------ pictures
def picture_extend(bpy, clip: Path, out: Path, frames: int = 150) -> dict:
    obj = import_bvh(bpy, clip, BANDAI_SCALE)
    start, end = action_range(obj)
    bpy.ops.strnn.extend_clip(frames=frames)
    poses, names = sample(bpy, obj, start, end + frames)
    joints = joints_z_up(obj, poses, names)
    old, new = joints[: end - start + 1], joints[end - start + 1:]
    fig, (side, top) = plt.subplots(1, 2, figsize=(14, 3.4), gridspec_kw={"width_ratios": [3, 1]})
    shown_old = list(range(len(old) - 1 - 4 * 10, len(old), 10))
    shown_new = list(range(9, len(new), 10))
    filmstrip(side, old, shown_old, 0.6, colour="#9a9a9a")
    filmstrip(side, new, shown_new, 0.6, first_slot=len(shown_old))
    side.axhline(0, color="k", lw=0.6)
    side.set_aspect("equal")
    side.axis("off")
    side.set_title("every 10th frame, each seen from its side: the clip's last frames (grey), then the new ones",
                   fontsize=9)
    top.plot(old[:, 0, 0], old[:, 0, 1], color="#9a9a9a", lw=2, label=f"clip ({len(old)} frames)")
    top.plot(new[:, 0, 0], new[:, 0, 1], color=NEW, lw=2, label=f"Extend Clip (+{len(new)} frames)")
    top.set_aspect("equal")
    top.grid(alpha=0.3)
    top.set_title("hips path from above (m)", fontsize=9)
    top.legend(loc="best", fontsize=8)
    fig.suptitle(f"Extend Clip: {clip.name} (a test-split take) continued by {frames} frames")
    finish(fig, out / "extend.png")
    return {"clip": clip.name, "frames": frames}


def add_jitter(obj, degrees: float, seed: int) -> None:
    """Gaussian jitter of ``degrees`` (std) on every keyed Euler rotation channel of ``obj``'s action:
    noisy capture. The F-curves come from the installed extension's own reader (layered or legacy)."""
    import batch_worker

    anim = importlib.import_module(f"{batch_worker.ADDON}.strnn_addon.scene.anim")
    rng = np.random.default_rng(seed)
    for fc in anim.Channels(obj.animation_data.action, obj.animation_data).fcurves:
        if fc.data_path.endswith("rotation_euler"):
            for key in fc.keyframe_points:
                key.co[1] += float(rng.normal(0.0, np.radians(degrees)))
                key.interpolation = "LINEAR"
            fc.update()


def picture_denoise(bpy, clip: Path, out: Path, seed: int, degrees: float = 1.5) -> dict:
    obj = import_bvh(bpy, clip, BANDAI_SCALE)
    start, end = action_range(obj)
    clean, names = sample(bpy, obj, start, end)
    add_jitter(obj, degrees, seed)
    before, _ = sample(bpy, obj, start, end)
    bpy.ops.strnn.denoise_action()
    after, _ = sample(bpy, obj, start, end)
    ref = canonical(obj, clean, names)
    err = {k: np.linalg.norm(canonical(obj, v, names) - ref, axis=-1).mean(-1) * 100
           for k, v in (("noisy", before), ("denoised", after))}
    wrist = bone_of(obj, names, "l_wrist")
    t = np.arange(len(clean)) / 30.0
    fig, (a, b) = plt.subplots(1, 2, figsize=(13, 3.8))
    a.plot(t, before[:, wrist, 0, 2], color="#bbbbbb", lw=1,
           label=f"noisy input ({degrees:g} degree jitter per channel)")
    a.plot(t, clean[:, wrist, 0, 2], color="k", lw=1.6, label="clean capture")
    a.plot(t, after[:, wrist, 0, 2], color=NEW, lw=1.6, label="Denoise Action")
    a.set_xlabel("time (s)")
    a.set_ylabel("left wrist height (m)")
    a.legend(fontsize=8)
    b.plot(t, err["noisy"], color="#bbbbbb", label=f"noisy: mean {err['noisy'].mean():.2f} cm")
    b.plot(t, err["denoised"], color=NEW, label=f"denoised: mean {err['denoised'].mean():.2f} cm")
    b.set_xlabel("time (s)")
    b.set_ylabel("mean joint error vs clean (cm)")
    b.legend(fontsize=8)
    for ax in (a, b):
        ax.grid(alpha=0.3)
    fig.suptitle(f"Denoise Action on {clip.name} (a test-split take) with Gaussian jitter of {degrees:g} degrees "
                 "on every rotation channel; error over the 21 model joints")
    finish(fig, out / "denoise.png")
    return {"clip": clip.name, "noisy_cm": float(err["noisy"].mean()), "denoised_cm": float(err["denoised"].mean())}


def picture_inbetween(bpy, clip: Path, out: Path, start: int = 80, gap: int = 30) -> dict:
    """A gap of ``gap`` frames from ``start`` frames into the take: its keys deleted (Blender then
    interpolates the F-curves across it), then filled by Fill Gap; both against the true motion."""
    from batch_worker import clear_keys

    obj = import_bvh(bpy, clip, BANDAI_SCALE)
    first, last = action_range(obj)
    a, b = first + start, first + start + gap - 1
    truth, names = sample(bpy, obj, first, last)
    clear_keys(obj, a, b)
    curves, _ = sample(bpy, obj, first, last)
    bpy.context.scene.frame_set(a + gap // 2)
    bpy.ops.strnn.inbetween()
    filled, _ = sample(bpy, obj, first, last)
    ref = canonical(obj, truth, names)
    window = slice(a - first - 10, b - first + 11)
    err = {k: np.linalg.norm(canonical(obj, v, names) - ref, axis=-1).mean(-1)[window] * 100
           for k, v in (("interpolation", curves), ("Fill Gap", filled))}
    foot = bone_of(obj, names, "l_foot")
    t = np.arange(len(truth))[window] / 30.0
    fig, (h, e) = plt.subplots(1, 2, figsize=(13, 3.8))
    for label, poses, colour, lw in (("true motion", truth, "k", 1.6),
                                     ("Blender's F-curve interpolation", curves, "#e08214", 1.3),
                                     ("Fill Gap", filled, NEW, 1.6)):
        h.plot(t, poses[window, foot, 0, 2], color=colour, lw=lw, label=label)
    for ax in (h, e):
        ax.axvspan(start / 30.0, (start + gap - 1) / 30.0, color="#eeeeee")
        ax.grid(alpha=0.3)
        ax.set_xlabel("time (s)")
    h.set_ylabel("left ankle height (m)")
    h.legend(fontsize=8)
    for label, colour in (("interpolation", "#e08214"), ("Fill Gap", NEW)):
        inside = err[label][10:-10]
        e.plot(t, err[label], color=colour, label=f"{label}: mean {inside.mean():.1f} cm over the gap")
    e.set_ylabel("mean joint error vs the true motion (cm)")
    e.legend(fontsize=8)
    fig.suptitle(f"Fill Gap on {clip.name} (a test-split take): frames {start + 1}-{start + gap} cut out "
                 f"(shaded) and filled")
    finish(fig, out / "inbetween.png")
    return {"clip": clip.name, "gap": gap, "interpolation_cm": float(err["interpolation"][10:-10].mean()),
            "fill_gap_cm": float(err["Fill Gap"][10:-10].mean())}


def foot_speed(poses: np.ndarray, foot: int) -> np.ndarray:
    return np.r_[0.0, np.linalg.norm(np.diff(poses[:, foot, 0, :2], axis=0), axis=1) * 100]


def picture_footlock(bpy, clip: Path, out: Path, frames: int = 150) -> dict:
    obj = import_bvh(bpy, clip, BANDAI_SCALE)
    start, end = action_range(obj)
    bpy.ops.strnn.extend_clip(frames=frames)
    s, e = end + 1, end + frames
    before, names = sample(bpy, obj, s, e)
    bpy.ops.strnn.foot_lock(use_range=True, frame_start=s, frame_end=e)
    after, _ = sample(bpy, obj, s, e)
    foot = bone_of(obj, names, "r_foot")
    pos0, pos1 = canonical(obj, before, names), canonical(obj, after, names)
    contacts0, contacts1 = detect_contacts(pos0), detect_contacts(pos1)
    skate = foot_skate_cm(pos0, contacts0), foot_skate_cm(pos1, contacts0)
    v0, v1 = foot_speed(before, foot), foot_speed(after, foot)
    planted = contacts0[:, 2] > 0.5  # right heel (ankle) contact, detected on the model's output
    t = np.arange(len(v0)) / 30.0
    fig, (a, b) = plt.subplots(1, 2, figsize=(13, 3.8), gridspec_kw={"width_ratios": [1.6, 1]})
    a.fill_between(t, 0, max(v0.max(), 1) * planted, color="#2ca02c", alpha=0.12, step="mid", label="foot planted")
    a.plot(t, v0, color="#bbbbbb", label="model output")
    a.plot(t, v1, color=NEW, label="after Foot Lock")
    a.set_xlabel("time (s)")
    a.set_ylabel(f"{names[foot]} ground speed (cm/frame)")
    a.legend(fontsize=8)
    # From above, each planted stretch drawn from where the foot landed: a straight walk's whole path is a
    # thin line metres long, in which a centimetre of slide cannot be seen.
    starts = np.flatnonzero(np.diff(np.r_[0, planted.astype(int)]) == 1)
    ends = np.flatnonzero(np.diff(np.r_[planted.astype(int), 0]) == -1)
    for k, (i, j) in enumerate(zip(starts, ends + 1)):
        for poses, colour, label in ((before, "#bbbbbb", "model output"), (after, NEW, "after Foot Lock")):
            path = (poses[i:j, foot, 0, :2] - poses[i, foot, 0, :2]) * 100
            b.plot(path[:, 0], path[:, 1], ".-", ms=3, lw=0.6, color=colour, label=label if k == 0 else None)
    b.set_aspect("equal", adjustable="datalim")
    b.set_xlabel("x from where the foot landed (cm)")
    b.set_ylabel("y (cm)")
    b.set_title(f"{names[foot]} from above while planted, one dot per frame", fontsize=9)
    b.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.02, 1.0))
    for ax in (a, b):
        ax.grid(alpha=0.3)
    fig.suptitle(f"Foot Lock on {frames} frames that Extend Clip generated from {clip.name}\nfoot skate "
                 f"{skate[0]:.2f} -> {skate[1]:.2f} cm/frame (both feet, contacts detected on the model's output)",
                 y=1.04)
    finish(fig, out / "footlock.png")
    return {"clip": clip.name, "skate_before_cm": skate[0], "skate_after_cm": skate[1],
            "contacts_after_lock": int(contacts1.sum())}


def picture_loop(bpy, clip: Path, out: Path, start: int = 60, end: int = 110, cycles: int = 3) -> dict:
    """Make Loop on frames ``start``-``end`` of the take as given (Match the Start off: the range's last frame starts
    the next cycle, though the walk is not where it started there): the cycle played ``cycles`` times as Blender
    plays it, beside the same cycle with its seam left as it is (Blend 0), and each frame's mean joint move."""
    obj = import_bvh(bpy, clip, BANDAI_SCALE)
    first = action_range(obj)[0]
    original = obj.animation_data.action
    played, record = {}, {}
    for label, blend in (("seam as it is (Blend 0)", 0.0), ("Make Loop", 0.4)):
        obj.animation_data.action = original
        bpy.ops.strnn.make_loop(use_range=True, frame_start=first + start, frame_end=first + end, blend=blend,
                                match=False)
        record[label] = obj.animation_data.action["strnn"]["cycle"].to_dict()
        c = record[label]
        poses, names = sample(bpy, obj, c["first"], c["first"] + cycles * c["frames"])
        played[label] = joints_z_up(obj, poses, names)
    length = record["Make Loop"]["frames"]
    fig, (side, moves) = plt.subplots(1, 2, figsize=(14, 3.6), gridspec_kw={"width_ratios": [3, 1.3]})
    every = 10
    around = [f for k in range(1, cycles) for f in range(k * length - 2 * every, k * length + 2 * every, every)]
    shown = sorted({f for f in around if 0 <= f < len(played["Make Loop"])})[:8]
    for row, (label, colour) in enumerate((("seam as it is (Blend 0)", "#e08214"), ("Make Loop", None))):
        flat = body_view(z_up_to_model(played[label]))[shown]
        for slot, pose in enumerate(flat):
            draw_pose(side, np.stack([pose[:, 0] + slot * 0.7, np.zeros(len(pose)), pose[:, 1] - 2.1 * row], -1),
                      (0, 2), 1.0, colour)
        side.text(-0.6, 0.9 - 2.1 * row, label, ha="right", fontsize=9)
        side.axhline(-2.1 * row, color="k", lw=0.6)
    side.set_aspect("equal")
    side.axis("off")
    side.set_title(f"every {every}th frame around the seams (frame {length} of each cycle starts the next)",
                   fontsize=9)
    t = np.arange(1, cycles * length + 1) / 30.0
    for label, colour in (("seam as it is (Blend 0)", "#e08214"), ("Make Loop", NEW)):
        step = np.linalg.norm(np.diff(z_up_to_model(played[label]), axis=0), axis=-1).mean(-1) * 100
        moves.plot(t[:len(step)], step, color=colour, lw=1.4, label=label)
    for k in range(1, cycles):
        moves.axvline(k * length / 30.0, color="#9a9a9a", lw=0.8, ls="--")
    moves.set_xlabel("time (s); dashed: where a cycle starts again")
    moves.set_ylabel("mean joint move a frame (cm)")
    moves.grid(alpha=0.3)
    moves.legend(fontsize=8)
    c = record["Make Loop"]
    fig.suptitle(f"Make Loop, Match the Start off, on frames {start + 1}-{end + 1} of {clip.name} (a test-split "
                 f"take): the last pose {c['match_cm']:.0f} cm a joint from the first, {cycles} cycles as played")
    finish(fig, out / "loop.png")
    seams = [k * length - 1 for k in range(1, cycles)]
    jumps = {label: float(np.linalg.norm(np.diff(z_up_to_model(j), axis=0), axis=-1).mean(-1)[seams].max() * 100)
             for label, j in played.items()}
    take = np.linalg.norm(np.diff(z_up_to_model(played["seam as it is (Blend 0)"][:length]), axis=0),
                          axis=-1).mean(-1).max() * 100
    return {"clip": clip.name, "cycle_frames": c["frames"], "match_cm": c["match_cm"],
            "seam_move_cm": jumps["Make Loop"], "seam_move_unblended_cm": jumps["seam as it is (Blend 0)"],
            "take_largest_move_cm": float(take)}


def path_from_the_take(bpy, clip: Path, path: str):
    """``clip`` imported, and a built-in ground ``path`` (batch_worker.add_path_curve) drawn from where the take
    ends, heading the way it walks: (armature, its action's last frame, curve)."""
    import batch_worker

    obj = import_bvh(bpy, clip, BANDAI_SCALE)
    _, end = action_range(obj)
    poses, names = sample(bpy, obj, end - 10, end)
    bpy.ops.strnn.auto_map()
    hips = joints_z_up(obj, poses, names)[:, 0]
    heading = np.arctan2(*(hips[-1, :2] - hips[0, :2])[::-1])
    curve = batch_worker.add_path_curve(bpy, path)  # starts at the origin heading -Y
    curve.location = (hips[-1, 0], hips[-1, 1], 0.0)  # drawn from where the character stands, as it walks
    curve.rotation_euler.z = heading + np.pi / 2
    bpy.context.view_layer.objects.active = obj
    return obj, end, curve


def picture_follow(bpy, clip: Path, out: Path) -> dict:
    obj, end, curve = path_from_the_take(bpy, clip, "figure_eight")
    bpy.ops.strnn.follow_curve(curve=curve.name)
    s, e = action_range(obj)
    poses, names = sample(bpy, obj, end + 1, e)
    joints = joints_z_up(obj, poses, names)
    bpy.context.view_layer.update()
    mw = curve.matrix_world
    spline = curve.data.splines[0]
    pts = np.array([list(mw @ p.co.xyz) for p in list(spline.points) + [spline.points[0]]])
    fig, (top, side) = plt.subplots(1, 2, figsize=(14, 3.6), gridspec_kw={"width_ratios": [1, 2.2]})
    top.plot(pts[:, 0], pts[:, 1], "--", color="k", lw=1, label="curve object")
    top.plot(joints[:, 0, 0], joints[:, 0, 1], color=NEW, lw=2, alpha=0.5, label=f"hips ({len(joints)} new frames)")
    ghosts(top, joints, 30, (0, 1), alpha=(0.8, 0.8))
    top.set_aspect("equal")
    top.grid(alpha=0.3)
    top.legend(fontsize=8, loc="best")
    top.set_title("from above (m), every 30th frame drawn", fontsize=9)
    shown = list(range(0, min(len(joints), 240), 12))
    filmstrip(side, joints, shown, 0.6)
    side.axhline(0, color="k", lw=0.6)
    side.set_aspect("equal")
    side.axis("off")
    side.set_title("the first 8 s, every 12th frame, each seen from its side", fontsize=9)
    fig.suptitle(f"Follow Curve: {clip.name} walks a figure-eight curve (two 2 m loops), foot-locked")
    finish(fig, out / "follow.png")
    return {"clip": clip.name, "frames": len(joints)}


def picture_ground(bpy, clip: Path, out: Path) -> dict:
    """Follow Curve along a straight line over a hill (a mesh: up 15 % for 3 m, a 2 m top, down again), with the
    hill as Ground: the side view along the way, every 6th frame, and the lowest foot's height over the hill."""
    obj, end, curve = path_from_the_take(bpy, clip, "line")  # 10 m
    way = np.array([-20.0, -1.0, 1.0, 3.0, 5.0, 6.0, 9.0, 30.0])  # metres along the line
    rise = np.array([0.0, 0.0, 0.0, 0.3, 0.3, 0.3, 0.0, 0.0])  # up 15 % from 1 m, a top from 3 to 6 m, down by 9
    verts = [(side, -d, z) for d, z in zip(way, rise) for side in (-4.0, 4.0)]
    faces = [(2 * i, 2 * i + 1, 2 * i + 3, 2 * i + 2) for i in range(len(way) - 1)]
    mesh = bpy.data.meshes.new("Hill")
    mesh.from_pydata(verts, [], faces)
    hill = bpy.data.objects.new("Hill", mesh)
    hill.location, hill.rotation_euler = curve.location, curve.rotation_euler
    bpy.context.scene.collection.objects.link(hill)
    bpy.context.view_layer.objects.active = obj
    bpy.ops.strnn.follow_curve(curve=curve.name, ground=hill.name, frames=300)
    s, e = action_range(obj)
    poses, names = sample(bpy, obj, end + 1, e)
    joints = joints_z_up(obj, poses, names)
    bpy.context.view_layer.update()
    to_path = np.array(curve.matrix_world.inverted())
    local = joints @ to_path[:3, :3].T + to_path[:3, 3]  # the line's frame: -Y along the way
    along = np.stack([-local[..., 1], local[..., 0], joints[..., 2]], -1)  # (along, side, height)

    def hill_under(d):
        return np.interp(d, way, rise)

    feet = [JOINTS.index(j) for j in ("l_foot", "l_toe", "r_foot", "r_toe")]
    over = along[:, feet, 2] - hill_under(along[:, feet, 0])
    lowest = over.min(axis=1)
    fps = bpy.context.scene.render.fps
    each_second = [float(lowest[i:i + fps].min()) for i in range(0, len(lowest) - fps + 1, fps)]
    hips_over = along[:, 0, 2] - hill_under(along[:, 0, 0])
    fig, (side, low) = plt.subplots(2, 1, figsize=(14, 5.2), gridspec_kw={"height_ratios": [2.2, 1]}, sharex=True)
    d = np.linspace(along[:, 0, 0].min() - 0.5, along[:, 0, 0].max() + 0.5, 200)
    side.fill_between(d, hill_under(d), -0.1, color="0.85", lw=0)
    side.plot(d, hill_under(d), color="k", lw=1, label="the Ground mesh (a hill)")
    ghosts(side, along, 6, (0, 2), alpha=(0.9, 0.9))
    side.set_aspect("equal")
    side.set_ylim(-0.1, 2.2)
    side.legend(fontsize=8, loc="upper right")
    side.set_title(f"{len(joints)} new frames along the line, every 6th drawn, seen from the side (m)", fontsize=9)
    low.plot(along[:, 0, 0], lowest * 100, color=NEW, lw=1.2, label="lowest heel or toe over the hill")
    low.axhline(0, color="k", lw=0.6)
    low.set_ylabel("cm", fontsize=8)
    low.set_xlabel("along the line (m)", fontsize=8)
    low.legend(fontsize=8, loc="upper right")
    low.grid(alpha=0.3)
    fig.suptitle(f"Follow Curve with Ground: {clip.name} walks a straight line over a hill, feet locked on it")
    finish(fig, out / "ground.png")
    return {"clip": clip.name, "frames": len(joints), "hips_over_hill_m": [float(hips_over.min()),
                                                                              float(hips_over.max())],
            "lowest_foot_each_second_cm": [round(100 * x, 1) for x in each_second]}


def label_column(ax, items: list[tuple[float, float, str, str]], x: float, gap: float, align: str):
    """Labels ``(x, z, text, colour)`` stacked in one column at ``x`` without overlaps, each with
    a thin line to its point."""
    last = np.inf
    for px, pz, text, colour in sorted(items, key=lambda it: -it[1]):
        y = min(pz, last - gap)
        last = y
        ax.annotate(text, (px, pz), (x, y), fontsize=7, ha=align, va="center", color=colour,
                    arrowprops={"arrowstyle": "-", "color": colour, "lw": 0.5, "alpha": 0.6})


def picture_bone_map(bpy, data: Path, out: Path) -> dict:
    """Auto-Map Bones on BVH imports of three rig families: each rig's bones on the first frame (grey)
    and the bone the map gives each of the 21 model joints (dots, labelled with the rig's own name)."""
    fig, axes = plt.subplots(1, len(BONE_MAP_CLIPS), figsize=(15, 4.8))
    counts = {}
    for ax, (family, rel, scale) in zip(axes, BONE_MAP_CLIPS):
        obj = import_bvh(bpy, data / rel, scale)
        bpy.ops.strnn.auto_map()
        start, _ = action_range(obj)
        poses, names = sample(bpy, obj, start, start)
        bones, joints = poses[0], joints_z_up(obj, poses, names)[0]
        # seen from the front: x along the body's left, z up (the character's left on the picture's right)
        lateral = (joints[JOINTS.index("l_arm")] - joints[JOINTS.index("r_arm")]
                   + joints[JOINTS.index("l_upleg")] - joints[JOINTS.index("r_upleg")])[:2]
        lateral /= np.linalg.norm(lateral)
        bones, joints = (np.stack([(p[..., :2] - joints[0, :2]) @ lateral, p[..., 1] * 0, p[..., 2]], -1)
                         for p in (bones, joints))
        for head, tail in bones:
            ax.plot([head[0], tail[0]], [head[2], tail[2]], color="#c8c8c8", lw=2, solid_capstyle="round")
        bone_map = obj.strnn_map
        left, right = [], []
        for j, (joint, p) in enumerate(zip(JOINTS, joints)):
            ax.plot(p[0], p[2], "o", ms=4.5, color=COLOURS[j])
            text = f"{joint}: {getattr(bone_map, joint)}"
            (left if joint.startswith("r_") else right).append((p[0], p[2], text, COLOURS[j]))
        span = np.ptp(joints[:, 2])
        xs = bones[..., 0]
        label_column(ax, left, xs.min() - 0.15 * span, 0.065 * span, "right")
        label_column(ax, right, xs.max() + 0.15 * span, 0.065 * span, "left")
        ax.set_xlim(xs.min() - 0.85 * span, xs.max() + 0.85 * span)
        counts[family] = sum(bool(getattr(bone_map, j)) for j in JOINTS)
        ax.set_aspect("equal")
        ax.axis("off")
        ax.set_title(f"{family}: {len(names)} bones, {counts[family]} of 21 joints mapped\n({Path(rel).name})",
                     fontsize=9)
    fig.suptitle("Auto-Map Bones: the 21 model joints found by bone names on three rigs (first frame, from the front)")
    finish(fig, out / "bonemap.png")
    return counts


BODY_DEFORM = ("spine", "pelvis", "thigh", "shin", "foot", "toe", "shoulder", "upper_arm", "forearm", "hand")


def generate_rigify(bpy):
    """A rig generated by Rigify (bundled with Blender) from its human metarig; the metarig is hidden."""
    import addon_utils

    addon_utils.enable("rigify", default_set=True)
    bpy.ops.object.armature_human_metarig_add()
    meta = bpy.context.active_object
    bpy.ops.pose.rigify_generate()
    meta.hide_set(True)
    return bpy.data.objects["rig"]


def picture_your_rig(bpy, clip: Path, out: Path, frames: int = 90) -> dict:
    """Transfer Motion from a BVH take onto a freshly generated Rigify rig (keyed on its controls: its limbs on their
    IK controls, as the rig comes), then Extend Clip on the rig: its deform bones drawn frame by frame."""
    bpy.ops.wm.read_homefile(use_empty=True)
    rig = generate_rigify(bpy)
    bpy.ops.import_anim.bvh(filepath=str(clip), global_scale=BANDAI_SCALE, update_scene_fps=True,
                            update_scene_duration=True)
    source = bpy.context.view_layer.objects.active
    source.location.x = -1.5
    bpy.ops.strnn.auto_map()  # its map, for drawing its joints
    for obj in bpy.context.view_layer.objects:
        obj.select_set(obj in (source, rig))
    bpy.context.view_layer.objects.active = rig
    bpy.ops.strnn.transfer_motion(foot_lock=True)
    moved = rig.animation_data.action
    start, end = action_range(rig)
    bpy.ops.strnn.extend_clip(frames=frames)
    extended = rig.animation_data.action
    poses, names = sample(bpy, rig, start, end + frames)
    src_poses, src_names = sample(bpy, source, start, end)
    joints = joints_z_up(rig, poses, names)
    source_joints = joints_z_up(source, src_poses, src_names)
    keyed = sorted({fc.data_path.split('"')[1] for fc in fcurves(rig, extended) if fc.data_path.startswith("pose")})
    deform = [i for i, n in enumerate(names) if n.startswith("DEF-") and any(w in n for w in BODY_DEFORM)]
    old, new = joints[: end - start + 1], joints[end - start + 1:]
    speed = lambda j: float(np.linalg.norm(np.diff(j - j[:, :1], axis=0), axis=-1).mean())  # noqa: E731
    fig, (strip, front) = plt.subplots(1, 2, figsize=(14, 3.6), gridspec_kw={"width_ratios": [3, 1]})
    shown_src = list(range(len(old) - 1 - 3 * 10, len(old), 10))
    filmstrip(strip, source_joints, shown_src, 0.6, colour="#c8c8c8")
    filmstrip(strip, old, shown_src, 0.6, colour="#7a7a7a", first_slot=len(shown_src))
    filmstrip(strip, new, list(range(9, len(new), 10)), 0.6, first_slot=2 * len(shown_src))
    strip.axhline(0, color="k", lw=0.6)
    strip.set_aspect("equal")
    strip.axis("off")
    strip.set_title("the BVH take (light grey), moved onto the Rigify rig (grey), then extended on it (blue); "
                    "every 10th frame", fontsize=9)
    last = poses[-1]
    for i in deform:
        side = "#1f77b4" if names[i].endswith(".L") else "#d62728" if names[i].endswith(".R") else "#333333"
        front.plot(last[i, :, 0], last[i, :, 2], color=side, lw=2, solid_capstyle="round")
    front.set_aspect("equal")
    front.axis("off")
    front.set_title(f"its deform bones at frame {end + frames} (front)", fontsize=9)
    fig.suptitle(f"Your own rig: {clip.name} on a generated Rigify rig with Transfer Motion, then Extend Clip "
                 f"(+{frames} frames), keyed on its controls")
    finish(fig, out / "your_rig.png")
    return {"clip": clip.name, "frames": frames, "keyed_bones": len(keyed),
            "keyed_deform_or_mechanism": len([k for k in keyed if k.startswith(("DEF-", "ORG-", "MCH-"))]),
            "transfer_max_error_cm": moved["strnn"]["controls"]["max_error_cm"],
            "extend_max_error_cm": extended["strnn"]["controls"]["max_error_cm"],
            "speed_ratio_new_to_old": speed(new) / speed(old[-60:])}


def fcurves(obj, action):
    """The F-curves of ``action`` on ``obj``'s slot (Blender 4.2's legacy actions or 4.4+ layered ones)."""
    if not hasattr(action, "slots"):
        return list(action.fcurves)
    from bpy_extras import anim_utils

    bag = anim_utils.action_get_channelbag_for_slot(action, obj.animation_data.action_slot)
    return list(bag.fcurves) if bag else []


def main(argv=None) -> int:
    args = parse_args(argv)
    clips = {k: args.data / v for k, v in (("extend", EXTEND_CLIP), ("denoise", DENOISE_CLIP), ("follow", FOLLOW_CLIP))}
    missing = [str(p) for p in [*clips.values(), *(args.data / rel for _, rel, _ in BONE_MAP_CLIPS)] if not p.is_file()]
    if missing:
        print(f"error: missing clips {missing}; unpack ../shared/mocap into {args.data} "
              "(../shared/mocap/extract.sh) or pass --data", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory(prefix="strnn_pictures_") as tmp:
        tmp = Path(tmp)
        zip_path = args.extension
        if zip_path is None:
            import build_extension

            zip_path = Path(build_extension.main(["--out", str(tmp / "dist")]))
        bpy = start_blender(zip_path, tmp / "user")
        makers = {
            "extend": lambda: picture_extend(bpy, clips["extend"], args.out),
            "inbetween": lambda: picture_inbetween(bpy, clips["follow"], args.out),
            "denoise": lambda: picture_denoise(bpy, clips["denoise"], args.out, args.seed),
            "footlock": lambda: picture_footlock(bpy, clips["extend"], args.out),
            "loop": lambda: picture_loop(bpy, clips["follow"], args.out),
            "follow": lambda: picture_follow(bpy, clips["follow"], args.out),
            "ground": lambda: picture_ground(bpy, clips["follow"], args.out),
            "bonemap": lambda: picture_bone_map(bpy, args.data, args.out),
            "your_rig": lambda: picture_your_rig(bpy, clips["follow"], args.out),
        }
        figures = {name: makers[name]() for name in PICTURES if name in args.only}
    print("figures: " + json.dumps({name: {k: round(v, 2) if isinstance(v, float) else v for k, v in fig.items()}
                                    for name, fig in figures.items()}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
