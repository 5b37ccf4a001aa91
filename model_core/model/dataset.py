"""Dataset building: file discovery, the split rule, feature caching, windows, statistics.

Split rule (deterministic, by whole take): ``crc32(take key) % 20`` is 0 or 1 -> test,
2 -> validation, anything else -> train. The take key is the file's path relative
to the data root without extension; partners of a paired take (``configs/data.toml``)
share the key of the lower-numbered file.
"""

from __future__ import annotations

import fnmatch
import functools
import hashlib
import os
import sys
import tomllib
import zlib
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..io.bvh import BvhError, read_bvh
from ..io.files import write_atomic
from ..motion.conventions import LAYOUT, MODEL_FPS
from ..motion.features import positions_to_features
from ..rig.rigs import RigError, canonical_clip, on_ground

REPO = Path(__file__).resolve().parents[2]
DATA_CONFIG = REPO / "configs" / "data.toml"
SPLITS = ("train", "validation", "test")
CACHE_VERSION = "1"


class DataError(ValueError):
    """A data folder is unusable (empty, or no readable clip)."""


def load_data_config(path: Path = DATA_CONFIG) -> dict:
    if not path.exists():
        return {"fps_overrides": {}, "paired_takes": {}, "held_out": {}}
    with open(path, "rb") as f:
        cfg = tomllib.load(f)
    for key in ("fps_overrides", "paired_takes", "held_out"):
        cfg.setdefault(key, {})
    return cfg


def held_out_group(name: str, config: dict | None = None) -> str | None:
    """The held-out group (``configs/data.toml`` ``[held_out]``) a clip belongs to, or None.
    ``name`` is the clip's path relative to the data root (or ending in it)."""
    for group, patterns in (config or load_data_config())["held_out"].items():
        if any(fnmatch.fnmatch(name, p) or fnmatch.fnmatch(name, "*/" + p) for p in patterns):
            return group
    return None


def _folder_rule(rules: dict, path: Path):
    folder = path.parent.as_posix()
    for key, value in rules.items():
        if folder == key or folder.endswith("/" + key):
            return value
    return None


def fps_override(path: Path, config: dict | None = None) -> float | None:
    """The true frame rate of ``path`` when its folder has an override, else None."""
    return _folder_rule((config or load_data_config())["fps_overrides"], Path(path))


def take_key(rel: Path, config: dict | None = None) -> str:
    """The split key of a file (path relative to the data root)."""
    rel = Path(rel)
    offset = _folder_rule((config or load_data_config())["paired_takes"], rel)
    stem = rel.stem
    if offset and stem.isdigit() and int(stem) > offset:
        stem = f"{int(stem) - offset:0{len(stem)}d}"
    return (rel.parent / stem).as_posix()


def split_of(rel: Path, config: dict | None = None) -> str:
    """``train``, ``validation`` or ``test`` for a file path relative to the data root."""
    h = zlib.crc32(take_key(rel, config).encode()) % 20
    return "test" if h < 2 else "validation" if h == 2 else "train"


def find_bvh(root: str | Path) -> list[Path]:
    """All ``.bvh`` files under ``root``, sorted; raises :class:`DataError` if there are none."""
    root = Path(root)
    if not root.exists():
        raise DataError(f"{root}: data folder does not exist")
    if root.is_file():
        return [root]
    files = sorted(p for p in root.rglob("*") if p.suffix.lower() == ".bvh" and p.is_file())
    if not files:
        raise DataError(f"{root}: no .bvh files found in this folder or below it")
    return files


@dataclass
class Clip:
    name: str  # path relative to the data root
    split: str
    positions: np.ndarray  # float32 [F, 21, 3]
    features: np.ndarray  # float32 [F, C]


@dataclass
class MotionData:
    """All clips of a data folder, with the files that could not be read."""

    root: str
    clips: list[Clip]
    failures: list[str] = field(default_factory=list)

    def split(self, name: str) -> list[Clip]:
        return [c for c in self.clips if c.split == name]

    def without_held_out(self, config: dict | None = None) -> MotionData:
        """The same data less the clips of every held-out group (for training)."""
        config = config or load_data_config()
        return MotionData(self.root, [c for c in self.clips if held_out_group(c.name, config) is None], self.failures)

    def group(self, name: str, config: dict | None = None) -> list[Clip]:
        """Every clip (any split) of one held-out group."""
        config = config or load_data_config()
        if name not in config["held_out"]:
            raise DataError(f"no held-out group {name!r}; configs/data.toml has {sorted(config['held_out'])}")
        return [c for c in self.clips if held_out_group(c.name, config) == name]


PHASE_MARK = "#phase"  # clip name "<file>#phase<p>": frames p, p + k, ... of a take at k x the model's rate


def _load_one(args):
    """``[(name, positions, features, error)]`` of one file: one clip, or with ``capture_phases`` one per
    phase of a take captured at a whole multiple of the model's rate (:func:`load_folder`)."""
    path, rel, fps, capture_phases = args
    try:
        bvh = read_bvh(path, fps=fps)
        k = int(round(bvh.fps / MODEL_FPS))
        if capture_phases and k >= 2 and abs(bvh.fps - k * MODEL_FPS) < 1e-3 * MODEL_FPS:
            full = canonical_clip(bvh, bvh.fps)
            clips = [(rel if p == 0 else f"{rel}{PHASE_MARK}{p}", on_ground(full[p::k])) for p in range(k)]
        else:
            clips = [(rel, canonical_clip(bvh))]
        return [(name, pos, positions_to_features(pos)[0], None) for name, pos in clips]
    except (BvhError, RigError) as e:
        return [(rel, None, None, str(e))]


def file_of(name: str) -> str:
    """The file (relative path) a clip name comes from (:data:`PHASE_MARK`)."""
    return name.split(PHASE_MARK)[0]


# The code that turns a BVH file into a clip's arrays: the cache is keyed by its source too, so arrays cached by
# another version of the reader (a change since made, or one since undone) are never read as this one's.
READER_SOURCES = ("io", "motion", "rig", "model/dataset.py")


def reader_files() -> list[Path]:
    """The source files of :data:`READER_SOURCES` (every ``.py`` file of its folders), sorted."""
    package = Path(__file__).resolve().parents[1]
    return sorted(f for part in READER_SOURCES
                  for f in ((package / part).rglob("*.py") if (package / part).is_dir() else [package / part]))


def source_digest(files: list[Path]) -> bytes:
    """A digest of ``files``' names and contents."""
    h = hashlib.sha1()
    for f in files:
        h.update(f.name.encode() + b"\0" + f.read_bytes() + b"\0")
    return h.digest()


@functools.lru_cache(maxsize=1)
def _reader_digest() -> bytes:
    return source_digest(reader_files())


def _cache_path(root: Path, files: list[Path], cache_dir: Path, capture_phases: bool = False) -> Path:
    h = hashlib.sha1(CACHE_VERSION.encode() + (b"|capture_phases" if capture_phases else b""))
    h.update(_reader_digest())
    h.update(DATA_CONFIG.read_bytes() if DATA_CONFIG.exists() else b"")
    for f in files:
        st = f.stat()
        h.update(f"{f.relative_to(root)}|{st.st_size}|{st.st_mtime_ns}".encode())
    return cache_dir / f"motion-{h.hexdigest()[:16]}.npz"


def load_folder(root: str | Path, cache_dir: str | Path | None = None, workers: int | None = None,
                progress: bool = True, capture_phases: bool = False) -> MotionData:
    """Read every BVH under ``root`` as canonical clips; cache the arrays in ``cache_dir``.

    A take is read at the model's rate, which for one captured at k times that rate (60, 120 fps) keeps
    every k-th frame from the first. With ``capture_phases`` (for training) it gives one clip per phase
    instead, frames p, p + k, ... for p = 0 .. k - 1 (:data:`PHASE_MARK` names the later ones), each in the
    take's own split and held-out group: Denoise reads such a take once per phase, and the phases are as many
    more views of the capture's own detail.

    Unreadable files are collected in ``failures`` (with file, line and reason);
    raises :class:`DataError` if the folder has no readable clip.
    """
    root = Path(root)
    files = find_bvh(root)
    base = root if root.is_dir() else root.parent
    config = load_data_config()
    cache = _cache_path(base, files, Path(cache_dir), capture_phases) if cache_dir else None
    if cache and cache.exists():
        with np.load(cache, allow_pickle=False) as z:
            z = {k: z[k] for k in z.files}  # read each array once
        bounds = np.concatenate([[0], np.cumsum(z["lengths"])])
        clips = [Clip(str(n), str(s), z["positions"][a:b], z["features"][a:b])
                 for n, s, a, b in zip(z["names"], z["splits"], bounds[:-1], bounds[1:])]
        return MotionData(str(root), clips, [str(x) for x in z["failures"]])
    jobs = [(str(f), f.relative_to(base).as_posix(), fps_override(f.relative_to(base), config), capture_phases)
            for f in files]
    workers = workers or min(4, os.cpu_count() or 1)
    clips, failures = [], []
    with ProcessPoolExecutor(workers) as pool:
        for i, results in enumerate(pool.map(_load_one, jobs, chunksize=8)):
            for name, pos, feats, err in results:
                if err:
                    failures.append(err)
                else:
                    clips.append(Clip(name, split_of(Path(file_of(name)), config), pos, feats))
            if progress and (i + 1) % 100 == 0:
                print(f"\rreading {i + 1}/{len(jobs)} files", end="", file=sys.stderr, flush=True)
    if progress and len(jobs) >= 100:
        print(file=sys.stderr)
    if not clips:
        raise DataError(f"{root}: none of the {len(files)} BVH files could be read:\n  " + "\n  ".join(failures[:10]))
    data = MotionData(str(root), clips, failures)
    if cache:
        def write(tmp: Path):
            with open(tmp, "wb") as f:  # a file object keeps np.savez from adding ".npz" to the name
                np.savez(f, names=np.array([c.name for c in clips]), splits=np.array([c.split for c in clips]),
                         lengths=np.array([len(c.features) for c in clips]),
                         positions=np.concatenate([c.positions for c in clips]),
                         features=np.concatenate([c.features for c in clips]),
                         failures=np.array(failures, dtype=str))

        write_atomic(cache, write)
    return data


def window_starts(lengths: list[int], window: int, stride: int = 1) -> np.ndarray:
    """``int64 [N, 2]`` (clip index, start frame) of every full window."""
    out = [(i, s) for i, n in enumerate(lengths) for s in range(0, n - window + 1, stride)]
    return np.array(out, dtype=np.int64).reshape(-1, 2)


@dataclass
class Normaliser:
    """Per-channel mean and std ``[C]``. All position channels share one std, so the loss
    weighs a centimetre the same on every joint (as MPJPE does); contacts stay 0/1."""

    mean: np.ndarray
    std: np.ndarray

    @classmethod
    def fit(cls, feats: np.ndarray, floor: float = 0.01) -> Normaliser:
        mean = feats.mean(0).astype(np.float32)
        std = np.maximum(feats.std(0), floor).astype(np.float32)
        std[LAYOUT.positions] = feats[:, LAYOUT.positions].std(0).mean()
        mean[LAYOUT.contacts], std[LAYOUT.contacts] = 0.0, 1.0
        std[LAYOUT.yaw_rate] = max(std[LAYOUT.yaw_rate], 0.002)
        return cls(mean, std)

    def encode(self, x):
        return (x - self.mean) / self.std

    def decode(self, x):
        return x * self.std + self.mean
