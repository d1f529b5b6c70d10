"""Do a model's intervals mean what they say? Coverage at nominal levels, the NLL and the calibration error of
Gaussian predictions N(mu, sigma^2), before and after a one-scalar recalibration of sigma.

The recalibration (the Gaussian family's one-parameter case of Kuleshov et al. 2018's recalibration, fitted on
validation data only) multiplies every sigma of a model by one number

    s = sqrt(mean(z^2)),   z = (y - mu) / sigma,

the maximum-likelihood scale of the residuals under N(0, (s sigma)^2): s = 5 says the intervals were five times
too narrow, s = 0.2 five times too wide. One scalar keeps the ranking of a model's sigmas (what gating and a
sharpness claim read) and moves only their size; applied the same way to every model it puts every model's
intervals on the scale their validation errors call for, so PICP and MPIW compare like with like.

Arrays: y, mu, sigma of one shape (..., out); mask (...) or (..., out) bool of the counted values (None = all).
"""
from __future__ import annotations

import numpy as np

from drfkit.core import metrics

NOMINAL_LEVELS = (0.68, 0.90, 0.95)  # the coverage the table reports, nominal


def _counted(y, mu, sigma, mask) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    y, mu, sigma = (np.asarray(a, dtype=np.float64) for a in (y, mu, sigma))
    if not (y.shape == mu.shape == sigma.shape):
        raise ValueError(f"y, mu and sigma must share one shape, got {y.shape}, {mu.shape}, {sigma.shape}")
    if mask is not None:
        m = np.asarray(mask, dtype=bool)
        m = np.broadcast_to(m[..., None] if m.ndim == y.ndim - 1 else m, y.shape)
        y, mu, sigma = y[m], mu[m], sigma[m]
    if y.size == 0:
        raise ValueError("no counted values: the mask leaves nothing to calibrate")
    if not np.all(sigma > 0):
        raise ValueError("every sigma must be > 0 (a zero or negative sigma has no interval)")
    return y.reshape(-1), mu.reshape(-1), sigma.reshape(-1)


def sigma_scale(y, mu, sigma, mask=None) -> float:
    """s = sqrt(mean(((y - mu) / sigma)^2)) over the counted values: the one scalar whose sigma * s has the
    lowest Gaussian NLL on these data (fit it on validation)."""
    y, mu, sigma = _counted(y, mu, sigma, mask)
    return float(np.sqrt(np.mean(np.square((y - mu) / sigma))))


def calibration_summary(y, mu, sigma, mask=None, scale: float = 1.0,
                        nominal=NOMINAL_LEVELS) -> dict[str, float]:
    """The Gaussian predictions N(mu, (scale * sigma)^2) against y: 'nll' (mean per value), 'cal_error'
    (``metrics.calibration_error``, 0 = calibrated), 'picp_<p>' the observed coverage of the central interval
    of nominal level p (as a fraction) and 'mpiw_<p>' its mean width, for p in ``nominal`` (named by percent:
    picp_68, picp_90, picp_95), 'sigma' the mean sigma used, 'z_rms' sqrt(mean(z^2)) (1 where calibrated) and
    'scale'."""
    if not scale > 0:
        raise ValueError(f"scale must be > 0, got {scale!r}")
    y, mu, sigma = _counted(y, mu, sigma, mask)
    sigma = sigma * scale
    out = {"nll": metrics.gaussian_nll(y, mu, sigma), "cal_error": metrics.calibration_error(y, mu, sigma),
           "sigma": float(sigma.mean()), "z_rms": float(np.sqrt(np.mean(np.square((y - mu) / sigma)))),
           "scale": float(scale)}
    for p in nominal:
        lower, upper = metrics.gaussian_interval(mu, sigma, p)
        name = f"{round(100 * p):d}"
        out[f"picp_{name}"] = metrics.picp(y, lower, upper)
        out[f"mpiw_{name}"] = metrics.mpiw(lower, upper)
    return out


__all__ = ["NOMINAL_LEVELS", "calibration_summary", "sigma_scale"]
