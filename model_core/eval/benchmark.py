"""Throughput of open-loop extrapolation against this machine's roofline.

- :func:`model_costs`: matmul FLOPs and weight bytes per generated frame, counted from a
  release's weight shapes (the real block structure, not the NumPy engine's dense folds).
- :func:`measure_sgemm` / :func:`measure_bandwidth`: this machine's SGEMM GFLOP/s and
  memory bandwidth, with whatever BLAS thread count the process was started with.
- :func:`time_extrapolate`: generated frames per second of any engine's ``extrapolate``.

Set ``OPENBLAS_NUM_THREADS`` before NumPy is imported (``scripts/benchmark_core.py`` does):
on a busy machine spinning BLAS threads distort every number here.
"""

from __future__ import annotations

import time

import numpy as np

# Weight matrices of each part of the model, by state-dict prefix.
_PARTS = {"spatial_encoder": "encode_frame.", "spatial_decoder": "decode_frame.", "lstm_encoder": "encoder.",
          "lstm_decoder": "decoder.", "lstm_predictor": "predictor.", "filter": "filter."}


def _matrices(weights: dict, prefix: str, contains: str = "") -> int:
    """Number of matrix entries (= multiply-adds per input row) of the 2-D weights under ``prefix``."""
    return sum(v.size for k, v in weights.items() if k.startswith(prefix) and v.ndim == 2 and contains in k)


def model_costs(weights: dict, config: dict, readings: int = 1, decoded: bool = False) -> dict:
    """Matmul FLOPs and weight bytes per generated frame of one extrapolation window, the model
    reading each context ``readings`` times (2: as it is and as its mirror image, as
    :meth:`Engine.predict <model_core.inference.engine.Engine.predict>` does).

    Per window (``m`` context frames, ``n`` predicted): the encoder runs m LSTM steps over m
    spatially encoded frames; the predictor runs n steps, each step a spatial decode and encode, and with
    ``decoded`` (every window through the backward decoder: :attr:`Engine.decode_later_windows`) the decoder
    runs beside it, max(r, n) steps of both; the residual filter runs once. The cost is a later window's (the
    first, decoded and with the release's partners, is one of many). Bytes are for batch 1 with no weight kept
    in cache between uses: per step each LSTM matrix is read once, the spatial nets once (for decoder and
    predictor together, one batch of two, where both run), the encoder's input weights and the filter once per
    window. The readings are rows of the same batch: they multiply the FLOPs, not the weight reads.
    """
    m, n = config["encode_len"], config["predict_len"]
    steps = max(config.get("decode_len") or m, n) if decoded else n  # the decoder rebuilds decode_len frames
    rows = 2 if decoded else 1  # rows per step through the spatial nets: decoder and predictor, or predictor
    macs = {k: _matrices(weights, p) for k, p in _PARTS.items()}
    enc_ih = _matrices(weights, "encoder.", "weight_ih")
    decoder = macs["lstm_decoder"] if decoded else 0
    flops_window = 2 * (m * (macs["spatial_encoder"] + macs["lstm_encoder"])
                        + steps * (decoder + macs["lstm_predictor"]
                                   + rows * (macs["spatial_decoder"] + macs["spatial_encoder"]))
                        + macs["filter"])
    entries_window = (macs["spatial_encoder"] + enc_ih + m * (macs["lstm_encoder"] - enc_ih)
                      + steps * (decoder + macs["lstm_predictor"]
                                 + macs["spatial_decoder"] + macs["spatial_encoder"])
                      + macs["filter"])
    return {"flops_per_frame": readings * flops_window / n, "weight_bytes_per_frame": 4 * entries_window / n,
            "weight_bytes_total": 4 * sum(macs.values()), "macs_per_part": macs, "readings": readings,
            "window": {"m": m, "n": n, "steps": steps, "decoded": decoded}}


def _best_seconds(fn, repeats: int) -> float:
    fn()  # warm up: caches, allocator, BLAS buffers
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def measure_sgemm(n: int = 2048, repeats: int = 5) -> float:
    """GFLOP/s of a float32 ``[n, n] @ [n, n]`` matmul (best of ``repeats``)."""
    rng = np.random.default_rng(0)
    a, b = rng.random((n, n), np.float32), rng.random((n, n), np.float32)
    return 2 * n ** 3 / _best_seconds(lambda: a @ b, repeats) / 1e9


def measure_bandwidth(megabytes: int = 256, repeats: int = 5) -> float:
    """Memory bandwidth in GB/s of copying a ``megabytes`` float32 array (read + write)."""
    src = np.ones(megabytes * 2 ** 20 // 4, np.float32)
    dst = np.empty_like(src)
    return 2 * src.nbytes / _best_seconds(lambda: np.copyto(dst, src), repeats) / 1e9


def measure_gemv(weights: dict, repeats: int = 20) -> float:
    """GB/s at which a batch-1 matmul streams the model's largest weight matrix (how fast the
    engine can read weights that do not stay in cache)."""
    w = max((v for v in weights.values() if v.ndim == 2), key=lambda v: v.size).astype(np.float32)
    x = np.ones((1, w.shape[1]), np.float32)
    wt = np.ascontiguousarray(w.T)
    return w.nbytes / _best_seconds(lambda: x @ wt, repeats) / 1e9


def time_extrapolate(engine, batch: int, frames: int, repeats: int = 3) -> dict:
    """Time ``engine.extrapolate`` from ``batch`` shipped seeds (cycled) for ``frames`` frames.

    Returns seconds per repeat and generated frames per second (best and median), counting
    ``batch * frames`` frames per call.
    """
    seeds = engine.seeds
    if len(seeds) == 0:
        raise ValueError("the model folder has no seeds.npz windows to start from")
    seed = seeds[np.arange(batch) % len(seeds)]
    engine.extrapolate(seed, engine.n)  # warm up
    seconds = []
    for _ in range(repeats):
        t = time.perf_counter()
        engine.extrapolate(seed, frames)
        seconds.append(time.perf_counter() - t)
    generated = batch * frames
    return {"batch": batch, "frames": frames, "seconds": seconds,
            "fps_best": generated / min(seconds), "fps_median": generated / float(np.median(seconds))}


def roofline(fps: float, batch: int, costs: dict, gflops: float, bandwidth_gbs: float) -> dict:
    """Compute and bandwidth bounds (frames/s) at ``batch`` and ``fps`` as a share of each.

    At batch B the weights read per step serve B frames, so the bandwidth bound grows with B.
    """
    compute = gflops * 1e9 / costs["flops_per_frame"]
    bandwidth = batch * bandwidth_gbs * 1e9 / costs["weight_bytes_per_frame"]
    return {"compute_bound_fps": compute, "bandwidth_bound_fps": bandwidth,
            "pct_of_compute_bound": 100 * fps / compute, "pct_of_bandwidth_bound": 100 * fps / bandwidth,
            "pct_of_roofline": 100 * fps / min(compute, bandwidth),
            "binding": "compute" if compute < bandwidth else "bandwidth"}
