"""scripts/strnn_batch.py: the real extension in spawned bpy workers over folders of BVH files."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

from model_core.io.bvh import read_bvh
from model_core.io.bvh_export import write_bvh
from model_core.motion.synthetic import walking_skeleton
from model_core.rig.rigs import canonical_positions

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "scripts"))

import strnn_batch  # noqa: E402


def frames_of(path: Path) -> int:
    return next(int(line.split(":")[1]) for line in path.read_text().splitlines() if line.startswith("Frames:"))


def snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def extension(tmp_path_factory) -> Path:
    pytest.importorskip("bpy")
    import build_extension

    return build_extension.main(["--out", str(tmp_path_factory.mktemp("dist"))])


@pytest.fixture
def clips(tmp_path) -> Path:
    """A folder with one good BVH (60 frames) and one cut short in its hierarchy."""
    folder = tmp_path / "clips"
    folder.mkdir()
    good = write_bvh(folder / "walk.bvh", walking_skeleton(60))
    (folder / "broken.bvh").write_text(good.read_text()[:400])
    return folder


def test_help_documents_every_command(capsys):
    with pytest.raises(SystemExit) as e:
        strnn_batch.main(["--help"])
    assert e.value.code == 0
    text = capsys.readouterr().out
    for word in ("extend", "inbetween", "denoise", "footlock", "loop", "follow", "--in-place", "--jobs", "Exit status"):
        assert word in text
    for command, option in [("extend", "--frames"), ("denoise", "--strength"), ("follow", "--path"),
                            ("footlock", "--blend"), ("inbetween", "--gap"), ("loop", "--no-travel")]:
        with pytest.raises(SystemExit):
            strnn_batch.main([command, "--help"])
        text = capsys.readouterr().out
        assert option in text and "--out" in text and "--jobs" in text


def test_follow_flags_reach_their_operators():
    """Extend's --no-follow-clip and Fill Gap's --no-follow-take turn the option off; both are on by default."""
    parse = strnn_batch.build_parser().parse_args
    assert strnn_batch.operator_call(parse(["extend", "a.bvh"]))[1]["follow_clip"] is True
    assert strnn_batch.operator_call(parse(["extend", "--no-follow-clip", "a.bvh"]))[1]["follow_clip"] is False
    name, kw = strnn_batch.operator_call(parse(["inbetween", "--gap", "3", "9", "a.bvh"]))
    assert name == "inbetween" and kw["follow_take"] is True and kw["use_range"] is True
    assert strnn_batch.operator_call(parse(["inbetween", "--no-follow-take", "a.bvh"]))[1]["follow_take"] is False


def test_transfer_root_motion_flag_reaches_its_operator():
    parse = strnn_batch.build_parser().parse_args
    assert strnn_batch.operator_call(parse(["transfer", "--target", "r.blend", "a.bvh"]))[1]["root_motion"] is False
    name, kw = strnn_batch.operator_call(parse(["transfer", "--target", "r.blend", "--root-motion", "a.bvh"]))
    assert name == "transfer_motion" and kw["root_motion"] is True


def test_good_file_processed_corrupt_one_reported(clips, tmp_path, extension, capsys):
    """A good take is extended, a broken one reported with its reason; a take that has come to rest in motion the
    model does not know is extended too, and the progress line, the summary and the report carry the operator's
    note on it (its first window was held near the last pose), as its report in Blender would warn."""
    walk = walking_skeleton(60)
    write_bvh(clips / "rest.bvh", np.repeat(walk[30:31], 40, 0))
    before = snapshot(clips)
    out = tmp_path / "out"
    code = strnn_batch.main(["extend", "--frames", "20", str(clips), "--out", str(out), "--jobs", "2",
                             "--extension", str(extension), "--report", str(tmp_path / "report.json")])
    captured = capsys.readouterr()
    assert code == 1
    result = out / "walk.extend.bvh"
    assert result.is_file() and frames_of(result) == 60 + 20
    # the result is in the take's own axes (Y up), its first frames the take's
    taken, written = (canonical_positions(read_bvh(p)) for p in (clips / "walk.bvh", result))
    assert np.abs(written[:60] - taken).max() < 0.01 * np.abs(taken).max(), np.abs(written[:60] - taken).max()
    assert sorted(p.name for p in out.iterdir()) == ["rest.extend.bvh", "walk.extend.bvh"]  # none for the broken
    assert snapshot(clips) == before  # inputs untouched
    failures = captured.err.split("failures:")[1]
    assert "broken.bvh" in failures and "broken BVH" in failures and "walk.bvh" not in failures
    assert "Traceback" not in captured.out + captured.err
    table = captured.out.split("file ")[-1]
    assert "ok" in table and "failed" in table and "2 of 3 files processed" in captured.out
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["command"] == "extend" and (report["processed"], report["failed"]) == (2, 1)
    rows = {Path(r["file"]).name: r for r in report["files"]}
    assert any("come to rest" in note for note in rows["rest.bvh"]["notes"]), rows["rest.bvh"]
    assert not any("come to rest" in note for note in rows["walk.bvh"]["notes"])
    rest_lines = [line for line in captured.out.splitlines() if "rest.bvh" in line]
    assert len(rest_lines) == 2 and all("come to rest" in line for line in rest_lines)  # progress line, summary
    assert rows["walk.bvh"]["status"] == "ok" and Path(rows["walk.bvh"]["output"]) == result.resolve()
    assert rows["broken.bvh"]["status"] == "failed" and "broken BVH" in rows["broken.bvh"]["reason"]


def test_importer_errors_and_missing_inputs_have_reasons(tmp_path, extension, capsys):
    folder = tmp_path / "clips"
    folder.mkdir()
    good = write_bvh(folder / "walk.bvh", walking_skeleton(40))
    text = good.read_text()
    (folder / "offset.bvh").write_text(text.replace("OFFSET", "OFFSET abc", 1))  # passes the quick text check
    (folder / "slow.bvh").write_text(re.sub(r"Frame Time: \S+", "Frame Time: 10", text))
    (folder / "inf.bvh").write_text(re.sub(r"(Frame Time: \S+\n)\S+", r"\1inf", text))
    (folder / "empty.bvh").write_text("")
    out = tmp_path / "out"
    code = strnn_batch.main(["footlock", str(folder / "offset.bvh"), str(folder / "empty.bvh"), str(good),
                             str(folder / "slow.bvh"), str(folder / "inf.bvh"),
                             str(tmp_path / "missing.bvh"), "--out", str(out), "--extension", str(extension)])
    err = capsys.readouterr().err
    assert code == 1
    assert frames_of(out / "walk.footlock.bvh") == 40
    assert re.search(r"offset.bvh: broken BVH: \d+: .*abc", err)
    assert "slow.bvh: broken BVH" in err and "far from any capture rate" in err and "configs/data.toml" in err
    assert re.search(r"inf.bvh: broken BVH: \d+: frame \d+ has inf in", err)
    assert "empty.bvh: not a BVH file: it is empty" in err
    assert "missing.bvh: no such file or folder" in err
    assert good.read_text() == text


def test_in_place_overwrites_only_when_asked(tmp_path, extension, capsys):
    clip = write_bvh(tmp_path / "walk.bvh", walking_skeleton(40))
    code = strnn_batch.main(["extend", "--frames", "5", "--in-place", str(clip), "--extension", str(extension)])
    assert code == 0 and frames_of(clip) == 45
    assert [p.name for p in tmp_path.iterdir()] == ["walk.bvh"]


def test_a_z_up_take_is_extended_standing_and_written_back_in_its_own_axes(tmp_path, extension, capsys):
    """A take whose file stands the body along Z (AMASS conversions, some exporters) is read with Up Z, so that it
    stands in Blender: extended as its Y-up twin is (the same heights over the floor), written back Z-up with
    its own frames unchanged, and the report says so."""
    walk = walking_skeleton(60)
    z_up = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])  # file Y -> Z
    takes = {"y": write_bvh(tmp_path / "y" / "walk.bvh", walk),
             "z": write_bvh(tmp_path / "z" / "walk.bvh", walk @ z_up.T)}
    out = {}
    for name, take in takes.items():
        report = tmp_path / f"{name}.json"
        assert strnn_batch.main(["extend", "--frames", "30", str(take), "--out", str(tmp_path / f"out_{name}"),
                                 "--extension", str(extension), "--report", str(report)]) == 0
        out[name] = (canonical_positions(read_bvh(tmp_path / f"out_{name}" / "walk.extend.bvh")),
                     json.loads(report.read_text())["files"][0]["notes"])
    (y, y_notes), (z, z_notes) = out["y"], out["z"]
    taken = canonical_positions(read_bvh(takes["z"]))
    assert np.abs(z[:60] - taken).max() < 0.01 * np.abs(taken).max()  # the take's own frames, in its own axes
    assert np.abs(z[60:, :, 2] - y[60:, :, 1]).max() < 0.01  # new frames: Z-up heights are the Y-up twin's
    assert any("stands along its file's Z axis" in note for note in z_notes), z_notes
    assert not any("stands along" in note for note in y_notes), y_notes


def test_a_take_that_starts_with_a_byte_order_mark_is_extended(tmp_path, extension, capsys):
    """Some Windows tools start a BVH with a UTF-8 byte-order mark; Blender's importer reads it, and so does the
    batch (it used to call it 'not a BVH file')."""
    take = write_bvh(tmp_path / "walk.bvh", walking_skeleton(40))
    take.write_bytes(b"\xef\xbb\xbf" + take.read_bytes())
    assert strnn_batch.main(["extend", "--frames", "10", str(take), "--out", str(tmp_path / "out"),
                             "--extension", str(extension)]) == 0
    assert frames_of(tmp_path / "out" / "walk.extend.bvh") == 50


def test_extend_from_a_frame_replaces_the_tail(tmp_path, extension, capsys):
    clip = write_bvh(tmp_path / "walk.bvh", walking_skeleton(60))
    out = tmp_path / "out"
    code = strnn_batch.main(["extend", "--frames", "10", "--from-frame", "40", str(clip), "--out", str(out),
                             "--extension", str(extension)])
    assert code == 0 and frames_of(out / "walk.extend.bvh") == 50  # frames 1-40 kept, 41-50 new, 51-60 gone


def test_keys_per_second_reads_a_take_whose_header_says_another_rate(tmp_path, extension, capsys):
    """A 60 fps walk whose file says 24 plays 2.5 x too slow: extended as it is, the report says to set Keys per
    Second to 60; with --keys-per-second 60 the operator reads it at its own pace, there is no such note, and the
    new frames move as far a frame as the take's."""
    walk = walking_skeleton(240, fps=60.0)  # 1.3 m/s at 60 fps: 2.2 cm a frame; strides of 1.1 s, 2.8 s read at 24
    take = write_bvh(tmp_path / "walk.bvh", walk, fps=24.0)
    runs = {}
    for name, extra in (("plain", []), ("kps", ["--keys-per-second", "60"])):
        report = tmp_path / f"{name}.json"
        assert strnn_batch.main(["extend", "--frames", "60", str(take), "--out", str(tmp_path / name),
                                 "--extension", str(extension), "--report", str(report), *extra]) == 0
        new = canonical_positions(read_bvh(tmp_path / name / "walk.extend.bvh"))[240:]
        step = np.linalg.norm(np.diff(new[:, 0, [0, 2]], axis=0), axis=-1).mean()  # the hips, a frame
        runs[name] = (step, json.loads(report.read_text())["files"][0]["notes"])
    clip_step = np.linalg.norm(np.diff(canonical_positions(read_bvh(take))[:, 0, [0, 2]], axis=0), axis=-1).mean()
    assert any("set Keys per Second to 60" in note and note.endswith("(in a batch: --keys-per-second 60)")
               for note in runs["plain"][1]), runs["plain"][1]
    assert not any("Keys per Second" in note for note in runs["kps"][1]), runs["kps"][1]
    assert abs(runs["kps"][0] / clip_step - 1) < 0.25, (runs, clip_step)
    with pytest.raises(SystemExit) as e:
        strnn_batch.main(["extend", str(take), "--keys-per-second", "0"])
    assert e.value.code == 2 and "--keys-per-second must be over 0" in capsys.readouterr().err


def test_inbetween_refills_a_gap(tmp_path, extension, capsys):
    """--gap 30 50: those frames' keys are replaced by the model's in-between; the take keeps its length."""
    pos = walking_skeleton(80)
    clip = write_bvh(tmp_path / "walk.bvh", pos)
    out = tmp_path / "out"
    code = strnn_batch.main(["inbetween", "--gap", "30", "50", str(clip), "--out", str(out),
                             "--extension", str(extension)])
    assert code == 0 and frames_of(out / "walk.inbetween.bvh") == 80
    with pytest.raises(SystemExit):
        strnn_batch.main(["inbetween", "--gap", "50", "50", str(clip)])
    assert "at least 2 frames" in capsys.readouterr().err


def test_loop_writes_the_cycle(tmp_path, extension, capsys):
    """loop --range 11 70: the BVH holds the cycle (where the walk comes round, one stride on), its last frame the
    next cycle's first, the first moved by the travel; --no-travel: the first itself."""
    pos = walking_skeleton(80)
    clip = write_bvh(tmp_path / "walk.bvh", pos)
    for flags, travels in (([], True), (["--no-travel"], False)):
        out = tmp_path / ("out" + "".join(flags))
        code = strnn_batch.main(["loop", "--range", "11", "70", *flags, str(clip), "--out", str(out),
                                 "--extension", str(extension)])
        assert code == 0, capsys.readouterr().err
        made = canonical_positions(read_bvh(out / "walk.loop.bvh"))
        assert len(made) in (34, 35), len(made)  # 0.9 strides a second at 30 fps: a cycle of 33 or 34 frames
        assert np.abs(made[0] - pos[10]).max() < 2e-3  # the cycle starts on the range's first frame
        moved = (made[-1] - made[0]).mean(0)
        assert np.abs(made[-1] - made[0] - moved).max() < 0.01 and abs(moved[1]) < 1e-3  # the first pose, moved
        assert (np.linalg.norm(moved) > 1.0) == travels, moved
    with pytest.raises(SystemExit):
        strnn_batch.main(["loop", "--range", "70", "11", str(clip)])
    assert "END must come after START" in capsys.readouterr().err


def test_timeout_kills_the_worker_and_writes_nothing(tmp_path, extension, capsys):
    clip = write_bvh(tmp_path / "walk.bvh", walking_skeleton(40))
    before = clip.read_bytes()
    out = tmp_path / "out"
    code = strnn_batch.main(["extend", "--frames", "5", str(clip), "--out", str(out), "--timeout", "0.5",
                             "--extension", str(extension)])
    err = capsys.readouterr().err
    assert code == 1
    assert "walk.bvh: timed out after 0.5 s (--timeout)" in err
    assert not out.exists() or not any(out.iterdir())
    assert clip.read_bytes() == before


def run_bpy(code: str) -> dict:
    """Run ``code`` in a fresh Python with the bpy module; it prints one JSON object, which is returned."""
    import json
    import subprocess

    done = subprocess.run([sys.executable, "-c", "import bpy, json\n" + code], capture_output=True, text=True,
                          timeout=120, cwd=REPO)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_every_armature_of_a_blend_file_is_extended(tmp_path, extension, capsys):
    """--every-armature: a .blend with two walking characters and a prop's armature, none of them active: both
    walkers get their new action, the prop is left and named in the notes; without it the file is refused as
    before (which one?)."""
    clips = [write_bvh(tmp_path / f"walk{i}.bvh", walking_skeleton(60 + 10 * i)) for i in range(2)]
    scene = tmp_path / "crowd.blend"
    run_bpy(f"""
bpy.ops.wm.read_factory_settings(use_empty=True)
for i, clip in enumerate({[str(c) for c in clips]!r}):
    bpy.ops.import_anim.bvh(filepath=clip)
    bpy.context.active_object.location.x = 2.0 * i
arm = bpy.data.armatures.new("Sword")
sword = bpy.data.objects.new("Sword", arm)
bpy.context.scene.collection.objects.link(sword)
bpy.context.view_layer.objects.active = sword
bpy.ops.object.mode_set(mode="EDIT")
bone = arm.edit_bones.new("blade")
bone.head, bone.tail = (0, 0, 0), (0, 0, 1)
bpy.ops.object.mode_set(mode="OBJECT")
for f in (1, 30):
    sword.pose.bones["blade"].location = (0, 0, 0.01 * f)
    sword.pose.bones["blade"].keyframe_insert("location", frame=f)
bpy.context.view_layer.objects.active = None
bpy.ops.wm.save_as_mainfile(filepath={str(scene)!r})
print(json.dumps(0))
""")
    out = tmp_path / "out"
    report = tmp_path / "report.json"
    code = strnn_batch.main(["extend", "--frames", "20", str(scene), "--out", str(out), "--extension", str(extension)])
    assert code == 1 and "3 armatures and none active" in capsys.readouterr().err
    code = strnn_batch.main(["extend", "--frames", "20", "--every-armature", "--keys-per-second", "30", str(scene),
                             "--out", str(out), "--report", str(report), "--extension", str(extension)])
    assert code == 0, capsys.readouterr().err
    notes = json.loads(report.read_text())["files"][0]["notes"]
    assert any(n.startswith("Sword: left as it was") for n in notes), notes
    got = run_bpy(f"""
bpy.ops.wm.open_mainfile(filepath={str(out / "crowd.extend.blend")!r})
print(json.dumps({{o.name: [o.animation_data.action.name, o.animation_data.action.frame_range[1],
                           o.animation_data.action.get("strnn", {{}}).get("keys_per_second")]
                  for o in bpy.data.objects if o.type == "ARMATURE"}}))
""")
    assert got["walk0"] == ["walk0.extended", 80, 30] and got["walk1"] == ["walk1.extended", 90, 30], got
    assert not got["Sword"][0].endswith(".extended"), got
    with pytest.raises(SystemExit):
        strnn_batch.main(["follow", "--every-armature", str(scene)])
    assert "not for follow" in capsys.readouterr().err


def test_follow_a_curve_in_a_blend_file_and_blend_to_bvh(tmp_path, extension, capsys):
    clip = write_bvh(tmp_path / "walk.bvh", walking_skeleton(60))
    scene = tmp_path / "scene.blend"
    start = run_bpy(f"""
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_anim.bvh(filepath={str(clip)!r})
arm = bpy.context.active_object
bpy.context.scene.frame_set(int(arm.animation_data.action.frame_range[1]))
x, y, _ = arm.matrix_world @ arm.pose.bones[0].head
data = bpy.data.curves.new("Path", "CURVE")
spline = data.splines.new("POLY")
spline.points.add(1)
spline.points[0].co = (x, y, 0.0, 1.0)  # from where the take ends
spline.points[1].co = (x, y - 6.0, 0.0, 1.0)
bpy.context.scene.collection.objects.link(bpy.data.objects.new("Path", data))
bpy.ops.wm.save_as_mainfile(filepath={str(scene)!r})
print(json.dumps([x, y]))
""")
    before = scene.read_bytes()
    out = tmp_path / "out"
    code = strnn_batch.main(["follow", "--curve", "Path", "--frames", "60", str(scene), "--out", str(out),
                             "--extension", str(extension)])
    assert code == 0, capsys.readouterr().err
    result = out / "scene.follow.blend"
    assert result.is_file() and scene.read_bytes() == before
    got = run_bpy(f"""
bpy.ops.wm.open_mainfile(filepath={str(result)!r})
arm = next(o for o in bpy.data.objects if o.type == "ARMATURE")
action = arm.animation_data.action
scene = bpy.context.scene
end = int(action.frame_range[1])
scene.frame_set(end)
hips = arm.matrix_world @ arm.pose.bones[0].head
print(json.dumps({{"actions": sorted(a.name for a in bpy.data.actions), "active": action.name,
                  "frames": end - int(action.frame_range[0]) + 1, "hips": list(hips)}}))
""")
    assert got["active"] != "walk" and "walk" in got["actions"]  # a new action; the original kept
    assert got["frames"] >= 60
    x, y, _ = got["hips"]
    assert abs(x - start[0]) < 0.3 and y < start[1] - 1.0, (start, got["hips"])  # down the curve (-Y), on it

    code = strnn_batch.main(["denoise", "--format", "bvh", str(scene), "--out", str(out),
                             "--extension", str(extension)])
    assert code == 0, capsys.readouterr().err
    assert frames_of(out / "scene.denoise.bvh") == 60 and scene.read_bytes() == before

    # --denoise-model picks the model Denoise uses: the main model here gives another result
    code = strnn_batch.main(["denoise", "--format", "bvh", str(scene), "--out", str(out / "main"),
                             "--denoise-model", str(REPO / "models" / "strnn_default"), "--extension", str(extension)])
    assert code == 0, capsys.readouterr().err
    if (REPO / "models" / "strnn_denoise" / "model.json").exists():
        assert (out / "main" / "scene.denoise.bvh").read_bytes() != (out / "scene.denoise.bvh").read_bytes()


def test_a_denoise_model_folder_without_a_model_is_refused(tmp_path, capsys):
    with pytest.raises(SystemExit) as stop:
        strnn_batch.main(["denoise", "--denoise-model", str(tmp_path), str(tmp_path / "a.bvh")])
    assert stop.value.code == 2 and f"--denoise-model {tmp_path}: no model.json" in capsys.readouterr().err


def test_transfer_takes_onto_a_character(tmp_path, extension, capsys):
    """Each take is moved onto the rig of a character .blend (a smaller Mixamo-named body): one copy of the
    .blend per take with the new action on the rig; the character file is never changed."""
    clip = write_bvh(tmp_path / "walk.bvh", walking_skeleton(60))
    small = write_bvh(tmp_path / "small.bvh", walking_skeleton(2) * 0.8)
    hero = tmp_path / "hero.blend"
    run_bpy(f"""
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_anim.bvh(filepath={str(small)!r})
rig = bpy.context.active_object
rig.name = "Hero"
rig.animation_data_clear()
bpy.data.objects.new("Prop", None)
bpy.ops.wm.save_as_mainfile(filepath={str(hero)!r})
print(json.dumps({{}}))
""")
    before = hero.read_bytes()
    out = tmp_path / "out"
    code = strnn_batch.main(["transfer", "--target", str(hero), "--rig", "Hero", str(clip), "--out", str(out),
                             "--extension", str(extension)])
    assert code == 0, capsys.readouterr().err
    assert hero.read_bytes() == before
    got = run_bpy(f"""
bpy.ops.wm.open_mainfile(filepath={str(out / "walk.transfer.blend")!r})
rig = bpy.data.objects["Hero"]
action = rig.animation_data.action
print(json.dumps({{"armatures": [o.name for o in bpy.data.objects if o.type == "ARMATURE"],
                  "action": action.name, "frames": int(action.frame_range[1] - action.frame_range[0]) + 1,
                  "record": action["strnn"]["operation"]}}))
""")
    assert got["armatures"] == ["Hero"] and got["record"] == "Transfer Motion" and got["frames"] == 60
    with pytest.raises(SystemExit):
        strnn_batch.main(["transfer", "--target", str(clip), str(clip)])
    assert "not a .blend, .fbx, .glb, .gltf or USD file" in capsys.readouterr().err


@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)], ids=["ctrl-c", "sigterm"])
def test_interrupting_a_batch_stops_cleanly(tmp_path, extension, sig, code):
    """Stopped after the first file: exit 130 / 143, the summary and the report say what finished and what
    did not, no temporary or partial file is left, and nothing is written afterwards."""
    takes = [write_bvh(tmp_path / f"walk{i}.bvh", walking_skeleton(40)) for i in range(24)]
    out, report = tmp_path / "out", tmp_path / "report.json"
    scratch = tmp_path / "tmp"  # the batch's own temporary folder: other tests running beside it make theirs
    scratch.mkdir()
    proc = subprocess.Popen([sys.executable, str(REPO / "scripts" / "strnn_batch.py"), "extend", "--frames", "5",
                             *map(str, takes), "--out", str(out), "--report", str(report), "--extension",
                             str(extension)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=os.environ | {"TMPDIR": str(scratch)})
    first = proc.stdout.readline()  # the first file's progress line
    assert "walk" in first, first
    proc.send_signal(sig)  # the workers, started, take a fraction of a second per file: most files are left
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == code, stderr[-2000:]
    assert "interrupted" in stdout and signal.Signals(sig).name in stderr
    assert "Traceback" not in stdout + stderr
    done = json.loads(report.read_text())
    assert done["interrupted"] and done["processed"] >= 1
    assert sorted(p.name for p in out.rglob("*") if ".tmp" in p.name) == []
    assert list(scratch.iterdir()) == []  # the workers' folders, Blender's own temporary ones in them, removed
    written = sorted(p.name for p in out.rglob("*.bvh"))
    time.sleep(3.0)
    assert sorted(p.name for p in out.rglob("*.bvh")) == written  # no worker writes after the batch exited


def test_unwritable_outputs_are_found_before_any_work(tmp_path, capsys):
    take = write_bvh(tmp_path / "walk.bvh", walking_skeleton(40))
    blocked = tmp_path / "file"
    blocked.write_text("")
    with pytest.raises(SystemExit):
        strnn_batch.main(["extend", str(take), "--out", str(blocked / "out")])
    assert "--out" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        strnn_batch.main(["extend", str(take), "--out", str(tmp_path / "o"), "--report", str(blocked / "r.json")])
    assert "--report" in capsys.readouterr().err


def test_extend_before_the_start_writes_the_lead_in_first(tmp_path, extension, capsys):
    """``--before-start``: the new frames come first in the file, then the take's own, unchanged."""
    walk = walking_skeleton(40)
    clip = write_bvh(tmp_path / "walk.bvh", walk)
    out = tmp_path / "out"
    assert strnn_batch.main(["extend", "--frames", "10", "--before-start", str(clip), "--out", str(out),
                             "--extension", str(extension)]) == 0
    got = canonical_positions(read_bvh(out / "walk.extend.bvh"))
    assert len(got) == 50
    take = canonical_positions(read_bvh(clip))
    assert np.abs(got[10:] - take).max() < 1e-3 * np.ptp(take[..., 1])  # the take's frames, after the lead-in


def test_foot_lock_on_a_ground_mesh_in_a_blend_file(tmp_path, extension, capsys):
    """``footlock --ground MESH`` pins the feet on a mesh of the .blend (here a floor under the walk); a name the
    file lacks fails that file with what to fix, and its output is not written."""
    clip = write_bvh(tmp_path / "walk.bvh", walking_skeleton(60))
    scene = tmp_path / "scene.blend"
    run_bpy(f"""
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_anim.bvh(filepath={str(clip)!r})
mesh = bpy.data.meshes.new("Floor")
mesh.from_pydata([(-20, -20, 0), (20, -20, 0), (20, 20, 0), (-20, 20, 0)], [], [(0, 1, 2, 3)])
bpy.context.scene.collection.objects.link(bpy.data.objects.new("Floor", mesh))
bpy.ops.wm.save_as_mainfile(filepath={str(scene)!r})
print(json.dumps(0))
""")
    out = tmp_path / "out"
    code = strnn_batch.main(["footlock", "--ground", "Nowhere", str(scene), "--out", str(out),
                             "--extension", str(extension)])
    assert code == 1 and "no object or collection named 'Nowhere' in the file for --ground" in capsys.readouterr().out
    assert not (out / "scene.footlock.blend").exists()
    code = strnn_batch.main(["footlock", "--ground", "Floor", str(scene), "--out", str(out),
                             "--extension", str(extension)])
    assert code == 0, capsys.readouterr().err
    got = run_bpy(f"""
bpy.ops.wm.open_mainfile(filepath={str(out / "scene.footlock.blend")!r})
arm = next(o for o in bpy.data.objects if o.type == "ARMATURE")
print(json.dumps(arm.animation_data.action["strnn"]["ground"].to_dict()))
""")
    assert got == {"object": "Floor", "frames_without": 0}


def batch_rows(capsys, extension: Path, report: Path, *argv: str) -> tuple[int, dict[str, dict]]:
    """Run the batch with ``argv`` and a JSON report at ``report``: its exit status and the report's rows by file
    name."""
    code = strnn_batch.main([*argv, "--report", str(report), "--extension", str(extension)])
    capsys.readouterr()
    return code, {Path(r["file"]).name: r for r in json.loads(report.read_text())["files"]}


def hero_blend(tmp_path: Path) -> Path:
    """A character .blend: the rig ``Hero``, a walking skeleton 0.8 x the size, with no action."""
    hero = tmp_path / "hero.blend"
    run_bpy(f"""
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_anim.bvh(filepath={str(write_bvh(tmp_path / "small.bvh", walking_skeleton(2) * 0.8))!r})
rig = bpy.context.active_object
rig.name = "Hero"
rig.animation_data_clear()
bpy.ops.wm.save_as_mainfile(filepath={str(hero)!r})
print(json.dumps(0))
""")
    return hero


def transferred(capsys, extension: Path, hero: Path, take: Path, out: Path, *flags: str) -> list[str]:
    """The names of the files the batch's transfer of ``take`` onto the character file ``hero`` writes in ``out``
    (the character's file left as it was)."""
    before = hero.read_bytes()
    code = strnn_batch.main(["transfer", "--target", str(hero), str(take), "--out", str(out),
                             "--extension", str(extension), *flags])
    assert code == 0, capsys.readouterr().err
    assert hero.read_bytes() == before
    return sorted(p.name for p in out.iterdir())


FBX_READ = """
def read_fbx(path):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_scene.fbx(filepath=path)
    arms = [o for o in bpy.data.objects if o.type == "ARMATURE"]
    arm = arms[0]
    first, last = (int(round(f)) for f in arm.animation_data.action.frame_range)
    heads = []
    for f in range(first, last + 1):
        bpy.context.scene.frame_set(f)
        heads.append([list(arm.matrix_world @ b.head) for b in arm.pose.bones])
    return {"armatures": len(arms), "meshes": sorted(o.name for o in bpy.data.objects if o.type == "MESH"),
            "bones": sorted(b.name for b in arm.data.bones), "fps": bpy.context.scene.render.fps,
            "parent": arm.parent.name if arm.parent else None,
            "first": first, "heads": heads}
"""


def test_fbx_takes_are_extended_into_fbx_and_moved_onto_a_character(tmp_path, extension, capsys):
    """An FBX (Blender's exporter: a 30 fps walk on its armature under a root null, a mesh skinned to it) is read
    with Blender's FBX importer and written back as FBX: the armature under its null and its mesh, no bone added,
    the take's own frames where they were and the new ones after them, at the take's frame rate. As a take it moves
    onto a character .blend, which keeps nothing the FBX brought, and onto a character FBX, whose results are FBX
    files of it (its rig, its mesh, the take its motion). A broken FBX is a failure with its reason, and so is an FBX
    of two walkers run on in place with --every-armature (its file would keep one), left as it was."""
    clip = write_bvh(tmp_path / "walk.bvh", walking_skeleton(60))
    take = tmp_path / "takes" / "walk.fbx"
    take.parent.mkdir()
    run_bpy(f"""
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_anim.bvh(filepath={str(clip)!r}, update_scene_fps=True, update_scene_duration=True)
arm = bpy.context.active_object
null = bpy.data.objects.new("Null", None)  # a root null above the armature, as Maya and MotionBuilder write it
bpy.context.scene.collection.objects.link(null)
null.location, null.rotation_euler = (1.0, 2.0, 0.0), (0.0, 0.0, 0.5)
arm.parent = null
bpy.ops.mesh.primitive_cube_add(size=0.3, location=(0, 0, 1))
body = bpy.context.active_object
body.name = "Body"
body.modifiers.new("Armature", "ARMATURE").object = arm
body.parent = arm
bpy.ops.export_scene.fbx(filepath={str(take)!r})
print(json.dumps(0))
""")
    (tmp_path / "takes" / "broken.fbx").write_bytes(take.read_bytes()[:300])
    out = tmp_path / "out"
    code = strnn_batch.main(["extend", "--frames", "20", str(tmp_path / "takes"), "--out", str(out),
                             "--extension", str(extension)])
    err = capsys.readouterr().err
    assert code == 1 and "broken.fbx" in err and "FBX importer could not read it" in err, err
    assert sorted(p.name for p in out.iterdir()) == ["walk.extend.fbx"]
    got = run_bpy(FBX_READ + f"""
print(json.dumps({{"take": read_fbx({str(take)!r}), "extended": read_fbx({str(out / "walk.extend.fbx")!r})}}))
""")
    before, after = got["take"], got["extended"]
    assert after["armatures"] == 1 and after["meshes"] == ["Body"] and after["bones"] == before["bones"]
    assert after["parent"] == before["parent"] == "Null"
    assert after["fps"] == before["fps"] == 30 and after["first"] == before["first"]
    heads, new = np.array(before["heads"]), np.array(after["heads"])
    assert len(new) == len(heads) + 20
    assert np.abs(new[:len(heads)] - heads).max() < 1e-3  # the take's own frames, as they were
    step = np.linalg.norm(np.diff(new, axis=0), axis=-1).mean(-1)
    assert 0.5 < step[len(heads):].mean() / step[:len(heads) - 1].mean() < 1.6  # walking on, not frozen
    cast = tmp_path / "cast.fbx"  # two walkers in one FBX: --every-armature --in-place would keep one of them
    run_bpy(f"""
bpy.ops.wm.read_factory_settings(use_empty=True)
for x in (0.0, 2.0):
    bpy.ops.import_anim.bvh(filepath={str(clip)!r})
    bpy.context.active_object.location.x = x
bpy.ops.export_scene.fbx(filepath={str(cast)!r})
print(json.dumps(0))
""")
    kept = cast.read_bytes()
    code = strnn_batch.main(["extend", "--frames", "10", "--every-armature", "--in-place", str(cast), "--extension",
                             str(extension)])
    err = capsys.readouterr().err
    assert code == 1 and "a .fbx result holds one" in err and cast.read_bytes() == kept, err
    hero = hero_blend(tmp_path)
    code = strnn_batch.main(["transfer", "--target", str(hero), str(take), "--out", str(out),
                             "--extension", str(extension)])
    assert code == 0, capsys.readouterr().err
    got = run_bpy(f"""
bpy.ops.wm.open_mainfile(filepath={str(out / "walk.transfer.blend")!r})
rig = bpy.data.objects["Hero"]
action = rig.animation_data.action
print(json.dumps({{"objects": sorted(o.name for o in bpy.data.objects), "record": action["strnn"]["operation"],
                  "frames": int(action.frame_range[1] - action.frame_range[0]) + 1}}))
""")
    assert got["objects"] == ["Hero"] and got["record"] == "Transfer Motion" and got["frames"] == 60, got
    hero_fbx = tmp_path / "hero.fbx"  # a character given as FBX (a rig with its mesh): the results are FBX too
    run_bpy(f"""
bpy.ops.wm.open_mainfile(filepath={str(hero)!r})
rig = bpy.data.objects["Hero"]
bpy.ops.mesh.primitive_cube_add(size=0.3, location=(0, 0, 1))
skin = bpy.context.active_object
skin.name = "Skin"
skin.modifiers.new("Armature", "ARMATURE").object = rig
skin.parent = rig
bpy.ops.export_scene.fbx(filepath={str(hero_fbx)!r}, add_leaf_bones=False)
print(json.dumps(0))
""")
    assert transferred(capsys, extension, hero_fbx, take, out / "fbx") == ["walk.transfer.fbx"]
    got = run_bpy(FBX_READ + f"""
print(json.dumps({{"moved": read_fbx({str(out / "fbx" / "walk.transfer.fbx")!r})}}))
""")
    moved = got["moved"]
    assert moved["armatures"] == 1 and moved["meshes"] == ["Skin"] and len(moved["heads"]) == 60, moved["meshes"]
    travel = np.linalg.norm(np.array(moved["heads"])[-1, 0, :2] - np.array(moved["heads"])[0, 0, :2])
    assert travel > 0.5  # the hero walks (the take's 60 frames of walking, on its shorter legs)


def test_a_finished_batch_leaves_no_temporary_folder(tmp_path, extension, monkeypatch):
    """The workers' user folders go when the batch ends, with the temporary folders Blender makes in them (a
    worker ends without Blender's own clean-up, which left a blender_* folder in the system's temporary folder per
    worker and run)."""
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    monkeypatch.setenv("TMPDIR", str(scratch))
    monkeypatch.setattr(tempfile, "tempdir", None)
    takes = [write_bvh(tmp_path / f"walk{i}.bvh", walking_skeleton(40)) for i in range(2)]
    code = strnn_batch.main(["extend", "--frames", "5", "--jobs", "2", *map(str, takes), "--out",
                             str(tmp_path / "out"), "--extension", str(extension)])
    assert code == 0 and len(list((tmp_path / "out").glob("*.bvh"))) == 2
    assert list(scratch.iterdir()) == []


def test_fbx_inputs_are_found_and_named_and_a_crowd_is_no_fbx(tmp_path, capsys):
    """Folders give up their FBX files beside BVH and .blend ones (any case of the suffix), an FBX's result is an FBX
    by default (a transfer's is the character's format), and --every-armature, whose result holds every character,
    writes a .blend for an FBX and refuses --format fbx as it does bvh."""
    (tmp_path / "takes" / "sub").mkdir(parents=True)
    for name in ("a.bvh", "sub/b.FBX", "c.blend", "notes.txt"):
        (tmp_path / "takes" / name).write_bytes(b"")
    found, problems = strnn_batch.collect([tmp_path / "takes"])
    assert sorted(str(rel) for _, rel in found) == ["a.bvh", "c.blend", "sub/b.FBX"] and problems == []
    parse = strnn_batch.build_parser().parse_args
    fbx = tmp_path / "takes" / "sub" / "b.FBX"
    assert strnn_batch.output_path(fbx, Path("sub/b.FBX"), parse(["extend", str(fbx)])).name == "b.extend.fbx"
    hero = tmp_path / "hero.fbx"
    hero.write_bytes(b"")
    args = parse(["transfer", "--target", str(hero), str(fbx)])
    assert strnn_batch.output_path(fbx, Path("b.FBX"), args).name == "b.transfer.fbx"
    with pytest.raises(SystemExit):
        strnn_batch.main(["extend", "--every-armature", "--format", "fbx", str(tmp_path / "takes" / "c.blend")])
    assert "--every-armature writes .blend or USD results" in capsys.readouterr().err
    crowd = parse(["extend", "--every-armature", str(fbx)])  # an FBX of a cast: every character, so a .blend
    assert strnn_batch.output_path(fbx, Path("sub/b.FBX"), crowd).name == "b.extend.blend"


def test_gltf_inputs_are_found_and_named_and_a_gltf_is_not_replaced_in_place(tmp_path, extension, capsys):
    """Folders give up .glb and .gltf files; a glTF's result is a .glb (a .gltf's too: glTF's one-file form, written
    whole), a glTF character's transfers are .glb files, --every-armature refuses --format glb, and --in-place on a
    .gltf (two files, the .gltf and its .bin, which cannot be replaced at once) fails with the fix, the file left."""
    (tmp_path / "takes").mkdir()
    for name in ("a.glb", "b.GLTF", "b.bin"):
        (tmp_path / "takes" / name).write_bytes(b"")
    found, problems = strnn_batch.collect([tmp_path / "takes"])
    assert sorted(str(rel) for _, rel in found) == ["a.glb", "b.GLTF"] and problems == []
    parse = strnn_batch.build_parser().parse_args
    glb, gltf = tmp_path / "takes" / "a.glb", tmp_path / "takes" / "b.GLTF"
    assert strnn_batch.output_path(glb, Path("a.glb"), parse(["extend", str(glb)])).name == "a.extend.glb"
    assert strnn_batch.output_path(gltf, Path("b.GLTF"), parse(["denoise", str(gltf)])).name == "b.denoise.glb"
    args = parse(["transfer", "--target", str(gltf), str(tmp_path / "walk.bvh")])
    assert strnn_batch.output_path(tmp_path / "walk.bvh", Path("walk.bvh"), args).name == "walk.transfer.glb"
    with pytest.raises(SystemExit):
        strnn_batch.main(["extend", "--every-armature", "--format", "glb", str(glb)])
    assert "--every-armature writes .blend or USD results" in capsys.readouterr().err
    gltf.write_text('{"asset": {"version": "2.0"}}')
    code = strnn_batch.main(["extend", "--in-place", str(gltf), "--extension", str(extension)])
    err = capsys.readouterr().err
    assert code == 1 and "write .glb results to --out" in err and gltf.read_text() == '{"asset": {"version": "2.0"}}'


GLTF_READ = """
def read_gltf(path, fps):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.context.scene.render.fps = fps  # glTF's times in seconds, each key on a frame at the file's rate
    bpy.ops.import_scene.gltf(filepath=path, disable_bone_shape=True)
    arm = next(o for o in bpy.data.objects if o.type == "ARMATURE")
    action = arm.animation_data.action
    first, last = action.frame_range
    heads = []
    for f in range(int(round(first)), int(round(last)) + 1):
        bpy.context.scene.frame_set(f)
        heads.append([list(arm.matrix_world @ b.head) for b in arm.pose.bones])
    return {"objects": sorted([o.name, o.type, o.parent.name if o.parent else None] for o in bpy.data.objects),
            "bones": sorted(b.name for b in arm.data.bones), "action": action.name,
            "first": first, "last": last, "heads": heads}
"""

GLTF_MAKE = """
def make_gltf(bvh, path, second=False):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_anim.bvh(filepath=bvh, update_scene_fps=True, update_scene_duration=True)
    arm = bpy.context.active_object
    null = bpy.data.objects.new("Null", None)  # a root node above the armature
    bpy.context.scene.collection.objects.link(null)
    null.location = (1.0, 2.0, 0.0)
    arm.parent = null
    bpy.ops.mesh.primitive_cube_add(size=0.3, location=(0, 0, 1))  # skinned: glTF's armature is a skin's joints
    body = bpy.context.active_object
    body.name = "Body"
    body.modifiers.new("Armature", "ARMATURE").object = arm
    body.parent = arm
    body.vertex_groups.new(name="Hips").add(range(len(body.data.vertices)), 1.0, "REPLACE")
    if second:  # a second clip, stashed in an NLA track, exported as the file's second animation
        idle = arm.animation_data.action.copy()
        idle.name = "zz_idle"
        arm.animation_data.nla_tracks.new().strips.new("zz_idle", 1, idle)
    bpy.ops.export_scene.gltf(filepath=path, export_format="GLB")
"""


def assert_extended_by_20(before: dict, after: dict) -> None:
    """``after``, a file read back as the glTF and USD readers here read it, is the 60-frame walk ``before`` extended
    by 20 frames: the same objects and bones, the take's frames where they were, the new ones walking on."""
    assert after["objects"] == before["objects"] and after["bones"] == before["bones"]
    assert round(after["first"], 3) == round(before["first"], 3) == 1.0 and round(after["last"], 3) == 80.0
    heads, new = np.array(before["heads"]), np.array(after["heads"])
    assert len(heads) == 60 and len(new) == 80
    assert np.abs(new[:60] - heads).max() < 1e-3  # the take's own frames, as they were
    step = np.linalg.norm(np.diff(new, axis=0), axis=-1).mean(-1)
    assert 0.5 < step[60:].mean() / step[:59].mean() < 1.6  # walking on, not frozen


def without_skin(glb: Path, path: Path) -> None:
    """Write ``glb`` to ``path`` without its skins (as a tool that exports a node tree with no mesh writes it)."""
    import struct

    data = glb.read_bytes()
    length = struct.unpack_from("<I", data, 12)[0]
    document = json.loads(data[20:20 + length])
    document.pop("skins")
    for node in document["nodes"]:
        node.pop("skin", None)
    text = json.dumps(document).encode()
    text += b" " * (-len(text) % 4)
    rest = data[20 + length:]
    header = struct.pack("<4sII", b"glTF", 2, 20 + len(text) + len(rest))
    path.write_bytes(header + struct.pack("<I4s", len(text), b"JSON") + text + rest)


def test_gltf_takes_are_extended_into_glb_and_moved_onto_a_character(tmp_path, extension, capsys):
    """A .glb (Blender's exporter: a 30 fps walk on an armature under a root node, a cube skinned to it) is read
    with Blender's glTF importer at the rate its keys were made at and written back as a .glb: the same objects and
    bones, the take's frames where they were and the new ones walking on after them, at 30 frames a second (not the
    factory 24, at which its keys would land 0.8 frames apart). A broken .glb and one with no skin (no armature in
    Blender) fail with their reasons; a file of two animations runs on its first and says so. As a take it moves
    onto a character .glb (a .glb result of it; the character's file unchanged)."""
    import batch_worker

    clip = write_bvh(tmp_path / "walk.bvh", walking_skeleton(60))
    takes = tmp_path / "takes"
    takes.mkdir()
    run_bpy(GLTF_MAKE + f"""
make_gltf({str(clip)!r}, {str(takes / "walk.glb")!r})
make_gltf({str(clip)!r}, {str(takes / "two.glb")!r}, second=True)
print(json.dumps(0))
""")
    take = takes / "walk.glb"
    (takes / "broken.glb").write_bytes(take.read_bytes()[:-100])  # its binary chunk cut short
    (takes / "cut.glb").write_bytes(take.read_bytes()[:600])  # its JSON cut short
    without_skin(take, takes / "bare.glb")
    out = tmp_path / "out"
    code, rows = batch_rows(capsys, extension, tmp_path / "report.json", "extend", "--frames", "20", str(takes),
                            "--out", str(out))
    assert code == 1, rows
    assert "glTF importer could not read it" in rows["broken.glb"]["reason"], rows["broken.glb"]
    assert rows["cut.glb"]["reason"].startswith("broken glTF: its JSON cannot be read"), rows["cut.glb"]
    assert "has no skin" in rows["bare.glb"]["reason"] and "skinned mesh" in rows["bare.glb"]["reason"]
    assert rows["walk.glb"]["status"] == rows["two.glb"]["status"] == "ok"
    assert any("2 animations" in n and "'zz_idle'" not in n for n in rows["two.glb"]["notes"]), rows["two.glb"]
    assert not any("animations" in n for n in rows["walk.glb"]["notes"])
    assert sorted(p.name for p in out.iterdir()) == ["two.extend.glb", "walk.extend.glb"]
    result = batch_worker.gltf_document(out / "walk.extend.glb")
    assert batch_worker.gltf_frame_rate(result) == 30 and len(result["animations"]) == 1
    got = run_bpy(GLTF_READ + f"""
print(json.dumps({{"take": read_gltf({str(take)!r}, 30), "extended": read_gltf({str(out / "walk.extend.glb")!r}, 30)}}))
""")
    before, after = got["take"], got["extended"]
    assert after["action"] == result["animations"][0]["name"] != before["action"]  # the new action, by its name
    assert_extended_by_20(before, after)
    hero = tmp_path / "hero.glb"  # a character given as glTF (a rig with its skinned mesh, no animation)
    small = write_bvh(tmp_path / "small.bvh", walking_skeleton(2) * 0.8)
    run_bpy(GLTF_MAKE + f"""
make_gltf({str(small)!r}, {str(hero)!r})
print(json.dumps(0))
""")
    assert transferred(capsys, extension, hero, take, out / "hero") == ["walk.transfer.glb"]
    got = run_bpy(GLTF_READ + f"""
print(json.dumps({{"moved": read_gltf({str(out / "hero" / "walk.transfer.glb")!r}, 30)}}))
""")
    moved = got["moved"]
    assert sorted(o[1] for o in moved["objects"]) == ["ARMATURE", "EMPTY", "MESH"], moved["objects"]
    assert len(moved["heads"]) == 60
    travel = np.linalg.norm(np.array(moved["heads"])[-1, 0, :2] - np.array(moved["heads"])[0, 0, :2])
    assert travel > 0.5  # the hero walks (the take's 60 frames of walking, on its shorter legs)


def test_a_gltf_frame_rate_is_read_from_its_keys(tmp_path):
    """The rate of a glTF's keys: (count - 1) / (last - first) of its densest sampler, where that is a frame rate
    (within 1 %); keys at a few poses, a file with no animation or a malformed one say none. The .glb's header and
    JSON are checked with a plain reason."""
    import batch_worker

    def document(*samplers):  # (count, first, last) per sampler's times
        accessors = [{"count": n, "min": [a], "max": [b]} for n, a, b in samplers]
        return {"accessors": accessors, "animations": [{"samplers": [{"input": i} for i in range(len(samplers))]}]}

    rate = batch_worker.gltf_frame_rate
    assert rate(document((115, 1 / 30, 115 / 30))) == 30
    assert rate(document((2, 0.0, 4.0), (241, 0.0, 4.0))) == 60  # the densest sampler (a constant channel has 2)
    assert rate(document((97, 0.0, 96 / 24 * 1.001))) == 24  # 23.976 fps: keys 0.999 frames apart at 24
    assert rate(document((5, 0.0, 2.0))) is None  # keys at a few poses: no rate
    assert rate(document((101, 0.0, 100 / 27))) is None  # 27 keys a second: no frame rate
    assert rate({"asset": {"version": "2.0"}}) is None and rate({"animations": [{"samplers": [{"input": 3}]}]}) is None
    assert batch_worker.gltf_animations({"animations": [{"name": "Walk"}, {}]}) == ["Walk", "animation 1"]
    (tmp_path / "a.glb").write_bytes(b"PK\x03\x04" + bytes(40))
    with pytest.raises(batch_worker.BatchError, match="does not start with glTF's header"):
        batch_worker.gltf_document(tmp_path / "a.glb")
    (tmp_path / "b.gltf").write_text('{"asset": ')
    with pytest.raises(batch_worker.BatchError, match="broken glTF: its JSON cannot be read"):
        batch_worker.gltf_document(tmp_path / "b.gltf")


USD_MAKE = """
def make_usd(bvh, path, **options):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_anim.bvh(filepath=bvh, update_scene_fps=True, update_scene_duration=True)
    arm = bpy.context.active_object
    arm.name = "Actor"
    bpy.ops.mesh.primitive_cube_add(size=0.3, location=(0, 0, 1))  # skinned: a UsdSkel character
    body = bpy.context.active_object
    body.name = "Body"
    body.modifiers.new("Armature", "ARMATURE").object = arm
    body.parent = arm
    body.vertex_groups.new(name="Hips").add(range(len(body.data.vertices)), 1.0, "REPLACE")
    bpy.ops.wm.usd_export(filepath=path, export_animation=True, **options)
"""

USD_READ = """
from pxr import Usd, UsdGeom


def read_usd(path, fps):
    stage = Usd.Stage.Open(path)
    settings = [stage.GetTimeCodesPerSecond(), str(UsdGeom.GetStageUpAxis(stage)),
                UsdGeom.GetStageMetersPerUnit(stage), str(stage.GetDefaultPrim().GetPath())]
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.context.scene.render.fps = fps
    bpy.ops.wm.usd_import(filepath=path)
    arm = next(o for o in bpy.data.objects if o.type == "ARMATURE")
    first, last = arm.animation_data.action.frame_range
    heads = []
    for f in range(int(round(first)), int(round(last)) + 1):
        bpy.context.scene.frame_set(f)
        heads.append([list(arm.matrix_world @ b.head) for b in arm.pose.bones])
    return {"stage": settings, "objects": sorted([o.name, o.type] for o in bpy.data.objects),
            "bones": sorted(b.name for b in arm.data.bones), "first": first, "last": last, "heads": heads}
"""


def test_usd_takes_are_extended_in_their_own_axes_units_and_rate(tmp_path, extension, capsys):
    """A USD character (Blender's exporter: a 30 fps walk on a skinned armature) is read with Blender's USD importer
    at the stage's time codes a second, which the importer leaves to the caller (at the factory 24 a 30 fps take
    would play slow), and written back as USD in the input's own form: a Y-up stage in centimetres under /World
    stays so (as Maya's or Houdini's pipelines write it), a Z-up one in metres too, .usdc binary and .usda text; the
    same objects and bones, the take's frames where they were and the new ones walking on. A USD with no skeleton
    and a broken file fail with their reasons. A take moves onto a USD character (a USD file of it)."""
    pytest.importorskip("pxr")
    clip = write_bvh(tmp_path / "walk.bvh", walking_skeleton(60))
    takes = tmp_path / "takes"
    takes.mkdir()
    run_bpy(USD_MAKE + f"""
make_usd({str(clip)!r}, {str(takes / "maya.usdc")!r}, convert_orientation=True, export_global_up_selection="Y",
         export_global_forward_selection="NEGATIVE_Z", convert_scene_units="CENTIMETERS", root_prim_path="/World")
make_usd({str(clip)!r}, {str(takes / "plain.usda")!r})
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.mesh.primitive_cube_add()
bpy.ops.wm.usd_export(filepath={str(takes / "prop.usda")!r})
print(json.dumps(0))
""")
    (takes / "broken.usdc").write_bytes((takes / "maya.usdc").read_bytes()[:300])
    out = tmp_path / "out"
    code, rows = batch_rows(capsys, extension, tmp_path / "report.json", "extend", "--frames", "20", str(takes),
                            "--out", str(out))
    assert code == 1, rows
    assert rows["broken.usdc"]["reason"].startswith("broken USD: Pixar's library cannot open it"), rows["broken.usdc"]
    assert "has no skeleton" in rows["prop.usda"]["reason"], rows["prop.usda"]
    assert rows["maya.usdc"]["status"] == rows["plain.usda"]["status"] == "ok"
    code, looked = batch_rows(capsys, extension, tmp_path / "inspect.json", "inspect", str(takes / "maya.usdc"))
    assert code == 0 and looked["maya.usdc"]["notes"][0] == "USD stage at 30 time codes a second, Y up, 0.01 m a " \
        "unit, default prim /World: results are written back so", looked
    assert sorted(p.name for p in out.iterdir()) == ["maya.extend.usdc", "plain.extend.usda"]
    assert (out / "plain.extend.usda").read_text().startswith("#usda")  # text stays text
    got = run_bpy(USD_READ + f"""
print(json.dumps({{name: read_usd(path, 30) for name, path in [
    ("maya", {str(takes / "maya.usdc")!r}), ("maya_extended", {str(out / "maya.extend.usdc")!r}),
    ("plain", {str(takes / "plain.usda")!r}), ("plain_extended", {str(out / "plain.extend.usda")!r})]}}))
""")
    assert got["maya"]["stage"] == got["maya_extended"]["stage"] == [30.0, "Y", 0.01, "/World"]
    assert got["plain"]["stage"] == got["plain_extended"]["stage"] == [30.0, "Z", 1.0, "/root"]
    for name in ("maya", "plain"):
        assert_extended_by_20(got[name], got[name + "_extended"])
    hero = tmp_path / "hero.usda"  # a character given as USD (a rig with its skinned mesh)
    run_bpy(USD_MAKE + f"""
make_usd({str(write_bvh(tmp_path / "small.bvh", walking_skeleton(2) * 0.8))!r}, {str(hero)!r})
print(json.dumps(0))
""")
    assert transferred(capsys, extension, hero, takes / "maya.usdc", out / "hero") == ["maya.transfer.usda"]
    moved = run_bpy(USD_READ + f"""
print(json.dumps(read_usd({str(out / "hero" / "maya.transfer.usda")!r}, 30)))
""")
    assert moved["stage"] == [30.0, "Z", 1.0, "/root"] and len(moved["heads"]) == 60
    # the character as its file has it (the rig under its Xform, its mesh), nothing of the take's
    assert moved["objects"] == [["Actor", "EMPTY"], ["Cube", "MESH"], ["small", "ARMATURE"]], moved["objects"]
    travel = np.linalg.norm(np.array(moved["heads"])[-1, 0, :2] - np.array(moved["heads"])[0, 0, :2])
    assert travel > 0.5  # the hero walks (the take's 60 frames of walking, on its shorter legs)


def test_every_skeleton_of_a_usd_shot_is_extended_into_one_usd_file(tmp_path, extension, capsys):
    """--every-armature on a USD shot of two skinned walkers (60 and 70 frames): one USD file of both, each skeleton
    extended by 20 frames from its own take (the take's frames where they were), in the shot's axes and units."""
    pytest.importorskip("pxr")
    clips = [write_bvh(tmp_path / f"walk{i}.bvh", walking_skeleton(60 + 10 * i)) for i in range(2)]
    shot = tmp_path / "shot.usda"
    run_bpy(f"""
bpy.ops.wm.read_factory_settings(use_empty=True)
for i, clip in enumerate({[str(c) for c in clips]!r}):
    bpy.ops.import_anim.bvh(filepath=clip, update_scene_fps=True, update_scene_duration=True)
    arm = bpy.context.active_object
    arm.location.x = 2.0 * i
    bpy.ops.mesh.primitive_cube_add(size=0.3, location=(2.0 * i, 0, 1))
    body = bpy.context.active_object
    body.modifiers.new("Armature", "ARMATURE").object = arm
    body.parent = arm
    body.vertex_groups.new(name="Hips").add(range(len(body.data.vertices)), 1.0, "REPLACE")
bpy.ops.wm.usd_export(filepath={str(shot)!r}, export_animation=True, convert_orientation=True,
                      export_global_up_selection="Y", convert_scene_units="CENTIMETERS", root_prim_path="/World")
print(json.dumps(0))
""")
    code, rows = batch_rows(capsys, extension, tmp_path / "report.json", "extend", "--frames", "20",
                            "--every-armature", str(shot), "--out", str(tmp_path / "out"))
    assert code == 0, rows
    result = tmp_path / "out" / "shot.extend.usda"
    got = run_bpy(USD_READ + f"""
def heads(path):
    found = {{}}
    read_usd(path, 30)  # (the stage's settings; the armatures are read below, each at its own frames)
    for arm in sorted((o for o in bpy.data.objects if o.type == "ARMATURE"), key=lambda o: o.name):
        first, last = arm.animation_data.action.frame_range
        frames = []
        for f in range(int(round(first)), int(round(last)) + 1):
            bpy.context.scene.frame_set(f)
            frames.append([list(arm.matrix_world @ b.head) for b in arm.pose.bones])
        found[arm.name] = frames
    return found
print(json.dumps({{"shot": heads({str(shot)!r}), "result": heads({str(result)!r}),
                  "stage": read_usd({str(result)!r}, 30)["stage"]}}))
""")
    assert got["stage"][1:3] == ["Y", 0.01]
    assert sorted(got["result"]) == sorted(got["shot"]) and len(got["shot"]) == 2
    for name, frames in got["shot"].items():
        take, new = np.array(frames), np.array(got["result"][name])
        assert len(new) == len(take) + 20, (name, len(take), len(new))
        assert np.abs(new[:len(take)] - take).max() < 1e-3  # each take's own frames, as they were


def test_usd_inputs_are_found_and_named_and_a_usd_skeleton_holds_one_take(tmp_path, extension, capsys):
    """Folders give up .usd, .usda, .usdc and .usdz files, each written back in its own form (--format usd for
    another input: a BVH's as Blender writes USD, at the frame rate its rounded frame time is near, as an FBX of it
    is); a USD character's transfers are USD files of it; a USD crowd's result is a USD file (a BVH's a
    .blend); and several takes into a USD skeleton, which holds one animation, fail with the fix (an FBX's two
    takes)."""
    (tmp_path / "lib").mkdir()
    for name in ("a.usd", "b.USDA", "c.usdc", "d.usdz", "notes.txt"):
        (tmp_path / "lib" / name).write_bytes(b"")
    found, problems = strnn_batch.collect([tmp_path / "lib"])
    assert sorted(str(rel) for _, rel in found) == ["a.usd", "b.USDA", "c.usdc", "d.usdz"] and problems == []
    parse = strnn_batch.build_parser().parse_args
    named = {rel.name: strnn_batch.output_path(path, rel, parse(["extend", str(path)])).name for path, rel in found}
    assert named == {"a.usd": "a.extend.usd", "b.USDA": "b.extend.usda", "c.usdc": "c.extend.usdc",
                     "d.usdz": "d.extend.usdz"}
    walk = write_bvh(tmp_path / "walk.bvh", walking_skeleton(60))
    text = walk.read_text()  # the frame time as capture files round it
    walk.write_text(re.sub(r"Frame Time:.*", "Frame Time: 0.0333333", text))
    assert strnn_batch.output_path(walk, Path("walk.bvh"), parse(["extend", "--format", "usd", str(walk)])).name \
        == "walk.extend.usd"
    code, rows = batch_rows(capsys, extension, tmp_path / "bvh.json", "extend", "--frames", "10", "--format", "usda",
                            str(walk), "--out", str(tmp_path / "usd"))
    text = (tmp_path / "usd" / "walk.extend.usda").read_text()  # Blender's own form: Z up, metres, /root
    assert code == 0 and 'upAxis = "Z"' in text and "metersPerUnit = 1\n" in text and 'defaultPrim = "root"' in text
    assert "timeCodesPerSecond = 30\n" in text and "endTimeCode = 70\n" in text  # 30, not Blender's 30.00003
    code, rows = batch_rows(capsys, extension, tmp_path / "fbx.json", "extend", "--frames", "10", "--format", "fbx",
                            str(walk), "--out", str(tmp_path / "fbx"))
    got = run_bpy(f"""
bpy.ops.import_scene.fbx(filepath={str(tmp_path / "fbx" / "walk.extend.fbx")!r})
print(json.dumps([bpy.context.scene.render.fps, bpy.context.scene.render.fps_base]))
""")
    assert code == 0 and got == [30, 1.0], got  # an FBX at 30 frames a second, not a custom 30.00003
    args = parse(["transfer", "--target", str(tmp_path / "lib" / "c.usdc"), str(walk)])
    assert strnn_batch.output_path(walk, Path("walk.bvh"), args).name == "walk.transfer.usdc"
    crowd = parse(["extend", "--every-armature", str(walk)])  # a crowd's result holds them all: a USD stage can
    assert strnn_batch.output_path(walk, Path("walk.bvh"), crowd).name == "walk.extend.blend"
    crowd = parse(["extend", "--every-armature", str(tmp_path / "lib" / "c.usdc")])
    assert strnn_batch.output_path(tmp_path / "lib" / "c.usdc", Path("c.usdc"), crowd).name == "c.extend.usdc"
    takes = tmp_path / "takes"
    two_takes(takes, fbx=True)
    (takes / "two.glb").unlink()
    code, rows = batch_rows(capsys, extension, tmp_path / "report.json", "extend", "--every-action", "--frames",
                            "10", "--format", "usd", str(takes), "--out", str(tmp_path / "out"))
    assert code == 1 and "found 2 takes, and a USD skeleton holds one" in rows["two.fbx"]["reason"], rows
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_a_rigify_character_that_came_back_through_usd_is_read_by_its_family(tmp_path, extension, capsys):
    """A Rigify character's deform skeleton exported to USD comes back with ``_`` for the ``-`` and ``.`` USD's names
    allow none of (``DEF_thigh_L``): it is still read as Rigify's deform bones (it failed: "no bone found for
    Head"), and extended into a USD file of it, the take's frames where they were."""
    pytest.importorskip("pxr")
    take = tmp_path / "rigify.usdc"
    run_bpy(f"""
import sys
sys.path.insert(0, "tests/blender")
from scenes import rigify_walk
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.context.scene.render.fps = 30
rig = rigify_walk(60)
bpy.context.scene.frame_start, bpy.context.scene.frame_end = 1, 60
bpy.ops.wm.usd_export(filepath={str(take)!r}, export_animation=True)
print(json.dumps(0))
""")
    code, rows = batch_rows(capsys, extension, tmp_path / "inspect.json", "inspect", str(take))
    assert code == 0 and "mapped from its rigify_deform bone names" in rows["rigify.usdc"]["notes"][1], rows
    code, rows = batch_rows(capsys, extension, tmp_path / "report.json", "extend", "--frames", "20", str(take),
                            "--out", str(tmp_path / "out"))
    assert code == 0, rows
    got = run_bpy(USD_READ + f"""
print(json.dumps({{"take": read_usd({str(take)!r}, 30),
                  "extended": read_usd({str(tmp_path / "out" / "rigify.extend.usdc")!r}, 30)}}))
""")
    assert "DEF_thigh_L" in got["take"]["bones"] and got["extended"]["bones"] == got["take"]["bones"]
    heads, new = np.array(got["take"]["heads"]), np.array(got["extended"]["heads"])
    assert len(heads) == 60 and len(new) == 80 and np.abs(new[:60] - heads).max() < 1e-3
    assert np.linalg.norm(np.diff(new[60:], axis=0), axis=-1).mean() > 1e-3  # the new frames move


def test_a_killed_workers_half_written_usd_is_discarded(tmp_path):
    """A worker killed while Blender's USD exporter writes leaves USD's own sibling temporary file (the name before
    the suffix, a dot and six letters or digits: ``walk.extend.tmp.2j0kv5``) beside the worker's ``.tmp`` name: both
    go; the result of an earlier run and other files stay."""
    out = tmp_path / "out"
    out.mkdir()
    names = ["walk.extend.tmp.usdc", "walk.extend.tmp.2j0kv5", "walk.extend.usdc", "walk.extend.tmp.notes.txt",
             "run.extend.tmp.a1b2c3"]
    for name in names:
        (out / name).write_bytes(b"x")
    strnn_batch._discard_partial({"output": str(out / "walk.extend.usdc")})
    assert sorted(p.name for p in out.iterdir()) == ["run.extend.tmp.a1b2c3", "walk.extend.tmp.notes.txt",
                                                     "walk.extend.usdc"]


def test_a_usd_stage_is_read_for_its_rate_axes_units_and_root(tmp_path):
    """What the batch reads from a USD stage with Pixar's library: its time codes a second (USD's 24 where the file
    says none, its framesPerSecond where it gives that alone), up axis, metres per unit and default prim; a file it
    cannot open is a plain reason. A rate near a frame rate is that rate (1 / 0.0333333 s is 30), another is kept
    as Blender writes an odd rate."""
    pytest.importorskip("pxr")
    import types

    import batch_worker

    def stage(header: str) -> dict:
        (tmp_path / "s.usda").write_text(f'#usda 1.0\n(\n{header}\n)\n\ndef Xform "Hero"\n{{\n}}\n')
        return batch_worker.usd_stage(tmp_path / "s.usda")

    got = stage('defaultPrim = "Hero"\ntimeCodesPerSecond = 60\nupAxis = "Y"\nmetersPerUnit = 0.01')
    assert got == {"rate": 60.0, "up": "Y", "meters": 0.01, "root": "Hero"}
    assert stage('framesPerSecond = 25')["rate"] == 25.0  # its frames a second where it gives no time codes
    assert stage('') == {"rate": 24.0, "up": "Y", "meters": 0.01, "root": ""}  # USD's own defaults
    (tmp_path / "bad.usdc").write_bytes(b"PXR-USDC" + bytes(40))
    with pytest.raises(batch_worker.BatchError, match="broken USD: Pixar's library cannot open it"):
        batch_worker.usd_stage(tmp_path / "bad.usdc")

    def rate(value: float) -> tuple[int, float]:
        scene = types.SimpleNamespace(render=types.SimpleNamespace(fps=24, fps_base=1.0))
        batch_worker.set_frame_rate(scene, value)
        return scene.render.fps, round(scene.render.fps / scene.render.fps_base, 4)

    assert rate(30.00003) == (30, 30.0) and rate(1 / 0.0333333) == (30, 30.0)
    assert rate(23.976) == (24, 24.0)  # NTSC film within 1 % of 24, as a glTF's keys are read
    assert rate(27.0) == (27, 27.0) and rate(59.94)[1] == 60.0


def two_takes(folder: Path, then: str = "", fbx: bool = False) -> None:
    """``folder``/two.glb: a 60-frame walk on a skinned rig with a second animation (``zz_idle``), made by
    Blender's exporter (with ``fbx`` also ``folder``/two.fbx of the rig, its takes ``walk`` and ``zz_idle``); then
    ``then`` runs in the same Blender, the rig ``arm``."""
    folder.mkdir()
    clip = write_bvh(folder.parent / "walk.bvh", walking_skeleton(60))
    run_bpy(GLTF_MAKE + f"""
make_gltf({str(clip)!r}, {str(folder / "two.glb")!r}, second=True)
arm = next(o for o in bpy.data.objects if o.type == "ARMATURE")
if {fbx!r}:
    arm.animation_data.action.name = "walk"
    arm.select_set(True)
    bpy.ops.export_scene.fbx(filepath={str(folder / "two.fbx")!r}, bake_anim_use_all_actions=True,
                             bake_anim_use_nla_strips=False, add_leaf_bones=False)
""" + then + "\nprint(json.dumps(0))\n")


def test_action_picks_the_take_of_an_fbx_or_the_animation_of_a_gltf(tmp_path, extension, capsys):
    """A file of several takes runs on the one Blender's importer plays and says so, naming --action; --action NAME
    runs on another (an FBX take by its name, a glTF animation by its), and a name the file does not have fails with
    the names it has, nothing written for it."""
    takes = tmp_path / "takes"
    two_takes(takes, fbx=True)
    report = tmp_path / "report.json"

    def run(*flags):
        code = strnn_batch.main(["extend", "--frames", "10", str(takes), "--out", str(tmp_path / "out"),
                                 "--report", str(report), "--extension", str(extension), *flags])
        capsys.readouterr()
        return code, {Path(r["file"]).name: r for r in json.loads(report.read_text())["files"]}

    code, rows = run()
    assert code == 0
    assert any("2 animations" in n and "'walk'" in n and "--action NAME" in n for n in rows["two.glb"]["notes"])
    assert any("2 takes" in n and "'walk'" in n and "--action NAME" in n for n in rows["two.fbx"]["notes"]), \
        rows["two.fbx"]  # (the importer plays the first by name; its ARMATURE|...| prefix left out)
    code, rows = run("--action", "zz_idle")
    assert code == 0 and not any("--action" in n for r in rows.values() for n in r["notes"])
    got = run_bpy(GLTF_READ + FBX_READ + f"""
glb = read_gltf({str(tmp_path / "out" / "two.extend.glb")!r}, 30)
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.fbx(filepath={str(tmp_path / "out" / "two.extend.fbx")!r})
print(json.dumps({{"glb": glb["action"], "fbx": [a.name for a in bpy.data.actions]}}))
""")
    assert got["glb"].startswith("zz_idle") and len(got["fbx"]) == 1 and "zz_idle" in got["fbx"][0], got
    (tmp_path / "out" / "two.extend.glb").unlink()
    code, rows = run("--action", "nope")
    assert code == 1 and rows["two.glb"]["reason"] == "no action named 'nope' for --action; the file has 'walk', " \
        "'zz_idle'", rows["two.glb"]
    assert "no action named 'nope'" in rows["two.fbx"]["reason"] and not (tmp_path / "out" / "two.extend.glb").exists()
    with pytest.raises(SystemExit):
        strnn_batch.main(["extend", "--every-armature", "--action", "walk", str(takes)])
    assert "--action is not for --every-armature" in capsys.readouterr().err


def test_every_action_runs_on_each_take_into_one_file(tmp_path, extension, capsys):
    """--every-action: each take of a .glb (two animations) and of an FBX (three) is extended in turn into one
    result that holds every new take, each as long as its take and the new frames, the notes named by take; moved onto a
    character .blend, every take of the FBX is a new action of the rig (the first playing, the others in muted NLA
    tracks, saved with the file); a BVH result, which holds one take, is refused for several."""
    import batch_worker

    short = write_bvh(tmp_path / "short.bvh", walking_skeleton(40))
    takes = tmp_path / "takes"
    two_takes(takes, f"""
bpy.ops.import_anim.bvh(filepath={str(short)!r})
other = bpy.context.active_object
arm.animation_data.action = other.animation_data.action  # a 40-frame take beside the 60-frame one
arm.animation_data.action.name = "short"
bpy.data.objects.remove(other)
for o in bpy.data.objects:
    o.select_set(o is arm)
bpy.ops.export_scene.fbx(filepath={str(takes / "two.fbx")!r}, use_selection=True, bake_anim_use_all_actions=True,
                         bake_anim_use_nla_strips=False, add_leaf_bones=False)
""")
    out, report = tmp_path / "out", tmp_path / "report.json"
    code = strnn_batch.main(["extend", "--frames", "10", "--every-action", str(takes), "--out", str(out),
                             "--report", str(report), "--extension", str(extension)])
    assert code == 0, capsys.readouterr().err
    rows = {Path(r["file"]).name: r for r in json.loads(report.read_text())["files"]}
    assert all(n.startswith(("walk", "zz_idle")) for n in rows["two.glb"]["notes"]), rows["two.glb"]["notes"]
    glb = batch_worker.gltf_document(out / "two.extend.glb")
    assert sorted(a["name"] for a in glb["animations"]) == ["walk.extended", "zz_idle.extended"]
    got = run_bpy(f"""
spans = {{}}
for path, read in (({str(out / "two.extend.fbx")!r}, bpy.ops.import_scene.fbx),
                   ({str(out / "two.extend.glb")!r}, bpy.ops.import_scene.gltf)):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.context.scene.render.fps = 30
    read(filepath=path)
    spans[path[-3:]] = {{a.name.rsplit("|", 1)[-1]: [round(f) for f in a.frame_range] for a in bpy.data.actions}}
print(json.dumps(spans))
""")
    assert got["glb"] == {"walk.extended": [1, 70], "zz_idle.extended": [1, 70]}, got  # each 60-frame take + 10
    taken = run_bpy(f"""
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.fbx(filepath={str(takes / "two.fbx")!r})
print(json.dumps({{a.name.rsplit("|", 1)[-1]: [round(f) for f in a.frame_range] for a in bpy.data.actions}}))
""")
    assert len(taken) >= 2 and got["fbx"] == {f"{name}.extended": [first, last + 10]
                                              for name, (first, last) in taken.items()}, (taken, got)
    hero = hero_blend(tmp_path)
    assert transferred(capsys, extension, hero, takes / "two.fbx", out / "hero", "--every-action") == \
        ["two.transfer.blend"]
    got = run_bpy(f"""
bpy.ops.wm.open_mainfile(filepath={str(out / "hero" / "two.transfer.blend")!r})
ad = bpy.data.objects["Hero"].animation_data
print(json.dumps({{"plays": round(ad.action.frame_range[1] - ad.action.frame_range[0]) + 1,
                  "stashed": [[t.mute, round(s.action.frame_range[1] - s.action.frame_range[0]) + 1]
                              for t in ad.nla_tracks for s in t.strips]}}))
""")
    assert sorted([got["plays"]] + [n for _, n in got["stashed"]]) == sorted(b - a + 1 for a, b in taken.values())
    assert all(mute for mute, _ in got["stashed"]), got
    code = strnn_batch.main(["extend", "--every-action", "--format", "bvh", str(takes / "two.glb"), "--out",
                             str(out / "bvh"), "--extension", str(extension)])
    err = capsys.readouterr().err
    assert code == 1 and "--every-action found 2 takes, and a BVH holds one" in err, err
    with pytest.raises(SystemExit):
        strnn_batch.main(["extend", "--every-action", "--action", "walk", str(takes)])
    assert "give one of them" in capsys.readouterr().err


def test_every_action_of_a_blend_is_its_action_and_its_stashed_ones():
    """--every-action on a .blend runs on the action the armature plays and those of its muted NLA tracks (stashed,
    as Blender's Stash and glTF importer leave them), not on a track that plays (a layer of the motion)."""
    got = run_bpy(f"""
import sys
sys.path.insert(0, {str(REPO / "scripts")!r})
import batch_worker
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.object.armature_add()
arm = bpy.context.active_object
ad = arm.animation_data_create()
played, stashed, layer = (bpy.data.actions.new(name) for name in ("played", "stashed", "layer"))
ad.action = played
for action, mute in ((stashed, True), (layer, False)):
    track = ad.nla_tracks.new()
    track.strips.new(action.name, 1, action)
    track.mute = mute
print(json.dumps([a.name for a in batch_worker.every_take(arm, [])]))
""")
    assert got == ["played", "stashed"]


def test_inspect_says_what_each_file_holds_and_writes_nothing(tmp_path, extension, capsys, monkeypatch):
    """``inspect``: for each file the armature the operators would run on, how its bones map, its takes (the one that
    plays first, each one's frames and how familiar its motion is to the model) and the rate read (a walk at another
    pace than people walk: the Keys per Second to set), or the reason the operators would refuse it (a prop's
    armature: a failure, exit status 1); nothing is written, not even an output folder."""
    takes = tmp_path / "takes"
    two_takes(takes, fbx=True, then=f"""
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.object.armature_add()  # a prop's rig: one bone, keyed
prop = bpy.context.active_object
prop.name = "Lamp"
prop.pose.bones[0].keyframe_insert("location", frame=1)
prop.pose.bones[0].location.z = 1.0
prop.pose.bones[0].keyframe_insert("location", frame=20)
bpy.ops.wm.save_as_mainfile(filepath={str(takes / "prop.blend")!r})
""")
    write_bvh(takes / "slow.bvh", walking_skeleton(240, fps=60.0), fps=24.0)  # a 60 fps walk its file says is 24
    monkeypatch.chdir(tmp_path)
    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    report = tmp_path / "report.json"
    code = strnn_batch.main(["inspect", str(takes), "--report", str(report), "--extension", str(extension)])
    capsys.readouterr()
    rows = {Path(r["file"]).name: r for r in json.loads(report.read_text())["files"]}
    assert code == 1 and sorted(rows) == ["prop.blend", "slow.bvh", "two.fbx", "two.glb"]
    slow = "; ".join(rows["slow.bvh"]["notes"])  # the pace's note, as the operators would give it after a run
    assert "set Keys per Second to 60" in slow and slow.endswith("(in a batch: --keys-per-second 60)"), slow
    assert not any("Keys per Second" in n for name in ("two.fbx", "two.glb") for n in rows[name]["notes"])
    assert rows["prop.blend"]["status"] == "failed" and "the operators would refuse it" in rows["prop.blend"]["reason"]
    for name in ("two.fbx", "two.glb"):
        notes = "; ".join(rows[name]["notes"])
        assert rows[name]["status"] == "ok" and rows[name]["output"] == "", rows[name]
        assert "21 joints mapped from its" in notes and "2 takes, the first plays, at 30 keys a second" in notes
        for take in ("walk", "zz_idle"):  # the synthetic walk is stiffer than any capture: the model says so
            assert f"'{take}' frames 1-60: this motion is unlike what the model learnt (it rebuilds it " in notes, notes
    assert sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*")) == sorted(before + [Path("report.json")])


def test_inspect_tells_motion_the_model_knows_from_motion_it_does_not(mocap_root, smallest_bvh, tmp_path, extension,
                                                                     capsys):
    """On real takes, ``inspect`` says a Bandai walk (motion like the training data) is motion the model knows and a
    CMU martial-arts take (an action family kept out of training) is not, as Extend's report would."""
    walk = smallest_bvh(mocap_root / "bandai-namco", "*_walk_normal_*.bvh")
    fight = smallest_bvh(mocap_root / "cmu" / "acrnn-dance" / "martial")
    report = tmp_path / "report.json"
    code = strnn_batch.main(["inspect", str(walk), str(fight), "--report", str(report), "--extension", str(extension)])
    capsys.readouterr()
    rows = {Path(r["file"]).name: "; ".join(r["notes"]) for r in json.loads(report.read_text())["files"]}
    assert code == 0
    assert "motion the model knows" in rows[walk.name], rows[walk.name]
    assert "unlike what the model learnt" in rows[fight.name], rows[fight.name]


def test_an_unreal_mannequin_from_fbx_is_extended_with_its_ik_bones_on_its_feet_and_hands(tmp_path, extension,
                                                                                            capsys):
    """An Unreal Engine mannequin walking, its IK bones (hanging from the root) keyed on its feet and hands on every
    frame as Unreal's animations have them, written by Blender's FBX exporter: ``inspect`` names the bones that go with
    the bones they follow, and the extension written back as FBX keeps each IK bone on its foot or hand over the new
    frames (they stayed where the take ended before)."""
    take = tmp_path / "mannequin.fbx"
    run_bpy(f"""
import sys
sys.path.insert(0, "tests/blender")
from scenes import build_armature, key_walk, unreal_bones
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.context.scene.render.fps = 30
rig = build_armature("SK_Mannequin", unreal_bones())
key_walk(rig, 60, "pelvis", ("thigh_l", "thigh_r"), ("calf_l", "calf_r"), ("upperarm_l", "upperarm_r"))
bones = rig.pose.bones
for f in range(1, 61):
    bpy.context.scene.frame_set(f)
    for ik, on in {FOLLOWED!r}.items():
        bones[ik].matrix = bones[on].matrix.copy()
        bpy.context.view_layer.update()
        bones[ik].keyframe_insert("location", frame=f)
        bones[ik].keyframe_insert("rotation_quaternion", frame=f)
bpy.context.scene.frame_start, bpy.context.scene.frame_end = 1, 60
bpy.ops.export_scene.fbx(filepath={str(take)!r}, add_leaf_bones=False, bake_anim_use_all_actions=True,
                         bake_anim_use_nla_strips=False)
print(json.dumps(0))
""")
    code, rows = batch_rows(capsys, extension, tmp_path / "inspect.json", "inspect", str(take))
    assert code == 0, rows
    notes = "; ".join(rows["mannequin.fbx"]["notes"])
    assert "5 bones outside the bone map keyed with the bones they follow (ik_foot_l on foot_l, " \
                         "ik_foot_r on foot_r, ik_hand_gun on hand_r" in notes, notes
    code, rows = batch_rows(capsys, extension, tmp_path / "report.json", "extend", "--frames", "20", str(take),
                            "--out", str(tmp_path / "out"))
    assert code == 0, rows
    got = run_bpy(f"""
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.fbx(filepath={str(tmp_path / "out" / "mannequin.extend.fbx")!r})
arm = next(o for o in bpy.data.objects if o.type == "ARMATURE")
first, last = (int(round(x)) for x in arm.animation_data.action.frame_range)
off, travel = [], []
for f in range(first, last + 1):
    bpy.context.scene.frame_set(f)
    bones = arm.pose.bones
    off.append(max((arm.matrix_world @ bones[ik].head - arm.matrix_world @ bones[on].head).length
                   for ik, on in {FOLLOWED!r}.items()))
    travel.append(list(arm.matrix_world @ bones["ik_foot_l"].head))
print(json.dumps({{"first": first, "last": last, "off": off, "travel": travel}}))
""")
    assert (got["first"], got["last"]) == (1, 80)
    assert max(got["off"]) < 2e-3, got["off"]
    assert np.linalg.norm(np.subtract(got["travel"][-1], got["travel"][59])) > 0.1  # the feet walk on, and with them


FOLLOWED = {"ik_foot_l": "foot_l", "ik_foot_r": "foot_r", "ik_hand_gun": "hand_r", "ik_hand_l": "hand_l",
            "ik_hand_r": "hand_r"}


def test_a_rigify_character_from_a_gltf_file_is_extended_with_all_its_skin(tmp_path, extension, capsys):
    """A generated Rigify rig walking, its head nodding, a skin of its own (a small tetrahedron at each deform bone,
    weighted to it alone), written as glTF with every bone, as a character from a model store comes: the exporter
    baked every bone and dropped the constraints, and the importer gives the mesh a vertex group for each of the 706
    joints, weighted or not. The batch reads it as the control rig it was (its deform bones mapped, the rest of its
    skin carried) and extends it into glTF: the face keeps its place on the head and no bone of the skin stays
    behind (it was refused before)."""
    take = tmp_path / "hero.glb"
    run_bpy(f"""
import addon_utils, bmesh, sys
sys.path.insert(0, "tests/blender")
from scenes import key_walk, nod_head
addon_utils.enable("rigify", default_set=True)
bpy.ops.wm.read_factory_settings(use_empty=True)
addon_utils.enable("rigify", default_set=True)
bpy.context.scene.render.fps = 30
bpy.ops.object.armature_human_metarig_add()
bpy.ops.pose.rigify_generate()
rig = bpy.data.objects["rig"]
for bone in ("thigh_parent.L", "thigh_parent.R", "upper_arm_parent.L", "upper_arm_parent.R"):
    rig.pose.bones[bone]["IK_FK"] = 1.0
key_walk(rig, 60, "torso", ("thigh_fk.L", "thigh_fk.R"), ("shin_fk.L", "shin_fk.R"),
         ("upper_arm_fk.L", "upper_arm_fk.R"), step=0.02)
nod_head(rig)
deform = [b for b in rig.data.bones if b.use_deform]
mesh = bpy.data.meshes.new("skin")
bm = bmesh.new()
for b in deform:
    h = b.head_local
    vs = [bm.verts.new((h.x + x, h.y + y, h.z + z)) for x, y, z in ((0.01, 0, 0), (-0.01, 0, 0), (0, 0.01, 0),
                                                                   (0, 0, 0.01))]
    for face in ((0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3)):
        bm.faces.new([vs[i] for i in face])
bm.to_mesh(mesh)
body = bpy.data.objects.new("skin", mesh)
bpy.context.scene.collection.objects.link(body)
body.parent = rig
body.modifiers.new("Armature", "ARMATURE").object = rig
for k, b in enumerate(deform):
    body.vertex_groups.new(name=b.name).add(list(range(4 * k, 4 * k + 4)), 1.0, "REPLACE")
bpy.context.scene.frame_start, bpy.context.scene.frame_end = 1, 60
bpy.ops.export_scene.gltf(filepath={str(take)!r}, export_format="GLB", export_animations=True)
print(json.dumps(len(deform)))
""")
    code, rows = batch_rows(capsys, extension, tmp_path / "inspect.json", "inspect", str(take))
    notes = "; ".join(rows["hero.glb"]["notes"])
    assert code == 0 and "mapped from its rigify_deform bone names; a control rig an exporter baked (its controls " \
                         "drive nothing): results keyed on its deform bones" in notes, rows
    code, rows = batch_rows(capsys, extension, tmp_path / "report.json", "extend", "--frames", "20", str(take),
                            "--out", str(tmp_path / "out"))
    assert code == 0, rows
    got = run_bpy(f"""
import numpy as np
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.context.scene.render.fps = 30
bpy.ops.import_scene.gltf(filepath={str(tmp_path / "out" / "hero.extend.glb")!r})
arm = next(o for o in bpy.data.objects if o.type == "ARMATURE")
body = next(o for o in bpy.data.objects if o.type == "MESH" and len(o.vertex_groups))
weighed = {{g.group for v in body.data.vertices for g in v.groups if g.weight > 0}}
skin = sorted(g.name for g in body.vertex_groups if g.index in weighed)
first, last = (int(round(x)) for x in arm.animation_data.action.frame_range)
mats = []
for f in range(first, last + 1):
    bpy.context.scene.frame_set(f)
    mats.append([(np.array(arm.matrix_world) @ np.array(arm.pose.bones[n].matrix)).tolist() for n in skin])
print(json.dumps({{"skin": skin, "first": first, "last": last, "mats": mats}}))
""")
    skin, mats = got["skin"], np.array(got["mats"])  # the take's 60 frames, then the 20 new ones
    assert (got["first"], got["last"]) == (1, 80) and len(skin) > 100
    hips, head = skin.index("DEF-spine"), skin.index("DEF-spine.006")
    assert np.linalg.norm(mats[-1, hips, :2, 3] - mats[59, hips, :2, 3]) > 0.1  # it walks on
    reach = np.linalg.norm(mats[:, :, :3, 3] - mats[:, hips:hips + 1, :3, 3], axis=-1)  # each bone from the hips
    grew = reach[60:].max(axis=0) - reach[:60].max(axis=0)
    assert grew.max() < 0.05, skin[int(grew.argmax())]  # none stays behind as the body walks on
    face = [k for k, n in enumerate(skin) if n.split("-")[1].split(".")[0] in ("lid", "nose", "lip", "brow", "jaw",
                                                                               "chin", "cheek", "ear", "temple")]
    on_head = np.linalg.inv(mats[60:, head])[:, None] @ mats[60:, face]
    assert len(face) > 40 and np.abs(on_head - on_head[:1]).max() < 2e-3
