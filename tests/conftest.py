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


@pytest.fixture
def baseline_release(tmp_path):
    """``baseline_release(arch, seed=0, **config) -> folder``: an untrained baseline (siMLPe or residual GRU)
    saved as a release folder, with random normalisation and output layer so that it moves."""
    import numpy as np
    import torch

    from model_core.io.checkpoint import save_release
    from model_core.model.baselines import MODELS

    def make(arch: str, seed: int = 0, **config) -> Path:
        torch.manual_seed(seed)
        rng = np.random.default_rng(seed)
        model_cls, config_cls = MODELS[arch]
        model = model_cls(config_cls(**config))
        with torch.no_grad():
            last = model.fc_out if arch == "simlpe" else model.out
            last.weight.normal_(0.0, 0.01)
        c, m = model.cfg.frame_size, model.cfg.encode_len
        mean, std = rng.normal(0.0, 0.2, c).astype(np.float32), rng.uniform(0.5, 1.5, c).astype(np.float32)
        seeds = (mean + std * rng.normal(size=(2, m, c))).astype(np.float32)
        weights = {k: v.numpy() for k, v in model.state_dict().items()}
        folder = tmp_path / f"{arch}_{seed}"
        save_release(folder, weights, model.cfg.to_dict(), mean, std, {"architecture": arch, "licence": "test"},
                     seeds, ["a", "b"])
        return folder

    return make


@pytest.fixture(scope="session")
def walk_folder(tmp_path_factory) -> Path:
    """A dozen synthetic walking clips written as BVH files (the training tests' data folder)."""
    from model_core.io.bvh_export import write_bvh
    from model_core.motion.synthetic import walking_skeleton

    root = tmp_path_factory.mktemp("walks")
    for i in range(12):
        write_bvh(root / f"walk_{i:02d}.bvh", walking_skeleton(frames=90, speed=0.8 + 0.1 * i, radius=3.0 + i))
    return root
