"""References that use knowledge the learned models do not have.

How does a learned filter compare with filters that know what generated the data? Three references
(comparisons, not bounds: a model whose encoder is trained through its filter can beat them):

* ``pendulum_particle_filter`` -- a causal particle filter with the generator's TRUE pendulum
  physics (``drfkit.data.pendulum``: theta'' = -c sin theta - friction theta', velocity noise
  N(0, 0.1^2) per frame, start at rest), fed per-frame estimates of (cos, sin) and their sigma
  (in the book: the no_dynamics model's, sigma scaled by a factor chosen on validation data).
  It is what this filter makes of that encoder's outputs (up to Monte Carlo error), not the best any
  model can do: the DRF's encoder is trained through its filter, and can do better.
* ``template_angles`` -- "what the pixels hold": each frame matched against the renderer's
  own clean images at ``n_angles`` angles (normalised correlation). Per frame, no dynamics.
* ``constant_velocity_filter`` -- for pedestrians: a Kalman filter with a constant-velocity
  motion model (white-acceleration process noise) on per-frame depths.

Shapes: N sequences, T frames, M particles. Everything is numpy float64, vectorised over
sequences and particles (the loop runs over frames only).
"""
from __future__ import annotations

import math
from typing import Any, Iterable

import numpy as np
import pandas as pd

from drfkit.data import pendulum as pend
from drfkit.data.pendulum import blackout_frames
from drfkit.methods.diagnostics import abs_error_per_frame, blackout_summary

# Integration of the true physics between frames: RK4 in 5 sub-steps of 10 ms. Against the
# generator's 500 semi-implicit Euler steps the angle differs by < 1e-4 rad after a frame
# (tested), far below the 0.1 rad/s velocity noise that each frame adds.
RK4_SUBSTEPS = 5
# A resampling happens when the effective sample size falls below this fraction of M.
RESAMPLE_BELOW = 0.5


def _accel(theta: np.ndarray, vel: np.ndarray) -> np.ndarray:
    c = pend.GRAVITY * pend.LENGTH * pend.MASS / (pend.MASS * pend.LENGTH ** 2 / 3.0)
    return -c * np.sin(theta) - pend.FRICTION * vel


def pendulum_propagate(theta: np.ndarray, vel: np.ndarray, dt: float = pend.FRAME_DT,
                       substeps: int = RK4_SUBSTEPS) -> tuple[np.ndarray, np.ndarray]:
    """The noiseless pendulum over one frame (RK4), angle from hanging down, any shape."""
    h = dt / substeps
    for _ in range(substeps):
        k1t, k1v = vel, _accel(theta, vel)
        k2t, k2v = vel + 0.5 * h * k1v, _accel(theta + 0.5 * h * k1t, vel + 0.5 * h * k1v)
        k3t, k3v = vel + 0.5 * h * k2v, _accel(theta + 0.5 * h * k2t, vel + 0.5 * h * k2v)
        k4t, k4v = vel + h * k3v, _accel(theta + h * k3t, vel + h * k3v)
        theta = theta + h / 6.0 * (k1t + 2 * k2t + 2 * k3t + k4t)
        vel = vel + h / 6.0 * (k1v + 2 * k2v + 2 * k3v + k4v)
    return theta, vel


def _systematic_resample(weights: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Indices (N, M) drawn from normalised weights (N, M), one uniform offset per sequence."""
    n, m = weights.shape
    positions = (rng.random((n, 1)) + np.arange(m)) / m
    cumulative = np.cumsum(weights, axis=1)
    cumulative[:, -1] = 1.0
    rows = np.arange(n)[:, None]
    # one searchsorted over all rows: row i's values shifted into [i, i + 1]
    flat = np.searchsorted((cumulative + rows).ravel(), (positions + rows).ravel()).reshape(n, m)
    return np.clip(flat - rows * m, 0, m - 1)


def pendulum_particle_filter(obs_mean: np.ndarray, obs_sigma: np.ndarray, *, n_particles: int = 1000,
                             seed: int = 0, sigma_scale: float = 1.0, outlier: float = 0.0,
                             velocity_noise: float = pend.TRANSITION_NOISE_STD) -> np.ndarray:
    """Causal posterior means of (cos theta, sin theta) (N, T, 2) under the true physics.

    obs_mean, obs_sigma (N, T, 2): per-frame estimates of (cos, sin) and their std. The
    likelihood of a particle is (1 - outlier) N(obs; (cos, sin), (sigma_scale sigma)^2) +
    outlier * 1/4 (uniform over the square [-1, 1]^2): a small ``outlier`` keeps one
    confidently wrong frame from killing every particle near the truth.
    """
    obs_mean, obs_sigma = np.asarray(obs_mean, np.float64), np.asarray(obs_sigma, np.float64)
    if obs_mean.ndim != 3 or obs_mean.shape[-1] != 2 or obs_sigma.shape != obs_mean.shape:
        raise ValueError(f"obs_mean and obs_sigma must both be (N, T, 2) (cos, sin), got "
                         f"{obs_mean.shape} and {obs_sigma.shape}")
    if not np.all(obs_sigma > 0):
        raise ValueError("obs_sigma must be > 0 everywhere")
    if not 0.0 <= outlier < 1.0 or not sigma_scale > 0 or n_particles < 1:
        raise ValueError(f"need 0 <= outlier < 1, sigma_scale > 0, n_particles >= 1; got {outlier}, "
                         f"{sigma_scale}, {n_particles}")
    rng = np.random.default_rng(seed)
    n, steps, _ = obs_mean.shape
    theta = rng.uniform(-np.pi, np.pi, size=(n, n_particles))   # the generator's start: uniform angle, at rest
    vel = np.zeros((n, n_particles))
    log_w = np.zeros((n, n_particles))
    out = np.empty((n, steps, 2))
    for t in range(steps):
        if t > 0:
            theta, vel = pendulum_propagate(theta, vel)
            vel = vel + rng.normal(0.0, velocity_noise, size=vel.shape)
        s = sigma_scale * obs_sigma[:, t][:, None, :]                     # (N, 1, 2)
        pred = np.stack([np.cos(theta), np.sin(theta)], axis=-1)          # (N, M, 2)
        log_gauss = (-0.5 * ((obs_mean[:, t][:, None, :] - pred) / s) ** 2 - np.log(s)).sum(-1) - math.log(2 * math.pi)
        if outlier > 0:
            log_like = np.logaddexp(math.log1p(-outlier) + log_gauss, math.log(outlier / 4.0))
        else:
            log_like = log_gauss
        log_w, w = normalised_weights(log_w + log_like)
        out[:, t] = np.einsum("nm,nmk->nk", w, pred)
        log_w = resample_degenerate(w, log_w, (theta, vel), rng)
    return out


def normalised_weights(log_w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Log weights (N, M) shifted to a row maximum of 0, and the normalised weights w (N, M)."""
    log_w = log_w - log_w.max(axis=1, keepdims=True)
    w = np.exp(log_w)
    return log_w, w / w.sum(axis=1, keepdims=True)


def resample_degenerate(w: np.ndarray, log_w: np.ndarray, states: tuple[np.ndarray, ...],
                        rng: np.random.Generator) -> np.ndarray:
    """Systematic resampling of the rows whose effective sample size fell below ``RESAMPLE_BELOW`` of M:
    each state array (N, M) of ``states`` is resampled in place; returns log_w with those rows reset to 0."""
    low = 1.0 / (w ** 2).sum(axis=1) < RESAMPLE_BELOW * w.shape[1]
    if low.any():
        idx = _systematic_resample(w[low], rng)
        for state in states:
            state[low] = np.take_along_axis(state[low], idx, axis=1)
        log_w = np.where(low[:, None], 0.0, log_w)
    return log_w


# below this outlier weight the grid's next step down is 0 (no outlier term): the weight's natural bound, so
# a filter that does best with no outlier model ends its calibration there rather than at an arbitrary 1e-4
OUTLIER_FLOOR = 3e-4


def calibrate_particle_filter(obs_mean: np.ndarray, obs_sigma: np.ndarray, targets: np.ndarray, *,
                              sigma_scales: Iterable[float] = (0.5, 1.0, 2.0),
                              outliers: Iterable[float] = (0.003, 0.01, 0.03), n_particles: int = 200,
                              seed: int = 0, max_widen: int = 4) -> dict[str, float]:
    """The (sigma_scale, outlier) with the lowest MAE on VALIDATION estimates and targets (N, T, 2), on a grid
    widened until the choice is interior: while the best value of either sits at its grid's edge, the grid
    grows past that edge (sigma scale halved or doubled, outlier weight divided or multiplied by 3, capped at
    0.5; below ``OUTLIER_FLOOR`` the next step down is 0, no outlier term), at most ``max_widen`` times.
    'interior' says whether the choice ended inside both grids or on a bound of the outlier weight's range
    (0 or 0.5): a choice at a grid's arbitrary edge would say the grid, not the data, chose it."""
    scales, outs = sorted(float(v) for v in sigma_scales), sorted(float(v) for v in outliers)
    tried: dict[tuple[float, float], float] = {}
    best: dict[str, Any] = {}
    for attempt in range(max_widen + 1):
        for scale in scales:
            for eps in outs:
                if (scale, eps) not in tried:
                    est = pendulum_particle_filter(obs_mean, obs_sigma, n_particles=n_particles, seed=seed,
                                                   sigma_scale=scale, outlier=eps)
                    tried[(scale, eps)] = float(np.abs(est - targets).mean())
        (scale, eps), err = min(((k, v) for k, v in tried.items() if k[0] in scales and k[1] in outs),
                                key=lambda kv: kv[1])
        edge_scale = scale in (scales[0], scales[-1])
        edge_eps = (eps == outs[0] and eps > 0.0) or (eps == outs[-1] and eps < 0.5)
        best = {"mae": err, "sigma_scale": scale, "outlier": eps, "interior": not (edge_scale or edge_eps)}
        if best["interior"] or attempt == max_widen:
            break
        if edge_scale:
            scales.insert(0, scale / 2.0) if scale == scales[0] else scales.append(scale * 2.0)
        if edge_eps:
            if eps == outs[0]:
                outs.insert(0, eps / 3.0 if eps / 3.0 >= OUTLIER_FLOOR else 0.0)
            else:
                outs.append(min(eps * 3.0, 0.5))
    return best


def template_angles(images: np.ndarray, n_angles: int = 4096, chunk: int = 4096) -> np.ndarray:
    """Per-frame angle estimates (...) from images uint8 (..., 24, 24): the angle of the clean
    rendered template with the highest normalised correlation with the frame. The blend
    (1 - n) image + n noise is affine in the image, so the correlation needs no noise level."""
    images = np.asarray(images)
    pend.check_images(images.reshape(-1, 1, pend.IMAGE_SIZE, pend.IMAGE_SIZE))
    angles = -np.pi + 2.0 * np.pi * np.arange(n_angles) / n_angles
    templates = pend.render_pendulum(angles).reshape(n_angles, -1)
    # the renderer draws one image per arc of angles (``drfkit.data.rod_bank``): score each distinct image once,
    # in the order of its first angle, so the argmax (the first of the best) names the same angle as over all
    _, first = np.unique(templates, axis=0, return_index=True)
    first = np.sort(first)
    angles, templates = angles[first], templates[first].astype(np.float32)
    templates -= templates.mean(axis=1, keepdims=True)
    templates /= np.linalg.norm(templates, axis=1, keepdims=True)
    frames = images.reshape(-1, templates.shape[1]).astype(np.float32)
    best = np.empty(frames.shape[0], dtype=np.int64)
    for start in range(0, frames.shape[0], chunk):
        x = frames[start:start + chunk]
        x = x - x.mean(axis=1, keepdims=True)   # the norm of x does not change the argmax
        best[start:start + chunk] = np.argmax(x @ templates.T, axis=1)
    return angles[best].reshape(images.shape[:-2])


def constant_velocity_filter(obs: np.ndarray, obs_sigma: np.ndarray, observed: np.ndarray | None = None, *,
                             dt, accel_std: float, init_velocity_std: float = 10.0) -> np.ndarray:
    """Causal Kalman filter on a scalar position with state (x, x'): x' constant up to white
    acceleration of std ``accel_std``. obs, obs_sigma (N, T); ``observed`` (N, T) bool, False
    where a frame has no observation (a removed detection, or padding): the filter only predicts
    there. ``dt``: seconds between frames, a number or (N, T-1). Returns the filtered x (N, T).
    The first frame must be observed (it starts the filter at x = obs, x' = 0)."""
    obs, obs_sigma = np.asarray(obs, np.float64), np.asarray(obs_sigma, np.float64)
    if obs.ndim != 2 or obs_sigma.shape != obs.shape:
        raise ValueError(f"obs and obs_sigma must both be (N, T), got {obs.shape} and {obs_sigma.shape}")
    n, steps = obs.shape
    observed = np.ones(obs.shape, bool) if observed is None else np.asarray(observed, bool)
    if observed.shape != obs.shape:
        raise ValueError(f"observed must be (N, T) = {obs.shape}, got {observed.shape}")
    if not observed[:, 0].all():
        raise ValueError("every sequence's first frame must be observed (it starts the filter)")
    dts = np.broadcast_to(np.asarray(dt, np.float64), (n, max(steps - 1, 0)))
    x = np.stack([obs[:, 0], np.zeros(n)], axis=1)                            # (N, 2)
    P = np.zeros((n, 2, 2))
    P[:, 0, 0], P[:, 1, 1] = obs_sigma[:, 0] ** 2, init_velocity_std ** 2
    out = np.empty((n, steps))
    out[:, 0] = x[:, 0]
    q = accel_std ** 2
    for t in range(1, steps):
        h = dts[:, t - 1]
        F = np.zeros((n, 2, 2))
        F[:, 0, 0] = F[:, 1, 1] = 1.0
        F[:, 0, 1] = h
        Q = q * np.stack([np.stack([h ** 4 / 4, h ** 3 / 2], -1), np.stack([h ** 3 / 2, h ** 2], -1)], -2)
        x = np.einsum("nij,nj->ni", F, x)
        P = F @ P @ F.transpose(0, 2, 1) + Q
        s = P[:, 0, 0] + obs_sigma[:, t] ** 2
        k = P[:, :, 0] / s[:, None]                                           # (N, 2)
        k = np.where(observed[:, t, None], k, 0.0)                            # no observation: prediction only
        x = x + k * (np.nan_to_num(obs[:, t]) - x[:, 0])[:, None]
        P = P - k[:, :, None] * P[:, 0, None, :]
        out[:, t] = x[:, 0]
    return out


def like_for_like_mae(per_frame: np.ndarray, test: Any) -> float:
    """The MAE a reference is compared with the models by: on the blackout set, the mean
    over the blackout frames alone (``blackout_summary``'s 'mae_blackout', as every model's blackout
    MAE); on any other set, over every frame. One function for both sides, so a reference is never
    averaged over other frames than the models it is set beside."""
    per_frame = np.asarray(per_frame, dtype=np.float64)
    if test == "blackout":
        return blackout_summary(per_frame, blackout_frames(per_frame.size))["mae_blackout"]
    return float(per_frame.mean())


def reference_on(predict, val: dict[str, np.ndarray], sets: dict[Any, dict[str, np.ndarray]], n_particles: int,
                 seed: int) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The true-physics particle filter on one encoder's per-frame estimates.

    predict(arrays) -> (mean, sigma), each (N, T, 2): the per-frame model (no_dynamics). Its
    likelihood scale and outlier weight are chosen on ``val`` (at the training noise) only;
    then every set of ``sets`` (name -> split arrays) is filtered. Returns (table: noise,
    mae_input, mae (both ``like_for_like_mae``: the blackout set's over its blackout frames, as the
    models'), mae_all_frames, sigma_scale, outlier, n_particles; curves: MAE per frame of the
    'blackout' set, model = 'physics_reference')."""
    mean, sigma = predict(val)
    cal = calibrate_particle_filter(mean, sigma, val["targets"], n_particles=min(n_particles, 200), seed=seed)
    rows, curve_rows = [], []
    for name, arrays in sets.items():
        mean, sigma = predict(arrays)
        est = pendulum_particle_filter(mean, sigma, n_particles=n_particles, seed=seed,
                                              sigma_scale=cal["sigma_scale"], outlier=cal["outlier"])
        per_frame = abs_error_per_frame(est, arrays["targets"])
        per_frame_input = abs_error_per_frame(mean, arrays["targets"])
        row = {"noise": name, "mae_input": like_for_like_mae(per_frame_input, name),
               "mae": like_for_like_mae(per_frame, name), "mae_all_frames": float(per_frame.mean()),
               "sigma_scale": cal["sigma_scale"], "outlier": cal["outlier"], "calibration_interior": cal["interior"],
               "n_particles": n_particles}
        rows.append(row)
        if name == "blackout":
            curve_rows += [{"model": "physics_reference", "frame": f, "mae": float(e)} for f, e in enumerate(per_frame)]
    return pd.DataFrame(rows), pd.DataFrame(curve_rows, columns=["model", "frame", "mae"])
