"""BVH reading, forward kinematics and resampling, vectorised over frames.

A :class:`Bvh` keeps the hierarchy (names, parents, offsets, channel layout)
and the raw motion ``float32 [frames, channels]``. :func:`forward_kinematics`
turns it into global positions ``[frames, joints, 3]`` in file units (Y-up),
End Sites included as joints named ``<parent>_end``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..motion.geometry import interpolate_frames
from ..motion.rotations import axis_matrix

_AXES = {"X": 0, "Y": 1, "Z": 2}


class BvhError(ValueError):
    """A BVH file could not be read; the message names the file and line."""


@dataclass
class Bvh:
    """A parsed BVH file. Joints include End Sites (``is_end`` True)."""

    path: str
    names: list[str]
    parents: np.ndarray  # int [joints], -1 for roots
    offsets: np.ndarray  # float64 [joints, 3], file units
    channels: list[list[str]]  # per joint, e.g. ["Xposition", ..., "Zrotation"]
    is_end: np.ndarray  # bool [joints]
    motion: np.ndarray  # float64 [frames, total channels]
    frame_time: float
    channel_start: list[int] = field(default_factory=list)

    @property
    def fps(self) -> float:
        return 1.0 / self.frame_time

    @property
    def frames(self) -> int:
        return self.motion.shape[0]

    def index(self, name: str) -> int:
        return self.names.index(name)


def _error(path, line, msg) -> BvhError:
    return BvhError(f"{path}:{line}: {msg}")


def read_bvh(path: str | Path, fps: float | None = None) -> Bvh:
    """Parse a BVH file. ``fps`` overrides the header's Frame Time when given.

    Raises :class:`BvhError` with ``file:line: what is wrong`` for bad input.
    """
    path = str(path)
    try:
        # utf-8-sig: past the byte-order mark some Windows tools write
        with open(path, encoding="utf-8-sig", errors="replace") as f:
            lines = f.read().splitlines()
    except OSError as e:
        raise BvhError(f"{path}: cannot read file ({e.strerror})") from e
    tokens = [(i + 1, t) for i, line in enumerate(lines) for t in line.split()]
    if not tokens:
        raise _error(path, 1, "file is empty; expected 'HIERARCHY'")
    if tokens[0][1].upper() != "HIERARCHY":
        raise _error(path, tokens[0][0], f"expected 'HIERARCHY', found {tokens[0][1]!r}")
    bvh = Bvh(path, [], np.zeros(0, int), np.zeros((0, 3)), [], np.zeros(0, bool), np.zeros((0, 0)), 0.0)
    parents, offsets, is_end = [], [], []
    stack: list[int] = []
    pos = 1
    n_channels = 0

    def take(expect=None):
        nonlocal pos
        if pos >= len(tokens):
            last = tokens[-1][0]
            raise _error(path, last, f"unexpected end of file{f'; expected {expect!r}' if expect else ''}")
        line, tok = tokens[pos]
        pos += 1
        if expect is not None and tok.upper() != expect.upper():
            raise _error(path, line, f"expected {expect!r}, found {tok!r}")
        return line, tok

    def number(what):
        line, tok = take()
        try:
            return float(tok)
        except ValueError:
            raise _error(path, line, f"expected a number for {what}, found {tok!r}") from None

    while pos < len(tokens):
        line, tok = take()
        key = tok.upper()
        if key in ("ROOT", "JOINT"):
            if key == "JOINT" and not stack:
                raise _error(path, line, "JOINT outside of a ROOT block")
            name_line, name = take()
            while pos < len(tokens) and tokens[pos][0] == name_line and tokens[pos][1] != "{":
                name += "_" + take()[1]  # a name with spaces (3ds Max's "Bip01 L Thigh"), joined as Blender joins it
            bvh.names.append(name)
            parents.append(stack[-1] if stack else -1)
            is_end.append(False)
            take("{")
            take("OFFSET")
            offsets.append([number(f"OFFSET of {name}") for _ in range(3)])
            cline, _ = take("CHANNELS")
            try:
                count = int(take()[1])
            except ValueError:
                raise _error(path, cline, f"CHANNELS of {name} needs a count") from None
            if not 0 <= count <= 6:
                raise _error(path, cline, f"CHANNELS of {name} has count {count}; expected 0 to 6")
            chans = [take()[1] for _ in range(count)]
            for c in chans:
                if len(c) != 9 or c[0].upper() not in _AXES or c[1:].lower() not in ("position", "rotation"):
                    raise _error(path, cline, f"unknown channel {c!r} on joint {name}")
            bvh.channels.append(chans)
            bvh.channel_start.append(n_channels)
            n_channels += count
            stack.append(len(bvh.names) - 1)
        elif key == "END":
            take("Site")
            if not stack:
                raise _error(path, line, "End Site outside of a joint block")
            parent = stack[-1]
            bvh.names.append(f"{bvh.names[parent]}_end")
            parents.append(parent)
            is_end.append(True)
            take("{")
            take("OFFSET")
            offsets.append([number("End Site OFFSET") for _ in range(3)])
            take("}")
            bvh.channels.append([])
            bvh.channel_start.append(n_channels)
        elif key == "}":
            if not stack:
                raise _error(path, line, "unbalanced '}'")
            stack.pop()
        elif key == "MOTION":
            break
        else:
            raise _error(path, line, f"unexpected token {tok!r} in HIERARCHY")
    else:
        raise _error(path, tokens[-1][0], "no MOTION section (file truncated?)")
    if stack:
        raise _error(path, tokens[pos - 1][0], "HIERARCHY has unclosed '{' before MOTION")
    if not bvh.names:
        raise _error(path, tokens[0][0], "HIERARCHY defines no joints")
    take("Frames:")
    fline, ftok = take()
    try:
        frames = int(ftok)
    except ValueError:
        raise _error(path, fline, f"expected a frame count, found {ftok!r}") from None
    take("Frame")
    take("Time:")
    frame_time = number("Frame Time")
    time_line = tokens[pos - 1][0]
    if fps is None:
        check_frame_time(path, time_line, frame_time)
    data_line = tokens[pos][0] if pos < len(tokens) else fline + 2
    values = [t for _, t in tokens[pos:]]
    expected = frames * n_channels
    if frames <= 0:
        raise _error(path, fline, f"file declares {frames} frames; a clip needs at least one")
    if len(values) < expected:
        got = len(values) // max(n_channels, 1)
        raise _error(path, lines and len(lines), f"truncated motion: header says {frames} frames of "
                     f"{n_channels} channels but only {got} complete frames follow (from line {data_line})")
    try:
        motion = np.array(values[:expected], dtype=np.float64).reshape(frames, n_channels)
    except ValueError:
        bad = next(i for i, v in enumerate(values[:expected]) if not _is_float(v))
        raise _error(path, tokens[pos + bad][0], f"motion value {values[bad]!r} is not a number") from None
    if not np.all(np.isfinite(motion)):
        row, col = (int(v[0]) for v in np.nonzero(~np.isfinite(motion)))
        joint = max(j for j, start in enumerate(bvh.channel_start) if start <= col and bvh.channels[j])
        channel = bvh.channels[joint][col - bvh.channel_start[joint]]
        raise _error(path, data_line + row, f"frame {row} has {motion[row, col]} in {bvh.names[joint]}'s "
                                           f"{channel}: motion values must be finite numbers")
    bvh.parents = np.array(parents, dtype=np.int64)
    bvh.offsets = np.array(offsets, dtype=np.float64)
    bvh.is_end = np.array(is_end, dtype=bool)
    bvh.motion = motion
    bvh.frame_time = 1.0 / fps if fps else frame_time
    return bvh


# seconds: the capture rates a header can mean (optical systems record up to 360 frames a second and more; video 10)
MIN_FRAME_TIME, MAX_FRAME_TIME = 1.0 / 500.0, 1.0 / 10.0


def check_frame_time(path: str, line: int, frame_time: float) -> None:
    """A :class:`BvhError` unless a header's Frame Time is a plausible capture rate (500 to 10 fps)."""
    fix = (" fix the header, or give the folder its true rate in configs/data.toml [fps_overrides] (the "
           "batch CLI and the extension read the header as it is)")
    if not frame_time > 0:
        raise _error(path, line, f"Frame Time must be positive, found {frame_time}:" + fix)
    if not MIN_FRAME_TIME * 0.999 <= frame_time <= MAX_FRAME_TIME * 1.001:
        raise _error(path, line, f"Frame Time {frame_time:g} s ({1 / frame_time:g} fps) is far from any capture "
                                 f"rate (1/500 to 1/10 s):" + fix)


def _is_float(s: str) -> bool:
    try:
        float(s)
        return True
    except ValueError:
        return False


def local_transforms(bvh: Bvh) -> tuple[np.ndarray, np.ndarray]:
    """Local rotations ``[frames, joints, 3, 3]`` and translations ``[frames, joints, 3]``.

    Rotation channels compose in the order listed (intrinsic), as BVH defines.
    Position channels, where present, replace the joint's OFFSET.
    """
    n, j = bvh.frames, len(bvh.names)
    rot = np.broadcast_to(np.eye(3), (n, j, 3, 3)).copy()
    trans = np.broadcast_to(bvh.offsets, (n, j, 3)).copy()
    for k, chans in enumerate(bvh.channels):
        start = bvh.channel_start[k]
        for c_i, c in enumerate(chans):
            axis = _AXES[c[0].upper()]
            col = bvh.motion[:, start + c_i]
            if c[1:].lower() == "position":
                trans[:, k, axis] = col
            else:
                rot[:, k] = rot[:, k] @ axis_matrix(axis, np.radians(col))
    return rot, trans


def forward_kinematics(bvh: Bvh) -> tuple[np.ndarray, np.ndarray]:
    """Global positions ``[frames, joints, 3]`` and rotations ``[frames, joints, 3, 3]``."""
    rot, trans = local_transforms(bvh)
    grot = np.empty_like(rot)
    gpos = np.empty_like(trans)
    for k, p in enumerate(bvh.parents):
        if p < 0:
            grot[:, k], gpos[:, k] = rot[:, k], trans[:, k]
        else:
            grot[:, k] = grot[:, p] @ rot[:, k]
            gpos[:, k] = np.einsum("fij,fj->fi", grot[:, p], trans[:, k]) + gpos[:, p]
    return gpos, grot


def resample(x: np.ndarray, src_fps: float, dst_fps: float) -> np.ndarray:
    """Resample ``[frames, ...]`` from ``src_fps`` to ``dst_fps`` by linear interpolation.

    Integer ratios (120 -> 30) pick frames exactly.
    """
    n = x.shape[0]
    if n == 0 or abs(src_fps - dst_fps) < 1e-6:
        return x
    duration = (n - 1) / src_fps
    m = int(np.floor(duration * dst_fps + 1e-6)) + 1
    return interpolate_frames(x, np.arange(m) * (src_fps / dst_fps), snap=1e-6).astype(x.dtype)
