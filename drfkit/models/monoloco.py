"""Monoloco (Bertoni et al., ICCV 2019): the per-frame pedestrian distance baseline.

Input: the 17 keypoints' (x, y), already normalised (10 K^-1 [u, v, 1]; a missed keypoint
is PifPaf's placeholder pixel back-projected, ``drfkit.data.records.PIFPAF_MISSED_UV``),
centred on the middle of the bounding box around all 17, placeholders included, as the
published code does -> 34 numbers.
Network: Linear(34, 256) -> BN -> ReLU -> Dropout, three residual blocks of two
(Linear(256, 256) -> BN -> ReLU -> Dropout), Linear(256, 2) -> (mu, s). 407,810 params.

Outputs through the shared interface: mean = mu (metres) and sigma = the std of the
Laplace(mu, b) with b = exp(s) |mu|, i.e. sigma = sqrt(2) exp(s) |mu|. The loss recovers
s = log(sigma / (sqrt(2) |mu|)) from (mean, sigma); ``head`` keeps |mu| >= MU_FLOOR in
that product so the inversion never divides by zero.

Monte Carlo dropout as in the published code: only the first, top-level dropout (after the
input layer) is switched on at test time; the residual blocks' six dropouts stay off (they
are on in training). With the same weights this gives about half the spread of mu of
switching on all seven. The "head" is the whole network and ``features`` only centres the
keypoints. BatchNorm always uses its running statistics while sampling, as Monoloco does at
test time. The S passes run either folded into one batch after one run of the input layer
('batched') or one after another ('sequential', as published; kept for the timing study).

``inputs='detected'`` is a diagnostic, not Monoloco: the same network fed what the DRF family's
encoder reads (``drfkit.models.parts.keypoint_features``: the detected keypoints centred on their
own box, missed ones 0, that centre and the 17 confidences -> 53 numbers), so that a gap between
Monoloco and the per-frame no_dynamics can be told apart: its inputs, or its network and loss.
"""
from __future__ import annotations

import math
import torch
import torch.nn.functional as F
from torch import nn

from drfkit.models.parts import (KEYPOINT_FEATURES, N_KEYPOINTS, check_dropout_p, check_keypoints, check_n_samples,
                                 keypoint_box_centre, keypoint_features, mc_dropout)
from drfkit.models.spec import ModelSpec
from drfkit.models.sequence import (SequenceModel, check_loss_args, fill_padding, frame_mask,
                                    masked_mean)

# |mu| below this (metres) is replaced by it in sigma = sqrt(2) exp(s) |mu|, so that
# sigma > 0 and the loss can invert sigma back to s. Real depths are metres away.
MU_FLOOR = 1e-3
MC_MODES = ("batched", "sequential")
# what the network reads: the published 34 centred keypoints, or the DRF family's 53 numbers (a diagnostic)
INPUTS = {"published": 2 * N_KEYPOINTS, "detected": KEYPOINT_FEATURES}
_LOG_SQRT2 = 0.5 * math.log(2.0)


def centre_keypoints(keypoints: torch.Tensor) -> torch.Tensor:
    """(B, T, 17, 3) -> (B, T, 34): Monoloco's input as published, the 17 (x, y) minus the
    centre of the bounding box around all of them, the placeholders of missed keypoints
    included (``keypoint_box_centre(..., include_missed=True)``). Layout: x0, y0, x1, y1, ...
    """
    check_keypoints(keypoints)
    return keypoint_box_centre(keypoints, include_missed=True)[1].flatten(-2)


class Monoloco(SequenceModel):
    """Per-frame Monoloco MLP on (B, T, 17, 3) keypoints -> depth (B, T, 1).

    Train it on valid frames only (e.g. reshape them to (N, 1, 17, 3)): in training mode
    BatchNorm statistics are taken over every frame passed in, padding included.
    """

    kind = "monoloco"
    spec = ModelSpec("Monoloco", "tab:orange", studies=("pedestrians",),
                     bench_modes=("published", "batched", "no_sampling"))  # its own schedule under every protocol
    per_frame = True

    def __init__(self, input_kind: str = "keypoints", out_dim: int = 1, hidden: int = 256,
                 n_blocks: int = 3, dropout_p: float = 0.2, mc_mode: str = "batched", inputs: str = "published"):
        if input_kind != "keypoints" or out_dim != 1:
            raise ValueError(f"Monoloco takes input_kind='keypoints' and out_dim=1, "
                             f"got {input_kind!r} and {out_dim!r}")
        if mc_mode not in MC_MODES:
            raise ValueError(f"mc_mode must be one of {MC_MODES}, got {mc_mode!r}")
        if inputs not in INPUTS:
            raise ValueError(f"inputs must be one of {sorted(INPUTS)}, got {inputs!r}")
        check_dropout_p(dropout_p)
        # the published inputs stay out of the config, so the names of runs made before the option hold
        extra = {"inputs": inputs} if inputs != "published" else {}
        super().__init__(dict(input_kind=input_kind, out_dim=out_dim, hidden=hidden,
                              n_blocks=n_blocks, dropout_p=dropout_p, mc_mode=mc_mode, **extra))
        self.dropout_p = float(dropout_p)
        self.mc_mode = mc_mode
        self.inputs = inputs
        self.input_layer = nn.Linear(INPUTS[inputs], hidden)
        self.input_norm = nn.BatchNorm1d(hidden)
        # block i has layers 2i and 2i + 1; the skip adds the block's input to its output
        self.layers = nn.ModuleList(nn.Linear(hidden, hidden) for _ in range(2 * n_blocks))
        self.norms = nn.ModuleList(nn.BatchNorm1d(hidden) for _ in range(2 * n_blocks))
        self.output_layer = nn.Linear(hidden, 2)

    @property
    def default_dropout_p(self) -> float:
        return self.dropout_p

    def features(self, inputs, return_gains=False):
        if self.inputs == "detected":
            check_keypoints(inputs)
            return keypoint_features(inputs.to(self.input_layer.weight.dtype)), None
        return centre_keypoints(inputs), None

    def _layer(self, x, linear, norm, p, dropout_on, bn_batch_stats):
        x = F.batch_norm(linear(x), norm.running_mean, norm.running_var, norm.weight, norm.bias,
                         training=bn_batch_stats, momentum=norm.momentum, eps=norm.eps)
        return F.dropout(F.relu(x), p, training=dropout_on)

    def _first(self, x: torch.Tensor, bn_batch_stats: bool) -> torch.Tensor:
        """(N, 34) -> (N, hidden): the input layer up to (not including) its dropout."""
        return self._layer(x, self.input_layer, self.input_norm, 0.0, False, bn_batch_stats)

    def _rest(self, y: torch.Tensor, p: float, dropout_on: bool, bn_batch_stats: bool
              ) -> tuple[torch.Tensor, torch.Tensor]:
        """(N, hidden) after the first dropout -> mu (N,), s (N,): the residual blocks and output."""
        for i in range(0, len(self.layers), 2):
            z = self._layer(y, self.layers[i], self.norms[i], p, dropout_on, bn_batch_stats)
            z = self._layer(z, self.layers[i + 1], self.norms[i + 1], p, dropout_on, bn_batch_stats)
            y = y + z
        out = self.output_layer(y)
        return out[:, 0], out[:, 1]

    def mlp(self, x: torch.Tensor, p: float, dropout_on: bool, bn_batch_stats: bool,
            first_dropout_only: bool = False) -> tuple[torch.Tensor, torch.Tensor]:
        """(N, 34) -> mu (N,), s (N,) with explicit dropout / BatchNorm modes. Training uses all
        seven dropouts; Monte Carlo sampling (``first_dropout_only``) only the input layer's."""
        y = F.dropout(self._first(x, bn_batch_stats), p, training=dropout_on)
        return self._rest(y, p, dropout_on and not first_dropout_only, bn_batch_stats)

    @staticmethod
    def mean_and_sigma(mu: torch.Tensor, s: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(mu, s) -> (mean, sigma) with sigma = sqrt(2) exp(s) max(|mu|, MU_FLOOR)."""
        sigma = math.sqrt(2.0) * torch.exp(s) * mu.abs().clamp_min(MU_FLOOR)
        return mu.unsqueeze(-1), sigma.unsqueeze(-1)

    def head(self, h, n_samples=0, dropout_p=None, uniforms=None):
        """h (B, T, 34) (53 with inputs='detected') -> mean, sigma (B, T, 1), or (S, B, T, 1) for n_samples = S > 0."""
        check_n_samples(n_samples)
        if h.ndim != 3 or h.shape[-1] != INPUTS[self.inputs]:
            raise ValueError(f"Monoloco.head expects its features (B, T, {INPUTS[self.inputs]}), got {tuple(h.shape)}")
        p = self.dropout_p if dropout_p is None else check_dropout_p(dropout_p)
        b, t, _ = h.shape
        x = h.reshape(b * t, -1)
        if n_samples == 0:
            mu, s = self.mlp(x, p, dropout_on=self.training, bn_batch_stats=self.training)
            mean, sigma = self.mean_and_sigma(mu, s)
            return mean.view(b, t, 1), sigma.view(b, t, 1)
        if p == 0.0:  # identical samples: compute once
            mu, s = self.mlp(x, p, dropout_on=False, bn_batch_stats=False)
            mu, s = (v.unsqueeze(0).expand(n_samples, -1) for v in (mu, s))
        elif self.mc_mode == "batched":  # the input layer once, its dropout masks for all S at once
            first = self._first(x, bn_batch_stats=False)
            folded = mc_dropout(first, n_samples, p, uniforms)
            mu, s = (v.view(n_samples, b * t) for v in
                     self._rest(folded.reshape(n_samples * b * t, -1), p, dropout_on=False, bn_batch_stats=False))
        else:
            passes = [self.mlp(x, p, dropout_on=True, bn_batch_stats=False, first_dropout_only=True)
                      for _ in range(n_samples)]
            mu = torch.stack([m for m, _ in passes])
            s = torch.stack([v for _, v in passes])
        mean, sigma = self.mean_and_sigma(mu, s)
        return mean.reshape(n_samples, b, t, 1), sigma.reshape(n_samples, b, t, 1)

    @staticmethod
    def log_scale(mean: torch.Tensor, sigma: torch.Tensor) -> torch.Tensor:
        """Invert ``mean_and_sigma``: s = log(sigma) - log(sqrt 2) - log(max(|mu|, MU_FLOOR))."""
        return torch.log(sigma) - _LOG_SQRT2 - torch.log(mean.abs().clamp_min(MU_FLOOR))

    def loss(self, mean, sigma, targets, mask=None):
        """Monoloco's relative Laplace loss |1 - mu / d| exp(-s) + s, averaged over valid
        frames; d = targets (metres, > 0), s recovered from sigma."""
        check_loss_args(mean, sigma, targets)
        mask = frame_mask(mask, mean.shape)
        s = self.log_scale(mean, sigma)
        targets = fill_padding(targets, mask)  # padding may hold d = 0
        per_value = torch.abs(1.0 - mean / targets) * torch.exp(-s) + s
        return masked_mean(per_value, mask)


def relative_laplace_loss(mu: torch.Tensor, s: torch.Tensor, d: torch.Tensor) -> torch.Tensor:
    """Reference form of Monoloco's loss on raw outputs, elementwise: |1 - mu/d| e^-s + s."""
    return torch.abs(1.0 - mu / d) * torch.exp(-s) + s


