"""Shared fixtures for the core tests (no Blender needed).

Real motion-capture data is optional: tests that need it use the ``mocap_root``
fixture and skip when ``data/mocap`` (or ``$STRNN_MOCAP_DIR``) is absent.
"""

from __future__ import annotations

import os
from pathlib import Path

# Tiny models on a small machine: BLAS/OpenMP worker threads only spin against each other
# (and against anything else running), which made one 150-step test take minutes.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import pytest  # noqa: E402  (after the thread settings above)

REPO = Path(__file__).resolve().parent.parent


@pytest.fixture
def write_text(tmp_path):
    """``write_text(name, text) -> Path``: a file under the test's temporary folder."""

    def write(name: str, text: str) -> Path:
        path = tmp_path / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
        return path

    return write


@pytest.fixture(scope="session")
def mocap_root() -> Path:
    """The unpacked motion-capture folder; skips the test when it is not on this machine."""
    root = Path(os.environ.get("STRNN_MOCAP_DIR", REPO / "data" / "mocap"))
    if not root.is_dir() or not any(root.iterdir()):
        pytest.skip(f"no motion-capture data at {root} (unpack ../shared/mocap there to run this test)")
    return root


@pytest.fixture(scope="session")
def smallest_bvh():
    """``smallest_bvh(folder, pattern="*.bvh") -> Path``: the smallest matching BVH under ``folder``
    (keeps real-data tests fast); skips the test when there is none."""

    def find(folder: Path, pattern: str = "*.bvh") -> Path:
        files = sorted(folder.rglob(pattern), key=lambda p: (p.stat().st_size, p.name))
        if not files:
            pytest.skip(f"no {pattern} under {folder}")
        return files[0]

    return find
