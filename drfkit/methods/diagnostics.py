"""Is the filter filtering? Mechanism diagnostics for the DRF family.

A learned Kalman filter earns its name only if
  * the observation variance r follows frame quality (so the gain drops on bad frames),
  * the transition predicts (F_t z_{t-1} is closer to the next observation than z_{t-1}),
  * F_t is a plausible dynamics matrix (spectral radius near 1, not exploding), and
  * the state coasts when observations vanish (errors stay low through a blackout).
These functions measure each of those on a data set with known per-frame noise levels.
They use the deterministic pass (eval mode, dropout off): the mechanism, not the MC samples.

Shapes: N sequences, T frames, n latent size, m = ``model.memory_dims`` (unobserved dims,
left out of every r / gain / prediction statistic: they have no observation).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch

from drfkit.core.metrics import rank_correlation
from drfkit.models.frame_codes import distinct_frames_once

CLEAN_LEVEL = 0.0      # a frame with noise level <= this is clean
NOISY_LEVEL = 0.4      # a frame with noise level > this is noisy
PURE_NOISE_LEVEL = 1.0  # pure uniform noise (the blackout's frames)


def _observed(model) -> int:
    return model.latent - getattr(model, "memory_dims", 0)


@torch.no_grad()
def filter_trace(model, inputs: torch.Tensor, batch_size: int = 100) -> dict[str, np.ndarray]:
    """Per-frame quantities of ``model`` on ``inputs`` (N, T, ...), in eval mode.

    Every model of the DRF family: 'r' (N, T) mean observation variance over the observed dims,
    'mean' (N, T, out) the decoder's mean. A filter (a model with ``filter_diagnostics``: the DRF, the
    known-dynamics filter) also: 'gain' (N, T) its gain on the observed dims (1 at t = 0);
    'prior_err' and 'static_err' (N, T-1): the distance of the one-step prediction, and of the last
    posterior, to the next observation; 'spectral_radius' (M,) of its transition matrices. Each distinct
    frame is encoded once (``distinct_frames_once``; across calls inside a caller's block too): the same numbers.
    """
    was_training = model.training
    model.eval()
    try:
        parts: dict[str, list[np.ndarray]] = {}
        with distinct_frames_once(model):
            for start in range(0, inputs.shape[0], batch_size):
                x = inputs[start:start + batch_size]
                if hasattr(model, "filter_diagnostics"):
                    out = model.filter_diagnostics(x)
                    h = out.pop("h")
                else:
                    _, r = model.observe(x)
                    out = {"r": r[..., :_observed(model)].mean(-1)}
                    h, _ = model.features(x)  # the frames' codes come from the block's book
                out["mean"] = model.head(h)[0]
                for name, value in out.items():
                    parts.setdefault(name, []).append(value.float().cpu().numpy())
        return {name: np.concatenate(values) for name, values in parts.items()}
    finally:
        model.train(was_training)


def mechanism_summary(trace: dict[str, np.ndarray], noise: np.ndarray) -> dict[str, float]:
    """Scalars from a :func:`filter_trace` and the frames' true noise levels (N, T).

    r_noise_spearman  rank correlation of r with the noise level over all frames (the filter
                      can only lower its gain on bad frames if r rises with the noise)
    gain_clean, gain_noisy, gain_pure   mean gain on clean / noisy (> NOISY_LEVEL) / pure-noise
                      frames, t >= 1 (NaN where a set is empty); gain_ratio = gain_pure / gain_clean
    prior_ratio       mean ||F z - w_next|| / mean ||z - w_next|| on clean next frames (< 1: F predicts)
    spectral_radius_median, spectral_radius_p95   of F_t
    """
    noise = np.asarray(noise, dtype=np.float64)
    if noise.shape != trace["r"].shape:
        raise ValueError(f"noise must have one level per frame, shape {trace['r'].shape}, got {noise.shape}")
    out: dict[str, float] = {"r_noise_spearman": rank_correlation(np.log(trace["r"]), noise)}
    if "gain" not in trace:
        return out
    gain, later = trace["gain"][:, 1:], noise[:, 1:]

    def mean_where(values, where):
        return float(values[where].mean()) if where.any() else math.nan

    out["gain_clean"] = mean_where(gain, later <= CLEAN_LEVEL)
    out["gain_noisy"] = mean_where(gain, later > NOISY_LEVEL)
    out["gain_pure"] = mean_where(gain, later >= PURE_NOISE_LEVEL)
    out["gain_ratio"] = out["gain_pure"] / out["gain_clean"]
    clean_next = later <= CLEAN_LEVEL
    out["prior_ratio"] = mean_where(trace["prior_err"], clean_next) / mean_where(trace["static_err"], clean_next)
    radius = trace["spectral_radius"]
    out["spectral_radius_median"] = float(np.median(radius)) if radius.size else math.nan
    out["spectral_radius_p95"] = float(np.quantile(radius, 0.95)) if radius.size else math.nan
    return out


def abs_error_per_frame(mean: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """|mean - target| averaged over outputs and sequences: (N, T, out) -> (T,)."""
    mean, targets = np.asarray(mean, dtype=np.float64), np.asarray(targets, dtype=np.float64)
    if mean.shape != targets.shape:
        raise ValueError(f"mean {mean.shape} and targets {targets.shape} must have one shape (N, T, out)")
    return np.abs(mean - targets).mean(axis=(0, 2))


def blackout_summary(mae_per_frame: np.ndarray, frames: tuple[int, int], after: int = 15) -> dict[str, float]:
    """MAE on the blackout frames [start, stop) and on the ``after`` frames that follow."""
    start, stop = frames
    mae_per_frame = np.asarray(mae_per_frame, dtype=np.float64)
    if not 0 <= start < stop <= mae_per_frame.size:
        raise ValueError(f"blackout frames {frames} must lie inside the {mae_per_frame.size} frames")
    tail = mae_per_frame[stop:stop + after]
    return {"mae_blackout": float(mae_per_frame[start:stop].mean()),
            "mae_after_blackout": float(tail.mean()) if tail.size else math.nan}


# Recovery: how far the estimate is from where it was before the gap once the frames are usable again. The
# yardstick is the model's own MAE on the ``after`` ordinary frames before the gap (same sequences, same noise), so
# a slow model is not called recovered for matching its slow self; "recovered" is within RECOVERY_WITHIN of it.
RECOVERY_WITHIN = 1.5


def recovery_summary(mae_per_frame: np.ndarray, frames: tuple[int, int], after: int = 15) -> dict[str, float]:
    """After a blackout [start, stop): 'mae_before_blackout' (up to ``after`` frames before the gap),
    'recovery_ratio' (MAE on the ``after`` frames after the gap / before it; 1 = back where it was) and
    'frames_to_recover' (frames after the gap until the MAE first falls to RECOVERY_WITHIN x the before-gap MAE;
    NaN if it does not within ``after`` frames)."""
    start, stop = frames
    mae_per_frame = np.asarray(mae_per_frame, dtype=np.float64)
    if not 1 <= start < stop <= mae_per_frame.size - 1:
        raise ValueError(f"a recovery needs a frame before the blackout {frames} and one after it, "
                         f"in {mae_per_frame.size} frames")
    before = float(mae_per_frame[max(0, start - after):start].mean())
    tail = mae_per_frame[stop:stop + after]
    back = np.flatnonzero(tail <= RECOVERY_WITHIN * before)
    return {"mae_before_blackout": before, "recovery_ratio": float(tail.mean()) / before,
            "frames_to_recover": float(back[0]) if back.size else math.nan}


def diagnose(model, arrays: dict[str, Any], batch_size: int = 100) -> tuple[dict[str, float], np.ndarray]:
    """:func:`mechanism_summary` plus the overall MAE on a pendulum split ('images', 'targets',
    'noise'); returns (summary, MAE per frame (T,))."""
    trace = filter_trace(model, torch.as_tensor(arrays["images"]), batch_size)
    per_frame = abs_error_per_frame(trace["mean"], arrays["targets"])
    summary = mechanism_summary(trace, arrays["noise"])
    summary["mae"] = float(per_frame.mean())
    return summary, per_frame
