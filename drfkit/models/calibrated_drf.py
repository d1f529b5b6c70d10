"""A DRF whose gain is calibrated out of distribution: the paper's DRF with its observation variance r read
from how noisy the frame is, through a link that extrapolates.

The paper's DRF learns r_t from the encoder's features; on frames worse than any it was trained on,
that r need not rise (the dissection, ``drfkit.methods.dissection``, measures that it does not), so the
gain stays high where the frame says nothing. Here

    s_t    = mean pixel of frame t / 127.5        an observable statistic of the frame's noise: the
                                                   benchmark blends (1 - l) clean + l U(0, 255), so on
                                                   the black background s grows linearly with the level l
                                                   (about l, plus the rod's constant share), up to pure noise
    log r_{t,i} = log_r0_i + softplus(slope_i) s_t  per latent dim i: monotone in s, log-linear, so it keeps
                                                   rising at levels no training frame had (by construction,
                                                   not by extrapolation of a network)

Everything else is the paper's DRF (``drfkit.models.drf``): encoder, LayerNorm latent w_t, LSTM transition
(F_t, q_t), Kalman step, decoder on [z_t, log diag P_t] with MC dropout. The encoder's own r head is not
read. Pendulum frames only (keypoints have no such statistic).
"""
from __future__ import annotations

import math
from typing import Any

import torch
import torch.nn.functional as F
from torch import nn

from drfkit.models.drf import DeepRecursiveFilter
from drfkit.models.parts import VARIANCE_FLOOR, mean_and_log_variance
from drfkit.models.spec import ModelSpec

PIXEL_MID = 127.5  # s = mean pixel / PIXEL_MID: pure uniform noise has s ~ 1


def frame_noise_statistic(images: torch.Tensor) -> torch.Tensor:
    """s (B, T, 1) = mean pixel / 127.5 of uint8 (or [0, 1] float) frames (B, T, H, W)."""
    if images.ndim != 4:
        raise ValueError(f"frames must be (B, T, H, W), got {tuple(images.shape)}")
    x = images.float() if images.dtype == torch.uint8 else images.float() * 255.0
    return (x.mean(dim=(-2, -1)) / PIXEL_MID).unsqueeze(-1)


class CalibratedGainDRF(DeepRecursiveFilter):
    """The paper's DRF with r_t = exp(log_r0 + softplus(slope) s_t) per latent dim (module docstring)."""

    kind = "drf_calibrated"
    spec = ModelSpec("DRF, calibrated gain", "tab:cyan", studies=("pendulum",),
                     bench_modes=("batched", "no_sampling"), protocols={"book": "fit_calibrated_prior_wide"})

    def __init__(self, input_kind: str = "pendulum", out_dim: int = 2, latent: int = 30,
                 r_slope_init: float = 2.0, **kwargs: Any):
        if input_kind != "pendulum":
            raise ValueError(f"the calibrated-gain DRF reads r from the frame's pixels: input_kind 'pendulum' only, "
                             f"got {input_kind!r}")
        if kwargs.get("memory_dims", 0) or kwargs.get("readout", "decoder") != "decoder":
            raise ValueError("the calibrated-gain DRF is the paper's DRF: no memory_dims, readout 'decoder'")
        if not (isinstance(r_slope_init, (int, float)) and r_slope_init > 0):
            raise ValueError(f"r_slope_init must be > 0 (r rises with the noise), got {r_slope_init!r}")
        super().__init__(input_kind, out_dim, latent, **kwargs)
        if r_slope_init != 2.0:
            self.config["r_slope_init"] = float(r_slope_init)
        self.log_r0 = nn.Parameter(torch.zeros(latent))
        # softplus^-1(r_slope_init): the link's slope starts at r_slope_init per unit of s
        self.r_slope = nn.Parameter(torch.full((latent,), math.log(math.expm1(r_slope_init))))

    def observation_variance(self, images: torch.Tensor) -> torch.Tensor:
        """r (B, T, n) from the frames' noise statistic through the monotone log-linear link."""
        s = frame_noise_statistic(images)                                              # (B, T, 1)
        return torch.exp(self.log_r0 + F.softplus(self.r_slope) * s) + VARIANCE_FLOOR

    def observe(self, inputs: torch.Tensor, starts: bool = True) -> tuple[torch.Tensor, torch.Tensor]:
        """w (B, T, n) from the encoder, r (B, T, n) from the frame (``observation_variance``)."""
        w, _ = self.heads(self.encoder(inputs))
        return w, self.observation_variance(inputs)

    def observation_output(self, inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(mean, sigma) (B, T, out) decoded from the observation alone, [w_t, log r_t] (an observation loss)."""
        w, r = self.observe(inputs)
        return self.head(mean_and_log_variance(w, r))


__all__ = ["CalibratedGainDRF", "PIXEL_MID", "frame_noise_statistic"]
