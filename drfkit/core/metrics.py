"""Uncertainty metrics for regression with Gaussian predictions N(mu, sigma^2).

Every metric accepts numpy arrays, torch tensors (detached and converted to numpy
float64) or Python numbers, with shapes that broadcast together, and an optional
boolean ``mask`` (True = the element counts; used to drop padded frames). The mask has
the broadcast shape of the other arguments (or broadcasts to it without enlarging it).
Scalar metrics return a Python float: the mean over all counted elements.

To catch a classic bug early, broadcasting must not create a shape larger than every
input: y of shape (N,) with mu of shape (N, 1) would silently broadcast to (N, N), and
is rejected here.

Definitions (Gneiting & Raftery 2007; Kuleshov et al. 2018), z = (y - mu) / sigma:

    PICP  = mean 1[lower <= y <= upper]            (a fraction in [0, 1])
    MPIW  = mean (upper - lower)
    NLL   = 0.5 log(2 pi sigma^2) + (y - mu)^2 / (2 sigma^2)
    CRPS  = sigma [z (2 Phi(z) - 1) + 2 phi(z) - 1 / sqrt(pi)]
    IS_a  = (u - l) + 2/a (l - y) 1[y < l] + 2/a (y - u) 1[y > u]
"""
from __future__ import annotations

import math
from statistics import NormalDist

import numpy as np
import pandas as pd
import torch

__all__ = [
    "normal_cdf", "normal_ppf", "gaussian_interval", "mae", "picp", "mpiw", "gaussian_nll",
    "crps_gaussian", "interval_score", "calibration_curve", "calibration_error",
    "DEFAULT_CALIBRATION_LEVELS", "rank_correlation", "t975", "prediction_metrics", "bootstrap_interval",
]

# 0.05, 0.10, ..., 0.95 (19 levels)
DEFAULT_CALIBRATION_LEVELS = np.round(np.arange(1, 20) * 0.05, 10)

_STANDARD_NORMAL = NormalDist()


# --------------------------------------------------------------------------- normal distribution

def normal_cdf(x) -> np.ndarray:
    """Standard normal CDF Phi(x) = erfc(-x / sqrt 2) / 2, elementwise, float64.

    erfc (rather than 1 + erf) keeps full relative accuracy in the lower tail.
    """
    x = np.asarray(x, dtype=np.float64)
    return 0.5 * torch.special.erfc(torch.as_tensor(np.asarray(-x / math.sqrt(2.0)))).numpy()


def normal_ppf(p) -> np.ndarray:
    """Standard normal quantile Phi^-1(p) for p in (0, 1), elementwise, float64."""
    p = np.asarray(p, dtype=np.float64)
    if not np.all((p > 0) & (p < 1)):
        raise ValueError(f"probabilities must lie strictly between 0 and 1, got {p}")
    return np.vectorize(_STANDARD_NORMAL.inv_cdf, otypes=[np.float64])(p)


def _standard_normal_pdf(z: np.ndarray) -> np.ndarray:
    return np.exp(-0.5 * z * z) / math.sqrt(2.0 * math.pi)


# --------------------------------------------------------------------------- input handling

def _as_float64(name: str, x) -> np.ndarray:
    if isinstance(x, torch.Tensor):
        return x.detach().to("cpu", torch.float64).numpy()
    try:
        arr = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise TypeError(f"{name} must be a numpy array, torch tensor or number, got {type(x).__name__}") from err
    return arr


def _as_mask(mask) -> np.ndarray:
    m = mask.detach().cpu().numpy() if isinstance(mask, torch.Tensor) else np.asarray(mask)
    if m.dtype != np.bool_:
        raise TypeError(f"mask must be boolean (True = element counts), got dtype {m.dtype}; "
                        f"use mask.astype(bool) or mask > 0")
    return m


def _broadcast_shape(shapes: dict[str, tuple[int, ...]]) -> tuple[int, ...]:
    shapes = {k: tuple(s) for k, s in shapes.items()}
    desc = ", ".join(f"{k} {s}" for k, s in shapes.items())
    try:
        shape = np.broadcast_shapes(*shapes.values())
    except ValueError:
        raise ValueError(f"shapes do not broadcast: {desc}") from None
    if all(s != shape for s in shapes.values()):
        raise ValueError(f"shapes {desc} would broadcast to {shape}, larger than every input: "
                         f"probably a missing squeeze/reshape (e.g. (N,) against (N, 1))")
    return shape


def _counted(mask, **inputs) -> dict[str, np.ndarray]:
    """Broadcast the inputs, drop the masked-out elements, return 1-D float64 arrays."""
    named = {k: _as_float64(k, v) for k, v in inputs.items()}
    shape = _broadcast_shape({k: v.shape for k, v in named.items()})
    if mask is None:
        flat = {k: np.broadcast_to(v, shape).reshape(-1) for k, v in named.items()}
    else:
        m = _as_mask(mask)
        try:
            ok = np.broadcast_shapes(m.shape, shape) == shape
        except ValueError:
            ok = False
        if not ok:
            raise ValueError(f"mask has shape {m.shape} but the inputs broadcast to {shape}; "
                             f"the mask must have that shape")
        keep = np.broadcast_to(m, shape)
        flat = {k: np.broadcast_to(v, shape)[keep] for k, v in named.items()}
    if next(iter(flat.values())).size == 0:
        raise ValueError("no element is counted (empty input or mask all False)")
    for k, v in flat.items():
        if not np.isfinite(v).all():
            raise ValueError(f"{k} contains NaN or inf at counted elements; mask them out or fix the input")
    return flat


def _check_sigma(sigma: np.ndarray) -> None:
    if not (sigma > 0).all():
        raise ValueError(f"sigma must be > 0 at every counted element, smallest is {sigma.min():.6g}")


def _check_interval(lower: np.ndarray, upper: np.ndarray) -> None:
    if not (lower <= upper).all():
        worst = float(np.max(lower - upper))
        raise ValueError(f"lower > upper at some counted element (by up to {worst:.6g}); "
                         f"did you swap lower and upper?")


def _check_level(name: str, level: float) -> float:
    level = float(level)
    if not 0.0 < level < 1.0:
        raise ValueError(f"{name} must lie strictly between 0 and 1, got {level}")
    return level


# --------------------------------------------------------------------------- intervals

def gaussian_interval(mu, sigma, level: float = 0.95):
    """Central interval of N(mu, sigma^2) holding probability ``level``: mu -/+ z sigma.

    z = Phi^-1((1 + level) / 2), 1.959964 for level 0.95. Returns (lower, upper) of the
    input kind: torch tensors (same dtype/device, differentiable) if mu or sigma is a
    tensor, otherwise numpy float64 arrays.
    """
    level = _check_level("level", level)
    z = _STANDARD_NORMAL.inv_cdf(0.5 + 0.5 * level)
    if isinstance(mu, torch.Tensor) or isinstance(sigma, torch.Tensor):
        ref = mu if isinstance(mu, torch.Tensor) else sigma
        mu_t = torch.as_tensor(mu, dtype=ref.dtype, device=ref.device)
        sigma_t = torch.as_tensor(sigma, dtype=ref.dtype, device=ref.device)
        _broadcast_shape({"mu": mu_t.shape, "sigma": sigma_t.shape})
        if not bool((sigma_t > 0).all()):
            raise ValueError(f"sigma must be > 0, smallest is {float(sigma_t.min()):.6g}")
        return mu_t - z * sigma_t, mu_t + z * sigma_t
    mu_a, sigma_a = _as_float64("mu", mu), _as_float64("sigma", sigma)
    _broadcast_shape({"mu": mu_a.shape, "sigma": sigma_a.shape})
    if not (sigma_a > 0).all():
        raise ValueError(f"sigma must be > 0, smallest is {sigma_a.min():.6g}")
    return mu_a - z * sigma_a, mu_a + z * sigma_a


# --------------------------------------------------------------------------- scalar metrics

def mae(y, mu, mask=None) -> float:
    """Mean absolute error mean |y - mu|."""
    a = _counted(mask, y=y, mu=mu)
    return float(np.mean(np.abs(a["y"] - a["mu"])))


def picp(y, lower, upper, mask=None) -> float:
    """Prediction interval coverage probability: fraction of y in [lower, upper] (in [0, 1])."""
    a = _counted(mask, y=y, lower=lower, upper=upper)
    _check_interval(a["lower"], a["upper"])
    return float(np.mean((a["lower"] <= a["y"]) & (a["y"] <= a["upper"])))


def mpiw(lower, upper, mask=None) -> float:
    """Mean prediction interval width mean (upper - lower)."""
    a = _counted(mask, lower=lower, upper=upper)
    _check_interval(a["lower"], a["upper"])
    return float(np.mean(a["upper"] - a["lower"]))


def gaussian_nll(y, mu, sigma, mask=None) -> float:
    """Mean negative log-likelihood of y under N(mu, sigma^2) (natural log, no constant dropped)."""
    a = _counted(mask, y=y, mu=mu, sigma=sigma)
    _check_sigma(a["sigma"])
    var = a["sigma"] ** 2
    return float(np.mean(0.5 * np.log(2.0 * math.pi * var) + (a["y"] - a["mu"]) ** 2 / (2.0 * var)))


def crps_gaussian(y, mu, sigma, mask=None) -> float:
    """Mean continuous ranked probability score of N(mu, sigma^2) at y (closed form; lower is better)."""
    a = _counted(mask, y=y, mu=mu, sigma=sigma)
    _check_sigma(a["sigma"])
    z = (a["y"] - a["mu"]) / a["sigma"]
    crps = a["sigma"] * (z * (2.0 * normal_cdf(z) - 1.0) + 2.0 * _standard_normal_pdf(z) - 1.0 / math.sqrt(math.pi))
    return float(np.mean(crps))


def interval_score(y, lower, upper, alpha: float, mask=None) -> float:
    """Mean interval score of the central (1 - alpha) interval (Gneiting & Raftery 2007).

    IS = (u - l) + 2/alpha (l - y) 1[y < l] + 2/alpha (y - u) 1[y > u]; lower is better.
    """
    alpha = _check_level("alpha", alpha)
    a = _counted(mask, y=y, lower=lower, upper=upper)
    _check_interval(a["lower"], a["upper"])
    y_, l_, u_ = a["y"], a["lower"], a["upper"]
    score = (u_ - l_) + (2.0 / alpha) * (np.maximum(l_ - y_, 0.0) + np.maximum(y_ - u_, 0.0))
    return float(np.mean(score))


# --------------------------------------------------------------------------- calibration

def calibration_curve(y, mu, sigma, levels=None, mask=None) -> tuple[np.ndarray, np.ndarray]:
    """Calibration curve of Gaussian predictions (Kuleshov et al. 2018).

    For each level p_j in (0, 1) (default 0.05, 0.10, ..., 0.95), the observed fraction of
    counted y at or below the predicted p_j quantile mu + sigma Phi^-1(p_j). A calibrated
    predictor gives observed == expected. Returns (expected, observed), both float64 (J,).
    The comparison is made on the standardised residual (y - mu) / sigma <= Phi^-1(p_j),
    which is the same event up to rounding.
    """
    expected = DEFAULT_CALIBRATION_LEVELS.copy() if levels is None else _as_float64("levels", levels).reshape(-1)
    if expected.size == 0 or not np.all((expected > 0) & (expected < 1)):
        raise ValueError(f"levels must be a non-empty list of values strictly between 0 and 1, got {expected}")
    a = _counted(mask, y=y, mu=mu, sigma=sigma)
    _check_sigma(a["sigma"])
    z_sorted = np.sort((a["y"] - a["mu"]) / a["sigma"])
    below = np.searchsorted(z_sorted, normal_ppf(expected), side="right")
    return expected, below / z_sorted.size


def calibration_error(y, mu, sigma, levels=None, mask=None) -> float:
    """Mean squared gap between observed and expected calibration-curve levels.

    cal = (1/J) sum_j (observed_j - p_j)^2 over the levels of :func:`calibration_curve`:
    Kuleshov et al.'s (2018) calibration error without their per-level weights
    (they weight each level by the number of predictions; here all levels count equally).
    0 is perfect calibration.
    """
    expected, observed = calibration_curve(y, mu, sigma, levels=levels, mask=mask)
    return float(np.mean((observed - expected) ** 2))


def rank_correlation(x, y) -> float:
    """Spearman's rank correlation of two 1-D arrays (average ranks for ties); NaN if either is constant."""
    x, y = np.asarray(x, dtype=np.float64).reshape(-1), np.asarray(y, dtype=np.float64).reshape(-1)
    if x.shape != y.shape or x.size < 2:
        raise ValueError(f"need two 1-D arrays of one length >= 2, got {x.shape} and {y.shape}")
    rx, ry = pd.Series(x).rank().to_numpy(), pd.Series(y).rank().to_numpy()
    if rx.std() == 0 or ry.std() == 0:
        return math.nan
    return float(np.corrcoef(rx, ry)[0, 1])


# Two-sided 95 % Student-t quantiles t_{0.975, df}; beyond df = 30 the normal value.
_T975 = {1: 12.706, 2: 4.303, 3: 3.182, 4: 2.776, 5: 2.571, 6: 2.447, 7: 2.365, 8: 2.306, 9: 2.262,
         10: 2.228, 12: 2.179, 15: 2.131, 20: 2.086, 25: 2.060, 30: 2.042}


def bootstrap_interval(per_unit, level: float = 0.95, n_boot: int = 2000, seed: int = 0) -> tuple[float, float]:
    """Percentile bootstrap interval of the mean of ``per_unit`` (N,) values (one per independent unit: a
    sequence), resampling the units with replacement ``n_boot`` times from ``seed``."""
    x = np.asarray(per_unit, dtype=np.float64).ravel()
    if x.size < 2:
        return math.nan, math.nan
    _check_level("level", level)
    idx = np.random.default_rng(seed).integers(0, x.size, size=(n_boot, x.size))
    means = x[idx].mean(axis=1)
    return float(np.quantile(means, (1 - level) / 2)), float(np.quantile(means, (1 + level) / 2))


def t975(df: int) -> float:
    if df < 1:
        return math.nan
    if df > 30:
        return 1.960
    key = max(k for k in _T975 if k <= df)
    return _T975[key]


def prediction_metrics(mean, total_sigma, targets, mask=None, level: float = 0.95, point=None) -> dict[str, float]:
    """All metrics of Gaussian predictions N(mean, total_sigma^2) against ``targets``; the MAE of
    ``point`` (the dropout-off estimate, ``drfkit.methods.uncertainty.Prediction.point``) where given,
    else of ``mean``: point metrics read the point estimate, interval metrics the predictive Gaussian.

    mean, total_sigma, targets, point: (N, T, out); mask: (N, T) bool or None (broadcast over out).
    """
    mean, sigma, y = (np.asarray(torch.as_tensor(a).detach().cpu(), dtype=np.float64)
                      for a in (mean, total_sigma, targets))
    point = mean if point is None else np.asarray(torch.as_tensor(point).detach().cpu(), dtype=np.float64)
    if point.shape != mean.shape:
        raise ValueError(f"point must have the mean's shape {mean.shape}, got {point.shape}")
    m = None
    if mask is not None:
        m = np.broadcast_to(np.asarray(torch.as_tensor(mask).cpu(), dtype=bool)[..., None], y.shape)
    lower, upper = gaussian_interval(mean, sigma, level)
    return {
        "mae": mae(y, point, mask=m),
        "picp": picp(y, lower, upper, mask=m),
        "mpiw": mpiw(lower, upper, mask=m),
        "nll": gaussian_nll(y, mean, sigma, mask=m),
        "crps": crps_gaussian(y, mean, sigma, mask=m),
        "cal_error": calibration_error(y, mean, sigma, mask=m),
    }
