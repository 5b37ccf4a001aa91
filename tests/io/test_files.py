"""files.unwritable: why files could not be written somewhere, found without creating anything."""

from __future__ import annotations

from model_core.io.files import unwritable


def test_a_folder_to_be_made_under_a_writable_one_is_fine_and_nothing_is_created(tmp_path):
    assert unwritable(tmp_path / "a" / "b") == ""
    assert not (tmp_path / "a").exists()
    assert unwritable(tmp_path) == ""


def test_a_path_under_a_file_is_refused_naming_the_file(tmp_path):
    blocked = tmp_path / "file"
    blocked.write_text("")
    assert unwritable(blocked / "out") == f"{blocked} is not a folder"
