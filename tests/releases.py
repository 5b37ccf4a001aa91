"""Small random releases for the core tests (a helper module, not a test file): shared by the
engine, follow, evaluation and benchmark tests, importable as ``releases`` because pytest puts
``tests/`` on ``sys.path`` for its conftest."""

from __future__ import annotations

import numpy as np
import torch

from model_core.io.checkpoint import save_release
from model_core.model.strnn import STRNN, STRNNConfig
from model_core.motion.conventions import LAYOUT

C = LAYOUT.size


def random_release(folder, spatial=True, residual=True, m=10, n=10, seed=0, purpose=None, offsets=False,
                   spatial_norm="batch", offset_keep=None, filter_context=False,
                   predictor_context=False, temporal_skip=False, decoder_skip=False, decode_len=None):
    """Save a random STRNN as a release in ``folder``; return (eval-mode model, mean [C], std [C])."""
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    cfg = STRNNConfig(width=64, encode_len=m, predict_len=n, spatial=spatial, residual=residual,
                      residual_width=32, offsets=offsets, spatial_norm=spatial_norm,
                      offset_keep=offset_keep, filter_context=filter_context,
                      predictor_context=predictor_context, temporal_skip=temporal_skip,
                      decoder_skip=decoder_skip, decode_len=decode_len)
    model = STRNN(cfg)
    with torch.no_grad():
        for mod in model.modules():
            if isinstance(mod, torch.nn.BatchNorm1d):
                mod.running_mean.normal_(0.0, 0.3)
                mod.running_var.uniform_(0.5, 2.0)
                mod.weight.uniform_(0.5, 1.5)
                mod.bias.normal_(0.0, 0.1)
        model.start.normal_(0.0, 0.5)
        if predictor_context:
            model.context_in.weight.normal_(0.0, 0.05)
        if temporal_skip:
            model.skip.normal_(0.0, 0.1)
        if decoder_skip:
            model.dec_skip.weight.normal_(0.0, 0.2)
        if residual:
            model.filter.net[-1].weight.normal_(0.0, 0.02)
            model.filter.net[-1].bias.normal_(0.0, 0.02)
    model.eval()
    weights = {k: v.numpy() for k, v in model.state_dict().items() if v.dtype.is_floating_point}
    mean = rng.normal(0.0, 0.2, C).astype(np.float32)
    std = rng.uniform(0.5, 1.5, C).astype(np.float32)
    seeds = (mean + std * rng.normal(size=(3, m, C))).astype(np.float32)
    meta = {"licence": "test", **({"purpose": purpose} if purpose else {})}
    save_release(folder, weights, cfg.to_dict(), mean, std, meta, seeds, ["a", "b", "c"])
    return model, mean, std
