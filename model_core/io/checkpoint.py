"""Release checkpoints: ``model.safetensors`` (weights, cannot run code on load) beside
``model.json`` (config, feature layout, normalisation, skeleton, data, licence) and
``seeds.npz`` (20-frame feature windows from test-split takes, loaded without pickle).
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

try:  # the library where it is installed; Blender's Python lacks it, so reading has a fallback
    from safetensors.numpy import load_file, save_file
except ImportError:  # pragma: no cover - exercised in Blender
    load_file = save_file = None

from ..motion.conventions import CONTACTS, JOINTS, LAYOUT, MODEL_FPS, PARENT_NAMES, UP_AXIS
from .files import write_atomic, write_json

REPO = Path(__file__).resolve().parents[2]
DEFAULT_MODEL = REPO / "models" / "strnn_default"
# A release may hold a second STRNN in this subfolder: the first window of every rollout is the average of
# the two models' predictions (Engine.predict_first); each later window is the release's own, but for a
# bounded gap that Fill Gap bends onto its target, whose windows are all averaged (Engine.extrapolate's
# paired_windows).
COMPANION = "companion"
# A release may hold a siMLPe in this subfolder (model_core/inference/simlpe_engine.py): the first window of every
# rollout is then a weighted average of the STRNN's prediction (and its companion's) with the siMLPe's
# (Engine.predict_first, SIMLPE_SHARE), which predicts the next 20 frames of motion unlike the training data better.
SIMLPE = "simlpe"
# A release may hold a regularised STRNN in this subfolder (the release fine-tuned with dropout, which leans towards
# the motion it learnt): on motion the release does not know, its first windows go that share of the way to this
# model's (Engine.extrapolate's ``unfamiliar``, REGULARISED_WINDOWS), which is nearer the truth there.
REGULARISED = "regularised"
# A release may hold its gap model in this subfolder: the learnt in-betweener Fill Gap uses
# (model_core/inference/gap_engine.py); without it Fill Gap bends the STRNN's continuation onto the target.
GAP = "gap"
DENOISE_MODEL = REPO / "models" / "strnn_denoise"  # the model Denoise uses unless told otherwise
PURPOSES = ("generate", "denoise")  # what a release is trained for (model.json "purpose"; absent: the first)
# What a release holds (model.json "architecture"; absent: the first). The others are published
# baselines (model_core/model/baselines.py), scored by scripts/evaluate.py; the engines run none on its own, and a
# siMLPe only as a release's partner in the first window (SIMLPE).
ARCHITECTURES = ("strnn", "simlpe", "residual_gru")


def default_denoiser(fallback=None):
    """The bundled denoising model's folder if it is there, else ``fallback`` (the model that
    Denoise uses when none is named)."""
    return DENOISE_MODEL if (DENOISE_MODEL / "model.json").exists() else fallback


def walk_seed_index(names: list[str]) -> int:
    """Index of the first shipped seed taken from a walk (by its clip name), else 0."""
    low = [n.lower() for n in names]
    return next((i for key in ("walk_", "walk") for i, n in enumerate(low) if key in n), 0)


class CheckpointError(ValueError):
    """A model folder is missing files or holds an unsupported format."""


@dataclass
class Checkpoint:
    """Everything inference needs: weights ``{name: float32 array}``, config dict,
    normalisation ``mean``/``std`` ``[C]``, metadata and seed windows ``[K, m, C]``."""

    weights: dict[str, np.ndarray]
    config: dict
    mean: np.ndarray
    std: np.ndarray
    meta: dict
    seeds: np.ndarray
    seed_names: list[str]
    companion: Checkpoint | None = None  # the second model of the first window (COMPANION)
    simlpe: Checkpoint | None = None  # the siMLPe that shares the first window (SIMLPE)
    regularised: Checkpoint | None = None  # the STRNN unfamiliar motion's first windows lean on (REGULARISED)
    gap_folder: Path | None = None  # the release's gap model's folder (GAP), read by load_gap on first use

    def load_gap(self):
        """The release's gap model (:data:`GAP`, a :class:`gap_engine.GapModel`), or None without one. Read when
        first needed, not with the release: only Fill Gap uses it, so Extend and Follow Curve neither wait for
        its weights nor fail on a damaged copy of them (Fill Gap does, with :class:`CheckpointError`)."""
        if self.gap_folder is None:
            return None
        from ..inference.gap_engine import GapModel  # it reads its files with this module's reader

        return GapModel.load(self.gap_folder)

    @property
    def purpose(self) -> str:
        """``generate`` (predicts: extend, follow, denoise) or ``denoise`` (a reconstruction-only model)."""
        return self.meta.get("purpose", PURPOSES[0])

    @property
    def architecture(self) -> str:
        """``strnn``, or the name of a baseline (:data:`ARCHITECTURES`)."""
        return self.meta.get("architecture", ARCHITECTURES[0])

    def require_strnn(self) -> None:
        """Raise :class:`CheckpointError` if this release is a baseline, which only evaluate.py runs."""
        if self.architecture != ARCHITECTURES[0]:
            raise CheckpointError(f"this model folder holds a {self.architecture} baseline (model.json architecture "
                                  f"{self.architecture!r}), not an STRNN model: it is only for scoring, with "
                                  f"scripts/evaluate.py --baseline-model FOLDER")

    def require_generator(self, what: str) -> None:
        """Raise :class:`CheckpointError` if this is a denoise-only model, which cannot do ``what``."""
        if self.purpose == "denoise":
            raise CheckpointError(f"this model was trained for Denoise alone (model.json purpose 'denoise'), so "
                                  f"it cannot {what}: use a generating model such as models/strnn_default")


_DTYPES = {"F32": "<f4", "F64": "<f8", "F16": "<f2", "I64": "<i8", "I32": "<i4", "U8": "u1", "BOOL": "?"}


def read_safetensors(path: str | Path) -> dict[str, np.ndarray]:
    """Read a .safetensors file with NumPy alone: an 8-byte little-endian header length,
    a JSON header of ``{name: {dtype, shape, data_offsets}}``, then the raw tensor bytes."""
    raw = Path(path).read_bytes()
    if len(raw) < 8:
        raise CheckpointError(f"{path}: too short to be a safetensors file")
    size = int.from_bytes(raw[:8], "little")
    try:
        header = json.loads(raw[8:8 + size])
    except ValueError as e:
        raise CheckpointError(f"{path}: unreadable safetensors header ({e})") from None
    body = memoryview(raw)[8 + size:]
    out = {}
    for name, info in header.items():
        if name == "__metadata__":
            continue
        if info["dtype"] not in _DTYPES:
            raise CheckpointError(f"{path}: tensor {name!r} has unsupported dtype {info['dtype']}")
        begin, end = info["data_offsets"]
        out[name] = np.frombuffer(body[begin:end], dtype=_DTYPES[info["dtype"]]).reshape(info["shape"]).copy()
    return out


def save_release(folder: str | Path, weights: dict[str, np.ndarray], config: dict, mean, std,
                 meta: dict, seeds: np.ndarray, seed_names: list[str]) -> Path:
    """Write a release checkpoint folder atomically, file by file."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    doc = {
        "format": "strnn-release-1",
        "config": config,
        "fps": MODEL_FPS,
        "up_axis": "xyz"[UP_AXIS],
        "units": "metres",
        "layout": {"size": LAYOUT.size, "positions": [LAYOUT.positions.start, LAYOUT.positions.stop],
                   "velocity": [LAYOUT.velocity.start, LAYOUT.velocity.stop], "yaw_rate": LAYOUT.yaw_rate,
                   "contacts": [LAYOUT.contacts.start, LAYOUT.contacts.stop],
                   "contact_names": [c for c, _ in CONTACTS]},
        "skeleton": {"joints": list(JOINTS), "parents": [PARENT_NAMES[j] for j in JOINTS]},
        "normalisation": {"mean": np.asarray(mean).tolist(), "std": np.asarray(std).tolist()},
        **meta,
    }
    contiguous = {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in weights.items()}
    write_atomic(folder / "model.safetensors", lambda p: save_file(contiguous, str(p)))
    write_json(folder / "model.json", doc)
    def write_seeds(p: Path):
        with open(p, "wb") as f:  # a file object keeps np.savez from renaming the temporary file
            np.savez(f, features=np.asarray(seeds, np.float32), names=np.array(seed_names, dtype=str))

    write_atomic(folder / "seeds.npz", write_seeds)
    return folder


def _read_json(path: Path) -> dict:
    """``path`` parsed as a JSON object, or :class:`CheckpointError` naming the file and the fault."""
    try:
        doc = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError) as e:
        raise CheckpointError(f"{path} cannot be read ({e})") from e
    except ValueError as e:
        raise CheckpointError(f"{path} is not valid JSON ({e}): copy the model folder again") from e
    if not isinstance(doc, dict):
        raise CheckpointError(f"{path} does not hold a JSON object: copy the model folder again")
    return doc


def load_release(folder: str | Path | None = None) -> Checkpoint:
    """Load a release checkpoint folder (default: the bundled model). Never unpickles."""
    folder = Path(folder) if folder else DEFAULT_MODEL
    if folder.is_file():
        folder = folder.parent
    for name in ("model.safetensors", "model.json"):
        if not (folder / name).exists():
            raise CheckpointError(f"{folder}: missing {name}; a model folder holds model.safetensors, "
                                  "model.json and seeds.npz (see models/strnn_default)")
    doc = _read_json(folder / "model.json")
    if doc.get("format") != "strnn-release-1":
        raise CheckpointError(f"{folder / 'model.json'}: unsupported format {doc.get('format')!r}")
    for key, wanted in (("layout", dict), ("config", dict), ("normalisation", dict)):
        if not isinstance(doc.get(key), wanted):
            raise CheckpointError(f"{folder / 'model.json'}: no {key!r} section; the file is incomplete (copy the "
                                  "whole model folder again, or write it with scripts/train.py --export)")
    if doc["layout"].get("size") != LAYOUT.size:
        raise CheckpointError(f"{folder}: feature size {doc['layout'].get('size')} does not match "
                              f"this code's {LAYOUT.size}: the model was trained for another feature layout")
    seeds, names = np.zeros((0, doc["config"].get("encode_len", 0), LAYOUT.size), np.float32), []
    if (folder / "seeds.npz").exists():
        try:
            z = np.load(folder / "seeds.npz", allow_pickle=False)
            seeds, names = z["features"], [str(n) for n in z["names"]]
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as e:
            raise CheckpointError(f"{folder / 'seeds.npz'} is unreadable ({e}): copy the model folder again") from e
    norm = doc["normalisation"]
    if len(norm.get("mean", ())) != LAYOUT.size or len(norm.get("std", ())) != LAYOUT.size:
        raise CheckpointError(f"{folder / 'model.json'}: the normalisation must hold {LAYOUT.size} means and "
                              "standard deviations; the file is incomplete (copy the model folder again)")
    meta = {k: v for k, v in doc.items() if k not in ("config", "normalisation")}
    reader = load_file if load_file is not None else read_safetensors
    try:
        weights = reader(str(folder / "model.safetensors"))
    except Exception as e:  # safetensors raises its own error type for a damaged file
        raise CheckpointError(f"{folder / 'model.safetensors'} is damaged or incomplete ({e}): copy the model "
                              "folder again, or export it anew with scripts/train.py --export") from e
    ckpt = Checkpoint(weights, doc["config"], np.array(norm["mean"], np.float32), np.array(norm["std"], np.float32),
                      meta, seeds, names)
    if ckpt.purpose not in PURPOSES:
        raise CheckpointError(f"{folder / 'model.json'}: unknown purpose {ckpt.purpose!r} "
                              f"(one of {', '.join(PURPOSES)})")
    if ckpt.architecture not in ARCHITECTURES:
        raise CheckpointError(f"{folder / 'model.json'}: unknown architecture {ckpt.architecture!r} "
                              f"(one of {', '.join(ARCHITECTURES)})")
    if ckpt.architecture == ARCHITECTURES[0]:
        _check_strnn_shapes(folder, ckpt)
        if (folder / COMPANION / "model.json").exists():
            ckpt.companion = _partner(folder, ckpt, COMPANION, ARCHITECTURES[0])
        if (folder / SIMLPE / "model.json").exists():
            ckpt.simlpe = _partner(folder, ckpt, SIMLPE, ARCHITECTURES[1])
        if (folder / REGULARISED / "model.json").exists():
            ckpt.regularised = _partner(folder, ckpt, REGULARISED, ARCHITECTURES[0])
            if any(ckpt.regularised.config.get(k) != ckpt.config.get(k) for k in ("encode_len", "predict_len")):
                raise CheckpointError(f"{folder / REGULARISED}: a {REGULARISED} model must read (encode_len) and "
                                      "predict (predict_len) as many frames as the release: copy the model folder "
                                      "again")
        if (folder / GAP / "model.json").exists():
            ckpt.gap_folder = folder / GAP
    return ckpt


def _partner(folder: Path, ckpt: Checkpoint, sub: str, architecture: str) -> Checkpoint:
    """A model the release shares its first windows with (:data:`COMPANION`, an STRNN; :data:`SIMLPE`, a siMLPe;
    :data:`REGULARISED`, an STRNN):
    a generating ``architecture`` model without partners of its own that predicts and reads no more frames than the
    release (it reads the last of the release's context frames, and continues its own prediction as far as the
    release's window reaches)."""
    other = load_release(folder / sub)
    m, n = other.config.get("encode_len"), other.config.get("predict_len")
    own_partners = (other.companion, other.simlpe, other.regularised)
    if other.architecture != architecture or other.purpose != PURPOSES[0] or any(p is not None for p in own_partners) \
            or not isinstance(n, int) or not 1 <= n <= ckpt.config.get("predict_len", 0) or not isinstance(m, int) \
            or not 1 <= m <= ckpt.config.get("encode_len", 0):
        raise CheckpointError(f"{folder / sub}: a {sub} must be a generating {architecture} model without a "
                              "companion, siMLPe or regularised model of its own that predicts no more frames "
                              "(predict_len) and reads no more (encode_len) than the release: copy the model folder "
                              "again")
    return other


def _check_strnn_shapes(folder: Path, ckpt: Checkpoint) -> None:
    """The weights of an STRNN release have the width, window and frame size its model.json says."""
    cfg, w = ckpt.config, ckpt.weights
    width, m, n = cfg.get("width"), cfg.get("encode_len"), cfg.get("predict_len")
    found = {"width": w["predictor.weight_hh"].shape[1] if "predictor.weight_hh" in w else None}
    if cfg.get("residual") and "filter.net.0.weight" in w:
        frames = w["filter.net.0.weight"].shape[1] // max(cfg.get("frame_size", LAYOUT.size), 1)
        found["window"] = frames - (m or 0) * bool(cfg.get("filter_context"))
    wanted = {"width": width, "window": (cfg.get("decode_len") or m or 0) + (n or 0)}
    for key, value in found.items():
        if value is None:
            raise CheckpointError(f"{folder / 'model.safetensors'} holds no STRNN predictor: it belongs to another "
                                  "model than model.json describes (copy both from the same model folder)")
        if value != wanted[key]:
            raise CheckpointError(f"{folder}: model.json describes a {key} of {wanted[key]} but model.safetensors "
                                  f"holds one of {value}: the two files come from different models (copy both "
                                  "from the same model folder)")
