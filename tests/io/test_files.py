"""files.unwritable: why files could not be written somewhere, found without creating anything; files.write_atomic
from two processes at once; files.write_json writes strict JSON."""

from __future__ import annotations

import json
import math
import multiprocessing
import time

import numpy as np
import pytest

from model_core.io.files import unwritable, write_atomic, write_json


def test_a_folder_to_be_made_under_a_writable_one_is_fine_and_nothing_is_created(tmp_path):
    assert unwritable(tmp_path / "a" / "b") == ""
    assert not (tmp_path / "a").exists()
    assert unwritable(tmp_path) == ""


def test_a_path_under_a_file_is_refused_naming_the_file(tmp_path):
    blocked = tmp_path / "file"
    blocked.write_text("")
    assert unwritable(blocked / "out") == f"{blocked} is not a folder"


def _write_slowly(path: str, text: str, started) -> None:
    def write(tmp):
        tmp.write_text(text[: len(text) // 2])
        started.wait(5)  # both processes are part way through their temporary file
        time.sleep(0.1)
        with open(tmp, "a") as f:
            f.write(text[len(text) // 2:])
    write_atomic(path, write)


def test_two_processes_writing_one_file_at_once_both_finish_and_leave_a_whole_file(tmp_path):
    target = tmp_path / "cache.npz"
    ctx = multiprocessing.get_context("fork")
    started = ctx.Barrier(2)
    texts = ["a" * 1000, "b" * 1000]
    procs = [ctx.Process(target=_write_slowly, args=(str(target), t, started)) for t in texts]
    for p in procs:
        p.start()
    for p in procs:
        p.join(20)
    assert [p.exitcode for p in procs] == [0, 0]
    assert target.read_text() in texts
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cache.npz"]


def _strict(token):
    raise ValueError(f"not JSON: {token}")


def test_json_holds_a_figure_with_nothing_to_measure_as_null_and_numpy_as_numbers(tmp_path):
    # evaluate.py's feet figures are NaN for a rollout with no second of locomotion; JSON has no NaN, and a
    # strict reader (jq, a browser, another language) refuses the whole file if one is written.
    doc = {"touch_fraction": [float("nan"), 1.0, np.float32(0.5)], "speed": np.float64(math.inf),
           "rows": (np.int64(3), np.array([1.5, np.nan])), "ok": True, "name": None,
           "mean": np.asarray(2.5)}
    path = write_json(tmp_path / "evaluation.json", doc)
    back = json.loads(path.read_text(), parse_constant=_strict)
    assert back == {"touch_fraction": [None, 1.0, 0.5], "speed": None, "rows": [3, [1.5, None]], "ok": True,
                    "name": None, "mean": 2.5}
    with pytest.raises(ValueError, match="not JSON"):
        json.loads(json.dumps(float("nan")), parse_constant=_strict)  # what json.dumps alone writes
