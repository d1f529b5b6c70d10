"""Predictions with aleatoric and epistemic (MC dropout) uncertainty, for any model of
``drfkit.models``.

The deterministic part of a model (encoder, filter or LSTM: ``model.features``) runs
ONCE per input chunk; the S Monte Carlo samples only go through the stochastic part
(``model.head``) in one batched call with the sample dimension folded into the batch.
That is what makes the DRF's uncertainty cheap: its dropout sits in the small decoder.

For S samples with means m_s and sigmas sigma_s (per frame and output):
    point      = the head's dropout-off mean: the point estimate every MAE and ordering reads
                 (the MC mean carries the noise of S draws; checkpoints are selected dropout-off too)
    mean       = mean_s m_s
    aleatoric  = sqrt(mean_s sigma_s^2)       the average predicted noise
    epistemic  = std_s m_s (population std)   the spread of the dropout passes
    total      = sqrt(aleatoric^2 + epistemic^2)
i.e. the moments of the equal-weight mixture of the S Gaussians.
"""
from __future__ import annotations

import contextlib
from dataclasses import dataclass
from typing import Iterator

import numpy as np
import torch

from drfkit.core.metrics import gaussian_interval
from drfkit.models.compiled import accelerated
from drfkit.models.frame_codes import distinct_frames_once
from drfkit.models.parts import SharedUniforms, check_dropout_p, check_n_samples


# Frames per call of a model's head: S = 25 samples of a 64-unit hidden layer over 600 frames are
# ~4 MB per tensor, in cache across the rates that share them (measured on one CPU thread: the heads of
# 256 pendulum sequences at five rates 1.8 s in one pass, 1.14 s in sub-chunks of 8 sequences).
HEAD_CHUNK_FRAMES = 600


@dataclass(frozen=True)
class Prediction:
    """CPU float32 tensors, each (B, T, out); gains (B, T, n, n) when asked for and the
    model has a filter, else None. ``point`` is the dropout-off mean (point metrics), ``mean`` and
    ``total`` the MC mixture's moments (interval metrics); with n_samples = 0 they coincide."""

    mean: torch.Tensor
    aleatoric: torch.Tensor
    epistemic: torch.Tensor
    total: torch.Tensor
    n_samples: int
    dropout_p: float
    point: torch.Tensor
    gains: torch.Tensor | None = None


def summarise_samples(means: torch.Tensor, sigmas: torch.Tensor
                      ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """(S, ...) sample means and sigmas -> mean, aleatoric, epistemic, total (...).

    The spread is computed about the first sample (shifted two-pass variance): stable,
    and exactly 0 when every sample is the same (dropout_p = 0).
    """
    if means.shape != sigmas.shape or means.ndim < 1 or means.shape[0] < 1:
        raise ValueError(f"means and sigmas must share a shape (S, ...) with S >= 1, "
                         f"got {tuple(means.shape)} and {tuple(sigmas.shape)}")
    offsets = means - means[:1]
    mean_offset = offsets.mean(dim=0)
    epistemic = (offsets - mean_offset).square().mean(dim=0).sqrt()
    aleatoric = sigmas.square().mean(dim=0).sqrt()
    total = torch.sqrt(aleatoric.square() + epistemic.square())
    return means[0] + mean_offset, aleatoric, epistemic, total


def as_model_input(model, inputs) -> torch.Tensor:
    """numpy array or tensor -> tensor the model accepts (checked early, with the fix)."""
    if isinstance(inputs, np.ndarray):
        inputs = torch.from_numpy(np.ascontiguousarray(inputs))
    if not isinstance(inputs, torch.Tensor):
        raise TypeError(f"inputs must be a numpy array or torch tensor, got {type(inputs).__name__}")
    if inputs.is_floating_point() and not bool(torch.isfinite(inputs).all()):
        raise ValueError("inputs contain NaN or inf: pass uint8 images, or keypoints with missed ones "
                         "zeroed (x = y = 0, confidence 0) as PifPaf does")
    if model.input_kind == "pendulum":
        if inputs.ndim != 4 or inputs.shape[-2:] != (24, 24):
            raise ValueError(f"pendulum inputs must be (B, T, 24, 24) images, got {tuple(inputs.shape)}")
        if inputs.dtype != torch.uint8 and not inputs.is_floating_point():
            raise TypeError(f"pendulum images must be uint8 0..255 (or float in [0, 1]), got {inputs.dtype}")
        return inputs
    if inputs.ndim != 4 or inputs.shape[-2:] != (17, 3):
        raise ValueError(f"keypoint inputs must be (B, T, 17, 3), got {tuple(inputs.shape)}")
    if not inputs.is_floating_point():
        raise TypeError(f"keypoints must be float32, got {inputs.dtype}")
    return inputs.to(torch.float32)


def _model_device(model) -> torch.device:
    return next(model.parameters()).device


@torch.no_grad()
def predict(model, inputs, n_samples: int = 25, dropout_p: float | None = None,
            batch_size: int | None = None, device=None, return_gains: bool = False) -> Prediction:
    """Mean and uncertainties of ``model`` on ``inputs`` (B, T, ...), in eval mode.

    n_samples: S >= 0 dropout passes of ``model.head``; 0 = one deterministic pass
        (dropout off, epistemic = 0).
    dropout_p: dropout rate used while sampling (default ``model.default_dropout_p``);
        the PICP-MPIW curves vary it.
    batch_size: sequences per chunk (bounds memory: S * chunk * T decoder rows);
        None = all at once.
    device: where to run (default: where the model is); the model's device and
        train/eval mode are restored afterwards.
    return_gains: also return the Kalman gains (B, T, n, n) (None for non-filter models).
    """
    return predict_rates(model, inputs, n_samples, [dropout_p], batch_size, device, return_gains)[0]


@contextlib.contextmanager
def _inference(model, device) -> Iterator[torch.device]:
    """``model`` in eval mode on ``device`` (default: where it is) for a block, each distinct image frame encoded
    once (``distinct_frames_once``: the same numbers); its device and mode restored after."""
    home, was_training = _model_device(model), model.training
    target = home if device is None else torch.device(device)
    model.to(target).eval()
    try:
        with distinct_frames_once(model):
            yield target
    finally:
        model.to(home).train(was_training)


def _check_batch_size(batch_size) -> None:
    if batch_size is not None and (isinstance(batch_size, bool) or not isinstance(batch_size, int)
                                   or batch_size < 1):
        raise ValueError(f"batch_size must be a positive int or None, got {batch_size!r}")


@torch.no_grad()
def model_features(model, inputs, batch_size: int | None = None, device=None) -> torch.Tensor:
    """The deterministic part of ``predict_rates``: ``model.features`` (encoder, then filter or LSTM) of ``inputs``
    (B, T, ...) in eval mode, chunk by chunk exactly as ``predict_rates`` runs it. Returns (B, T, D) on the CPU:
    what ``predict_rates(features=...)`` takes, so a later call at other dropout rates runs only the heads."""
    _check_batch_size(batch_size)
    x = as_model_input(model, inputs)
    if x.shape[0] == 0:
        raise ValueError("inputs hold no sequence (B = 0)")
    chunk = x.shape[0] if batch_size is None else batch_size
    with _inference(model, device) as target:
        parts = []
        for start in range(0, x.shape[0], chunk):
            with accelerated(model, target):
                parts.append(model.features(x[start:start + chunk].to(target))[0].cpu())
    return torch.cat(parts, dim=0)


@torch.no_grad()
def predict_rates(model, inputs, n_samples: int = 25, dropout_rates=(None,), batch_size: int | None = None,
                  device=None, return_gains: bool = False, features: torch.Tensor | None = None) -> list[Prediction]:
    """``predict`` at several dropout rates, sharing one run of ``model.features`` (the
    encoder and filter) and one draw of the dropout masks' uniforms (``SharedUniforms``: the
    mask at rate p keeps U >= p) per chunk: one Prediction per entry of ``dropout_rates``.

    features: (B, T, D) ``model_features(model, inputs, batch_size, device)`` computed before (the store of
    ``drfkit.methods.predictions``): only the heads run, and the numbers are the same bit for bit (the features
    draw no random numbers, so the masks' draws start where they would). Not with ``return_gains``."""
    n_samples = check_n_samples(n_samples)
    rates = [model.default_dropout_p if p is None else check_dropout_p(p) for p in dropout_rates]
    if not rates:
        raise ValueError("dropout_rates is empty")
    _check_batch_size(batch_size)
    x = as_model_input(model, inputs)
    n_seq = x.shape[0]
    if n_seq == 0:
        raise ValueError("inputs hold no sequence (B = 0)")
    if features is not None and (return_gains or features.ndim != 3 or features.shape[:2] != x.shape[:2]):
        raise ValueError(f"features must be model_features of these inputs, (B, T, D) with (B, T) = "
                         f"{tuple(x.shape[:2])}, and cannot give gains; got {tuple(features.shape)}"
                         f"{' with return_gains' if return_gains else ''}")
    chunk = n_seq if batch_size is None else batch_size
    with _inference(model, device) as target:
        parts: list[list[tuple[torch.Tensor, ...]]] = [[] for _ in rates]
        gains: list[torch.Tensor] = []
        for start in range(0, n_seq, chunk):
            if features is not None:
                h_chunk, g = features[start:start + chunk].to(target), None
            else:
                with accelerated(model, target):  # on CUDA a filter runs its captured step; the CPU is untouched
                    h_chunk, g = model.features(x[start:start + chunk].to(target), return_gains=return_gains)
            # the heads in sub-chunks whose S samples stay in cache (2x faster than one pass on 256 sequences)
            for h in h_chunk.split(max(1, HEAD_CHUNK_FRAMES // h_chunk.shape[1])):
                uniforms = SharedUniforms()  # one draw of the masks' uniforms, for every rate
                point, sigma = model.head(h)  # dropout off (eval mode): the point estimate, at every rate
                for i, p in enumerate(rates):
                    if n_samples == 0:
                        summary = (point, sigma, torch.zeros_like(point), sigma)
                    else:
                        summary = summarise_samples(*model.head(h, n_samples=n_samples, dropout_p=p,
                                                                uniforms=uniforms))
                    parts[i].append(tuple(t.float().cpu() for t in (*summary, point)))
            if g is not None:
                gains.append(g.float().cpu())
    all_gains = torch.cat(gains, dim=0) if gains else None
    out = []
    for p, chunks in zip(rates, parts):
        mean, aleatoric, epistemic, total, point = (torch.cat(ts, dim=0) for ts in zip(*chunks))
        out.append(Prediction(mean=mean, aleatoric=aleatoric, epistemic=epistemic, total=total,
                              n_samples=n_samples, dropout_p=p if n_samples else 0.0, point=point, gains=all_gains))
    return out


def intervals(pred: Prediction, level: float = 0.95) -> tuple[torch.Tensor, torch.Tensor]:
    """Central Gaussian interval mean -/+ z * total (z = 1.959964 at the 95 % the paper's
    PICP/MPIW figures use). Returns (lower, upper), each (B, T, out)."""
    return gaussian_interval(pred.mean, pred.total, level)
