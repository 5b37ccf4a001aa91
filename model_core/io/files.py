"""Writing files so that nobody ever sees half of one.

Every file the project writes (releases, caches, checkpoints, BVH, pictures, reports) goes
through :func:`write_atomic`: the content is written under a temporary name beside the
target and renamed over it, so a reader sees the old file or the new one, and a crash or
an error part way leaves the old file as it was.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np


def write_atomic(path: str | Path, write: Callable[[Path], object]) -> Path:
    """Make ``path`` by ``write(temporary path)`` then a rename; returns ``path``. The folder is
    created if missing; the temporary file is removed when ``write`` fails. The temporary name holds the
    process id, so that two processes making the same file (two trainings filling one cache) do not write
    into one temporary file: the last rename wins, and both are whole."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def unwritable(folder: str | Path) -> str:
    """Why files could not be written into ``folder`` ('' when they can), found without creating anything:
    the nearest folder that exists at or above it must be a writable folder (the rest is made on writing)."""
    existing = Path(folder)
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        return f"{existing} is not a folder"
    if not os.access(existing, os.W_OK | os.X_OK):
        return f"{existing} is not writable"
    return ""


def write_text(path: str | Path, text: str) -> Path:
    return write_atomic(path, lambda p: p.write_text(text))


def json_ready(doc):
    """``doc`` with what strict JSON cannot hold made plain: a float that is not finite (NaN: a figure with
    nothing to measure, e.g. no second of locomotion) becomes ``None``, NumPy scalars and arrays Python numbers
    and lists, tuples lists. Python's ``json`` would write ``NaN``, which JSON readers in other languages and
    ``jq`` refuse."""
    if isinstance(doc, Mapping):
        return {key: json_ready(value) for key, value in doc.items()}
    if isinstance(doc, np.ndarray):
        return json_ready(doc.tolist())  # a 0-d array is one number
    if isinstance(doc, (list, tuple)):
        return [json_ready(value) for value in doc]
    if isinstance(doc, np.generic):
        doc = doc.item()
    if isinstance(doc, float) and not math.isfinite(doc):
        return None
    return doc


def write_json(path: str | Path, doc) -> Path:
    """``doc`` as indented, strict JSON (:func:`json_ready`: a figure that is NaN is written as null)."""
    return write_text(path, json.dumps(json_ready(doc), indent=1, allow_nan=False))
