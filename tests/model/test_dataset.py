"""Dataset: the split rule, paired takes, the per-folder frame-rate override, windows, Normaliser, caching."""

from __future__ import annotations

import collections
from pathlib import Path

import numpy as np
import pytest

from model_core.io.bvh_export import write_bvh
from model_core.model.dataset import (
    DATA_CONFIG,
    Clip,
    DataError,
    MotionData,
    Normaliser,
    fps_override,
    held_out_group,
    load_data_config,
    load_folder,
    split_of,
    take_key,
    window_starts,
)
from model_core.motion.conventions import LAYOUT
from model_core.motion.synthetic import walking_skeleton


def test_split_rule_is_fixed():
    # A snapshot of the committed rule: changing it would silently reshuffle the test split.
    expected = {"train": ["take_001", "take_003", "take_004"], "validation": ["take_011", "take_039", "take_045"],
                "test": ["take_000", "take_002", "take_006"]}
    for split, names in expected.items():
        for name in names:
            assert split_of(Path(f"set/{name}.bvh")) == split


def test_split_is_deterministic_and_roughly_85_5_10():
    names = [Path(f"folder/take_{i:04d}.bvh") for i in range(4000)]
    first = [split_of(n) for n in names]
    assert first == [split_of(n) for n in names]
    share = {k: v / len(names) for k, v in collections.Counter(first).items()}
    assert share["test"] == pytest.approx(0.10, abs=0.02)
    assert share["validation"] == pytest.approx(0.05, abs=0.02)


def test_take_key_is_the_relative_path_without_extension():
    assert take_key(Path("cmu/iclone/002_03.bvh")) == "cmu/iclone/002_03"
    assert split_of(Path("cmu/iclone/002_03.bvh")) == split_of(Path("cmu/iclone/002_03.BVH"))


def test_salsa_partners_share_a_take_and_a_split():
    config = load_data_config()
    for n in range(1, 16):
        a = Path(f"cmu/acrnn-dance/salsa/{n:02d}.bvh")
        b = Path(f"cmu/acrnn-dance/salsa/{n + 15:02d}.bvh")
        assert take_key(a, config) == take_key(b, config)
        assert split_of(a, config) == split_of(b, config)
    assert take_key(Path("cmu/acrnn-dance/indian/18.bvh"), config) == "cmu/acrnn-dance/indian/18"


def test_fps_override_comes_from_configs_data_toml():
    assert DATA_CONFIG.name == "data.toml" and DATA_CONFIG.exists()
    assert fps_override(Path("cmu/acrnn-dance/salsa/01.bvh")) == 60
    assert fps_override(Path("/any/where/acrnn-dance/salsa/01.bvh")) == 60
    assert fps_override(Path("acrnn-dance/salsa/01.bvh")) == 60
    assert fps_override(Path("cmu/acrnn-dance/indian/04.bvh")) is None
    assert fps_override(Path("cmu/not-acrnn-dance/salsa/01.bvh")) is None  # whole folder names only
    assert fps_override(Path("x/y.bvh"), {"fps_overrides": {"x": 24}, "paired_takes": {}}) == 24


def test_load_folder_applies_the_override_and_caches(tmp_path):
    walk = walking_skeleton(61)
    # Both files claim 120 fps in their header; only the salsa folder's override says 60.
    write_bvh(tmp_path / "data/acrnn-dance/salsa/01.bvh", walk, fps=120)
    write_bvh(tmp_path / "data/acrnn-dance/indian/01.bvh", walk, fps=120)
    data = load_folder(tmp_path / "data", cache_dir=tmp_path / "cache", workers=1, progress=False)
    frames = {c.name: len(c.features) for c in data.clips}
    assert frames == {"acrnn-dance/indian/01.bvh": 16, "acrnn-dance/salsa/01.bvh": 31}
    assert data.failures == []
    assert len(list((tmp_path / "cache").glob("motion-*.npz"))) == 1
    again = load_folder(tmp_path / "data", cache_dir=tmp_path / "cache", workers=1, progress=False)
    assert [c.name for c in again.clips] == [c.name for c in data.clips]
    for a, b in zip(again.clips, data.clips):
        np.testing.assert_array_equal(a.features, b.features)
        assert a.split == b.split


def test_arrays_cached_by_another_version_of_the_reader_are_not_read(tmp_path, monkeypatch):
    """The cache is keyed by the reader's source as well as the files: arrays a reader wrote before its code changed
    (here doctored, as a reader that kept another frame would have left them) are read again only by that code."""
    from model_core.model import dataset

    sources = {f.relative_to(Path(dataset.__file__).resolve().parents[1]).as_posix() for f in dataset.reader_files()}
    assert {"io/bvh.py", "rig/rigs.py", "motion/features.py", "model/dataset.py"} <= sources
    code = tmp_path / "bvh.py"
    code.write_text("x = 1\n")
    before = dataset.source_digest([code])
    code.write_text("x = 2\n")
    assert dataset.source_digest([code]) != before

    write_bvh(tmp_path / "data/bandai/walk_001.bvh", walking_skeleton(61), fps=30)
    fresh = load_folder(tmp_path / "data", cache_dir=tmp_path / "cache", workers=1, progress=False)
    (cached,) = (tmp_path / "cache").glob("motion-*.npz")
    with np.load(cached) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["positions"] = arrays["positions"] + 1.0  # what another reader might have left
    with open(cached, "wb") as f:
        np.savez(f, **arrays)
    stale = load_folder(tmp_path / "data", cache_dir=tmp_path / "cache", workers=1, progress=False)
    np.testing.assert_allclose(stale.clips[0].positions, fresh.clips[0].positions + 1.0)  # the same reader: a hit
    monkeypatch.setattr(dataset, "_reader_digest", lambda: b"the reader as changed since")
    again = load_folder(tmp_path / "data", cache_dir=tmp_path / "cache", workers=1, progress=False)
    np.testing.assert_array_equal(again.clips[0].positions, fresh.clips[0].positions)
    assert len(list((tmp_path / "cache").glob("motion-*.npz"))) == 2


def test_capture_phases_give_one_clip_per_phase_in_the_takes_split_and_group(tmp_path):
    """A 60 fps take is read at 30 fps from its first frame; with capture_phases (training) also from its
    second, as a clip of its own in the take's split and held-out group. A 30 fps take stays one clip."""
    walk = walking_skeleton(121, fps=60.0)
    write_bvh(tmp_path / "data/cmu/iclone/006_01.bvh", walk, fps=60)  # the held-out CMU subject's folder
    write_bvh(tmp_path / "data/bandai/walk_001.bvh", walking_skeleton(61), fps=30)
    plain = load_folder(tmp_path / "data", cache_dir=tmp_path / "cache", workers=1, progress=False)
    both = load_folder(tmp_path / "data", cache_dir=tmp_path / "cache", workers=1, progress=False,
                       capture_phases=True)
    assert sorted(c.name for c in plain.clips) == ["bandai/walk_001.bvh", "cmu/iclone/006_01.bvh"]
    assert sorted(c.name for c in both.clips) == ["bandai/walk_001.bvh", "cmu/iclone/006_01.bvh",
                                                   "cmu/iclone/006_01.bvh#phase1"]
    assert len(list((tmp_path / "cache").glob("motion-*.npz"))) == 2  # cached apart
    clips = {c.name: c for c in both.clips}
    first, second = clips["cmu/iclone/006_01.bvh"], clips["cmu/iclone/006_01.bvh#phase1"]
    np.testing.assert_allclose(first.positions, {c.name: c for c in plain.clips}[first.name].positions, atol=1e-6)
    assert len(first.positions) == 61 and len(second.positions) == 60
    # the second phase is the frames in between: each lies about half way between its neighbours
    mid = 0.5 * (first.positions[:-1] + first.positions[1:])
    assert np.abs(second.positions - mid).mean() < 0.25 * np.abs(first.positions[1:] - first.positions[:-1]).mean()
    assert second.split == first.split
    assert held_out_group(second.name) == held_out_group(first.name) == "actor"
    assert len(MotionData("", both.clips).without_held_out().clips) == 1


def test_window_starts_cover_every_full_window():
    starts = window_starts([45, 10, 41], window=40, stride=5)
    assert starts.tolist() == [[0, 0], [0, 5], [2, 0]]
    assert window_starts([5], window=40).shape == (0, 2)


def test_normaliser_round_trip_and_contacts_untouched():
    rng = np.random.default_rng(0)
    feats = rng.normal(3.0, 2.0, size=(500, LAYOUT.size)).astype(np.float32)
    feats[:, LAYOUT.contacts] = rng.integers(0, 2, size=(500, 4))
    const = LAYOUT.velocity.start
    feats[:, const] = 1.0  # a constant channel: std floored, no division by zero
    norm = Normaliser.fit(feats)
    assert norm.mean.shape == norm.std.shape == (LAYOUT.size,)
    np.testing.assert_array_equal(norm.mean[LAYOUT.contacts], 0.0)
    np.testing.assert_array_equal(norm.std[LAYOUT.contacts], 1.0)
    assert norm.std[const] == pytest.approx(0.01)
    # one std for every position channel, so a centimetre weighs the same on every joint
    assert np.unique(norm.std[LAYOUT.positions]).size == 1
    enc = norm.encode(feats)
    np.testing.assert_array_equal(enc[:, LAYOUT.contacts], feats[:, LAYOUT.contacts])
    body = [i for i in range(LAYOUT.size) if i != const and i not in range(LAYOUT.contacts.start, LAYOUT.contacts.stop)]
    np.testing.assert_allclose(enc[:, body].mean(0), 0.0, atol=1e-4)
    own = [i for i in body if i >= LAYOUT.positions.stop]  # channels with their own std
    np.testing.assert_allclose(enc[:, own].std(0), 1.0, atol=1e-3)
    assert enc[:, LAYOUT.positions].std() == pytest.approx(1.0, abs=0.05)
    np.testing.assert_allclose(norm.decode(enc), feats, atol=1e-5)


def test_held_out_groups_come_from_configs_data_toml():
    config = load_data_config()
    assert held_out_group("bandai-namco/dataset-2/dataset-2_walk_exhausted_001.bvh", config) == "style"
    assert held_out_group("cmu/acrnn-dance/martial/03.bvh", config) == "actions"
    assert held_out_group("bandai-namco/dataset-2/dataset-2_walk_normal_001.bvh", config) is None
    clips = [Clip(name, "train", np.zeros((1, 21, 3)), np.zeros((1, 70)))
             for name in ("cmu/acrnn-dance/martial/03.bvh", "cmu/acrnn-dance/salsa/01.bvh")]
    data = MotionData("root", clips)
    assert [c.name for c in data.without_held_out(config).clips] == ["cmu/acrnn-dance/salsa/01.bvh"]
    assert [c.name for c in data.group("actions", config)] == ["cmu/acrnn-dance/martial/03.bvh"]
    with pytest.raises(DataError, match="no held-out group"):
        data.group("nothing", config)
