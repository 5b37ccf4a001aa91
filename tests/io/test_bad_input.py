"""Bad input gives an error that names the file (and line) and what is wrong, never a bare traceback."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import pytest

from model_core.io.bvh import BvhError, read_bvh
from model_core.io.bvh_export import write_bvh
from model_core.model.dataset import DataError, find_bvh, load_folder
from model_core.motion.synthetic import walking_skeleton
from model_core.rig.rigs import RigError, load_clip

REPO = Path(__file__).resolve().parents[2]

HEADER = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  End Site
  {
    OFFSET 0 1 0
  }
}
MOTION
"""  # the MOTION line is line 11


def _raises(path: Path, line: int | None, what: str):
    """Assert that reading ``path`` raises BvhError '<path>:<line>: ...what...'."""
    with pytest.raises(BvhError) as err:
        read_bvh(path)
    msg = str(err.value)
    where = re.escape(f"{path}:{line}:") if line is not None else re.escape(f"{path}:")
    assert re.match(where, msg), msg
    assert what in msg, msg
    return msg


def test_empty_file(write_text):
    _raises(write_text("empty.bvh", ""), 1, "file is empty")
    _raises(write_text("blank.bvh", "\n  \n"), 1, "file is empty")


def test_not_a_bvh_file(write_text):
    _raises(write_text("notes.bvh", "hello world\n"), 1, "expected 'HIERARCHY', found 'hello'")


def test_missing_file_and_directory(tmp_path):
    _raises(tmp_path / "nope.bvh", None, "cannot read file")
    _raises(tmp_path, None, "cannot read file")


def test_truncated_motion_names_the_frame_count(write_text):
    path = write_text("short.bvh", HEADER + "Frames: 3\nFrame Time: 0.033333\n0 0 0 0 0 0\n0 0 0 0 0 0\n")
    msg = _raises(path, 15, "truncated motion")
    assert "header says 3 frames of 6 channels but only 2 complete frames follow (from line 14)" in msg


def test_truncated_inside_the_hierarchy(write_text):
    cut = "\n".join(HEADER.splitlines()[:5]) + "\n"  # stops after the CHANNELS line
    _raises(write_text("cut.bvh", cut), 5, "no MOTION section (file truncated?)")
    _raises(write_text("mid.bvh", "HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0"), 4, "unexpected end of file")
    _raises(write_text("nomotion.bvh", HEADER.replace("MOTION\n", "")), 10, "no MOTION section")


def test_malformed_number_in_motion_names_its_line(write_text):
    path = write_text("bad.bvh", HEADER + "Frames: 2\nFrame Time: 0.033333\n0 0 0 0 0 0\n0 0 1,5 0 0 0\n")
    _raises(path, 15, "motion value '1,5' is not a number")


def test_malformed_offset_and_frame_count(write_text):
    _raises(write_text("off.bvh", HEADER.replace("OFFSET 0 1 0", "OFFSET 0 x 0")), 8, "found 'x'")
    _raises(write_text("frames.bvh", HEADER + "Frames: many\nFrame Time: 0.03\n"), 12, "expected a frame count")
    zero_time = HEADER + "Frames: 1\nFrame Time: 0\n0 0 0 0 0 0\n"
    _raises(write_text("time.bvh", zero_time), 13, "Frame Time must be positive")
    _raises(write_text("zero.bvh", HEADER + "Frames: 0\nFrame Time: 0.03\n"), 12, "declares 0 frames")


def test_nan_and_inf_in_motion_name_the_frame_and_channel(write_text):
    path = write_text("nan.bvh", HEADER + "Frames: 2\nFrame Time: 0.033333\n0 0 0 0 0 0\n0 nan 0 0 0 0\n")
    _raises(path, 15, "frame 1 has nan in Hips's Yposition: motion values must be finite")
    path = write_text("inf.bvh", HEADER + "Frames: 2\nFrame Time: 0.033333\n0 0 0 0 0 inf\n0 0 0 0 0 0\n")
    _raises(path, 14, "frame 0 has inf in Hips's")


@pytest.mark.parametrize("time,what", [("10", "far from any capture rate"), ("0.0001", "far from any capture rate"),
                                       ("-0.033", "must be positive"), ("0", "must be positive")])
def test_implausible_frame_times_are_refused_with_the_fix(write_text, time, what):
    path = write_text("t.bvh", HEADER + f"Frames: 1\nFrame Time: {time}\n0 0 0 0 0 0\n")
    _raises(path, 13, what)
    _raises(path, 13, "configs/data.toml")
    assert read_bvh(path, fps=30.0).fps == 30.0  # a folder override replaces the header


def test_capture_rates_from_10_to_500_fps_are_read(write_text):
    """Video to optical capture (Vicon and Qualisys record at 250, OptiTrack at 360 frames a second)."""
    for fps in (10, 24, 30, 60, 120, 240, 250, 360, 500):
        path = write_text(f"r{fps}.bvh", HEADER + f"Frames: 1\nFrame Time: {1 / fps:.6f}\n0 0 0 0 0 0\n")
        assert abs(read_bvh(path).fps - fps) < 0.001 * fps


def test_bad_channels_and_structure(write_text):
    _raises(write_text("chan.bvh", HEADER.replace("Zrotation Xrotation", "Zrotation Wrotation")), 5,
            "unknown channel 'Wrotation' on joint Hips")
    _raises(write_text("count.bvh", HEADER.replace("CHANNELS 6", "CHANNELS 9")), 5, "expected 0 to 6")
    _raises(write_text("brace.bvh", HEADER.replace("MOTION", "}\nMOTION")), 11, "unbalanced '}'")
    orphan = "HIERARCHY\nEnd Site\n{\nOFFSET 0 0 0\n}\nMOTION\nFrames: 1\nFrame Time: 0.03\n\n"
    _raises(write_text("orphan.bvh", orphan), 2, "End Site outside of a joint block")
    stray = "HIERARCHY\nJOINT Arm\n{\n"
    _raises(write_text("stray.bvh", stray), 2, "JOINT outside of a ROOT block")


def test_unknown_rig_names_the_file_and_missing_joints(write_text):
    path = write_text("robot.bvh", HEADER + "Frames: 1\nFrame Time: 0.033333\n0 0 0 0 0 0\n")
    with pytest.raises(RigError) as err:
        load_clip(path)
    msg = str(err.value)
    assert msg.startswith(f"{path}: unknown rig")
    assert "spine" in msg and "l_knee" in msg and "Known families:" in msg


def test_empty_and_missing_data_folders(tmp_path):
    with pytest.raises(DataError, match=re.escape(f"{tmp_path}: no .bvh files found")):
        find_bvh(tmp_path)
    (tmp_path / "notes.txt").write_text("not motion")
    with pytest.raises(DataError, match="no .bvh files found"):
        load_folder(tmp_path, progress=False)
    with pytest.raises(DataError, match=re.escape(f"{tmp_path / 'missing'}: data folder does not exist")):
        find_bvh(tmp_path / "missing")


def test_folder_of_only_bad_files_lists_each_failure(tmp_path):
    (tmp_path / "a.bvh").write_text("")
    (tmp_path / "b.bvh").write_text(HEADER + "Frames: 1\nFrame Time: 0.033333\n0 0 0 0 0 0\n")
    with pytest.raises(DataError) as err:
        load_folder(tmp_path, workers=1, progress=False)
    msg = str(err.value)
    assert "none of the 2 BVH files could be read" in msg
    assert f"{tmp_path / 'a.bvh'}:1: file is empty" in msg
    assert f"{tmp_path / 'b.bvh'}: unknown rig" in msg


def test_bad_files_beside_good_ones_are_reported_not_fatal(tmp_path):
    write_bvh(tmp_path / "good.bvh", walking_skeleton(40))
    (tmp_path / "bad.bvh").write_text("HIERARCHY\nROOT\n")
    data = load_folder(tmp_path, workers=1, progress=False)
    assert [c.name for c in data.clips] == ["good.bvh"]
    assert len(data.failures) == 1 and data.failures[0].startswith(str(tmp_path / "bad.bvh"))


def test_demo_without_a_model_prints_an_error_not_a_traceback(tmp_path, capsys):
    spec = importlib.util.spec_from_file_location("demo", REPO / "scripts" / "demo.py")
    demo = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(demo)
    assert demo.main(["--model", str(tmp_path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "missing model.safetensors" in err
    assert not (tmp_path / "out").exists()
