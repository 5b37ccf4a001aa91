"""STRNN in PyTorch: spatial encoder/decoder, LSTM encoder + backward decoder +
forward predictor (conditional), residual filter. Shapes: ``B`` batch, ``T`` time,
``C`` feature channels (normalised, :data:`conventions.LAYOUT`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import torch
from torch import nn

from ..inference.engine import offset_weights
from ..motion.conventions import LAYOUT, LIMBS, group_channels as group_indices


@dataclass
class STRNNConfig:
    frame_size: int = LAYOUT.size  # channels per frame
    width: int = 512  # L4 width and LSTM hidden size; L1..L3 are width/8, /4, /2
    encode_len: int = 20  # m: context frames
    predict_len: int = 20  # n: predicted frames (the decoder reconstructs m, or decode_len)
    spatial: bool = True  # hierarchical body-part encoder; False = "Temporal" (one linear layer)
    residual: bool = True  # residual filter over decoded + predicted frames
    residual_width: int = 512  # hidden units of the residual filter
    dropout: float = 0.0  # after each spatial layer (paper: 0.1; 0 trains better at width 128, see the model card)
    # The frame decoder outputs offsets from the last context frame (a residual connection over
    # time) instead of whole frames, so the first predicted frames start where the context ends.
    offsets: bool = False
    # With offsets: the predicted frames from this one on let go of the last context frame, its weight
    # falling linearly to 0 at the window's last frame (:func:`offset_weights`), so that an open-loop
    # rollout carries no offset, and no bias, from window to window (None: every frame an offset).
    offset_keep: int | None = None
    # Normalisation after each spatial layer: "batch" (the paper's batch norm) or "none". Batch norm
    # normalises each step's frames over the batch while training but uses running statistics at
    # inference; unrolled over the encoder, decoder and predictor steps the two differ, and the
    # first predicted frame of the released models is 3 to 4 cm off with running statistics against
    # 1 cm with the batch's (model card). "none" trains and runs the same.
    spatial_norm: str = "batch"
    # The residual filter also reads the true context frames, not only the window of decoded context
    # and prediction: the predictor's LSTM sees the context only through its state and the last frame,
    # and the filter over the whole window could correct the first predicted frames only from the
    # decoder's reconstruction of the context, errors included.
    filter_context: bool = False
    # Every input of the forward predictor also gets a learnt linear map of the context's frames less its
    # last frame (the motion leading up to the cut, as siMLPe-like predictors read it): without it the
    # predictor knows the context's pace only through the encoder's state.
    predictor_context: bool = False
    # Each predicted frame also gets a learnt linear extrapolation of the context's motion: frame i adds
    # sum_t A[i, t] (x_t - x_last), one (n, m) map shared by every channel (zero and constant velocity
    # are two such maps), so the network learns what a linear extrapolation leaves over.
    temporal_skip: bool = False
    # The backward decoder, reconstructing frame t, also reads a learnt linear map of the encoder's state at
    # frame t: without it every reconstructed frame comes from the one code of the whole window, and detail
    # the code has no room for (motion unlike the training data) is lost; with it the decoder and the
    # encoder read the window from both ends, as a bidirectional network does.
    decoder_skip: bool = False
    # The backward decoder reconstructs only the context's last this many frames (None: all m), and the residual
    # filter runs over them and the prediction. A model that reads a long context (a walk's whole cycle and more)
    # then costs little more per window than one that reads 20 frames: the encoder's steps are cheap, the
    # decoder's (a frame decoded and encoded again each step) are not.
    decode_len: int | None = None

    def __post_init__(self):
        if self.spatial_norm not in ("batch", "none"):
            raise ValueError(f"spatial_norm must be 'batch' or 'none', not {self.spatial_norm!r}")
        if self.decode_len is not None and not 1 <= self.decode_len <= self.encode_len:
            raise ValueError(f"decode_len must be 1 to encode_len ({self.encode_len}), not {self.decode_len}")

    @property
    def recon_len(self) -> int:
        """r: the context frames the decoder reconstructs (its last; the window is r + n frames)."""
        return self.encode_len if self.decode_len is None else self.decode_len

    def to_dict(self) -> dict:
        out = asdict(self)
        if self.decode_len is None:  # every frame reconstructed: as releases without the option record it
            del out["decode_len"]
        return out


class Block(nn.Sequential):
    """Fully connected, tanh, dropout, batch norm (the paper's spatial layer; ``norm="none"``: no norm)."""

    def __init__(self, n_in: int, n_out: int, dropout: float, norm: str = "batch"):
        last = nn.BatchNorm1d(n_out) if norm == "batch" else nn.Identity()
        super().__init__(nn.Linear(n_in, n_out), nn.Tanh(), nn.Dropout(dropout), last)


class SpatialEncoder(nn.Module):
    """Frames ``(N, C)`` -> body code ``(N, width)`` through L1..L4."""

    def __init__(self, cfg: STRNNConfig):
        super().__init__()
        w1, w2, w3, w4 = cfg.width // 8, cfg.width // 4, cfg.width // 2, cfg.width
        d = (cfg.dropout, cfg.spatial_norm)
        g = group_indices()
        for name, idx in g.items():
            self.register_buffer(f"idx_{name}", torch.tensor(idx), persistent=False)
        self.l1 = nn.ModuleDict({k: Block(len(g[k]), w1, *d) for k in ("torso",) + LIMBS})
        self.l2 = nn.ModuleDict({k: Block(2 * w1, w2, *d) for k in LIMBS})
        self.l3 = nn.ModuleDict({k: Block(2 * w2, w3, *d) for k in ("upper", "lower")})
        self.l4 = Block(2 * w3 + len(g["root"]) + len(g["contacts"]), w4, *d)

    def forward(self, x):
        part = {k: self.l1[k](x[:, getattr(self, f"idx_{k}")]) for k in self.l1}
        merged = {k: self.l2[k](torch.cat([part[k], part["torso"]], -1)) for k in LIMBS}
        upper = self.l3["upper"](torch.cat([merged["l_arm"], merged["r_arm"]], -1))
        lower = self.l3["lower"](torch.cat([merged["l_leg"], merged["r_leg"]], -1))
        rest = torch.cat([upper, lower, x[:, self.idx_root], x[:, self.idx_contacts]], -1)
        return self.l4(rest)  # (N, width)


class SpatialDecoder(nn.Module):
    """Body code ``(N, width)`` -> frames ``(N, C)``, mirroring :class:`SpatialEncoder`."""

    def __init__(self, cfg: STRNNConfig):
        super().__init__()
        w1, w2, w3, w4 = cfg.width // 8, cfg.width // 4, cfg.width // 2, cfg.width
        d = (cfg.dropout, cfg.spatial_norm)
        g = group_indices()
        self.groups = g
        self.frame_size = cfg.frame_size
        self.l4 = nn.ModuleDict({k: Block(w4, w3, *d) for k in ("upper", "lower")})
        self.root = nn.Linear(w4, len(g["root"]))
        self.contacts = nn.Linear(w4, len(g["contacts"]))
        self.l3 = nn.ModuleDict({k: Block(w3, w2, *d) for k in LIMBS})
        self.l2 = nn.ModuleDict({k: Block(w2, 2 * w1, *d) for k in LIMBS})
        self.out = nn.ModuleDict({k: nn.Linear(w1, len(g[k])) for k in LIMBS})
        self.torso = nn.Linear(4 * w1, len(g["torso"]))
        order = [i for k in ("root", "contacts", "torso") + LIMBS for i in g[k]]
        self.register_buffer("perm", torch.argsort(torch.tensor(order)), persistent=False)

    def forward(self, h):
        upper, lower = self.l4["upper"](h), self.l4["lower"](h)
        src = {"l_arm": upper, "r_arm": upper, "l_leg": lower, "r_leg": lower}
        limb = {k: self.l2[k](self.l3[k](src[k])) for k in LIMBS}  # (N, 2*w1): limb half, torso half
        w1 = limb["l_arm"].shape[-1] // 2
        torso = self.torso(torch.cat([limb[k][:, w1:] for k in LIMBS], -1))
        parts = [self.root(h), self.contacts(h), torso] + [self.out[k](limb[k][:, :w1]) for k in LIMBS]
        return torch.cat(parts, -1)[:, self.perm]  # (N, C) in layout order


class ResidualFilter(nn.Module):
    """Four fully connected layers (ELU) over a whole window ``(B, T, C)``, added back."""

    def __init__(self, cfg: STRNNConfig):
        super().__init__()
        n = (cfg.recon_len + cfg.predict_len) * cfg.frame_size
        n_in = n + (cfg.encode_len * cfg.frame_size if cfg.filter_context else 0)
        w = cfg.residual_width
        self.reads_context = cfg.filter_context
        self.net = nn.Sequential(nn.Linear(n_in, w), nn.ELU(), nn.Linear(w, w), nn.ELU(),
                                 nn.Linear(w, w), nn.ELU(), nn.Linear(w, n))
        nn.init.zeros_(self.net[-1].weight)
        nn.init.zeros_(self.net[-1].bias)

    def forward(self, x, context=None):
        """Window ``(B, r + n, C)`` (and, where the filter reads it, the true context ``(B, m, C)``)."""
        y = x.flatten(1)
        if self.reads_context:
            if context is None:
                raise ValueError("this residual filter reads the true context: pass it")
            y = torch.cat([y, context.flatten(1)], 1)
        return x + self.net(y).view_as(x)


class STRNN(nn.Module):
    """Encode m frames, decode them (their last r: :attr:`STRNNConfig.recon_len`) backwards and predict n frames
    forwards."""

    def __init__(self, cfg: STRNNConfig):
        super().__init__()
        self.cfg = cfg
        c, w = cfg.frame_size, cfg.width
        self.encode_frame = SpatialEncoder(cfg) if cfg.spatial else nn.Linear(c, w)
        self.decode_frame = SpatialDecoder(cfg) if cfg.spatial else nn.Linear(w, c)
        self.encoder = nn.LSTM(w, w, batch_first=True)
        self.decoder = nn.LSTMCell(w, w)
        self.predictor = nn.LSTMCell(w, w)
        self.start = nn.Parameter(torch.zeros(w))  # first input of the backward decoder
        self.filter = ResidualFilter(cfg) if cfg.residual else None
        if cfg.temporal_skip:
            self.skip = nn.Parameter(torch.zeros(cfg.predict_len, cfg.encode_len))  # starts as the model without
        if cfg.predictor_context:
            self.context_in = nn.Linear(cfg.encode_len * c, w, bias=False)
            nn.init.zeros_(self.context_in.weight)  # starts as the model without it
        if cfg.decoder_skip:
            self.dec_skip = nn.Linear(w, w, bias=False)
            nn.init.zeros_(self.dec_skip.weight)  # starts as the model without it

    def skip_frames(self, x):
        """The linear extrapolation ``(B, n, C)`` of context ``(B, m, C)`` (:attr:`STRNNConfig.temporal_skip`)."""
        if not self.cfg.temporal_skip:
            return None
        return torch.einsum("it,btc->bic", self.skip, x - x[:, -1:])

    def context_code(self, x):
        """The predictor's extra input from context ``(B, m, C)``: ``(B, W)``, or 0 without one."""
        if not self.cfg.predictor_context:
            return 0.0
        return self.context_in((x - x[:, -1:]).flatten(1))

    def encode_frames(self, x):
        b, t, c = x.shape
        return self.encode_frame(x.reshape(b * t, c)).view(b, t, -1)  # (B, T, W)

    def spatio_temporal(self, x, decode: bool = True):
        """Context ``(B, m, C)`` -> decoded ``(B, r, C)`` (the last r frames, chronological) and predicted
        ``(B, n, C)``. ``decode`` False: the context's last r frames in place of the decoded ones (the backward
        decoder is not run; inference only, :meth:`Engine.predict_next`)."""
        cfg = self.cfg
        r = cfg.recon_len
        states, (h, c) = self.encoder(self.encode_frames(x))
        h, c = h[0], c[0]  # (B, W)
        dec_skip = self.dec_skip(states) if cfg.decoder_skip and decode else None  # (B, m, W)
        dec_in = self.start.expand_as(h)
        extra = self.context_code(x)
        skip = self.skip_frames(x)
        pred_in = self.encode_frames(x[:, -1:])[:, 0] + extra
        (hd, cd), (hp, cp) = (h, c), (h, c)
        base = x[:, -1] if cfg.offsets else 0.0
        keep = offset_weights(cfg.predict_len, cfg.offset_keep)
        decoded, predicted = [], []
        for i in range(max(r, cfg.predict_len) if decode else cfg.predict_len):
            if decode and i < r:
                step_in = dec_in if dec_skip is None else dec_in + dec_skip[:, cfg.encode_len - 1 - i]
                hd, cd = self.decoder(step_in, (hd, cd))
                frame = base + self.decode_frame(hd)
                decoded.append(frame)
                dec_in = self.encode_frame(frame)
            if i < cfg.predict_len:
                hp, cp = self.predictor(pred_in, (hp, cp))
                frame = base * float(keep[i]) + self.decode_frame(hp)
                if skip is not None:
                    frame = frame + skip[:, i]
                predicted.append(frame)
                pred_in = self.encode_frame(frame) + extra
        return torch.stack(decoded[::-1], 1) if decode else x[:, -r:], torch.stack(predicted, 1)

    def forward(self, x, use_filter: bool = True, decode: bool = True):
        """Context ``(B, m, C)`` -> window ``(B, r + n, C)``: decoded context (its last r frames) then
        prediction (``decode``: :meth:`spatio_temporal`'s)."""
        decoded, predicted = self.spatio_temporal(x, decode)
        out = torch.cat([decoded, predicted], 1)
        if self.filter is not None and use_filter:
            out = self.filter(out, x)
        return out


def smoothness_cost(window, root: slice = LAYOUT.root):
    """Long-horizon cost: mean squared 2nd difference of body channels + squared 1st
    difference of the root channels, over the whole window ``(B, T, C)``."""
    body = window[..., LAYOUT.positions]
    acc = body[:, 2:] - 2 * body[:, 1:-1] + body[:, :-2]
    vel = window[:, 1:, root] - window[:, :-1, root]
    return acc.pow(2).mean() + vel.pow(2).mean()

