"""The limit on pixels: Bayes estimates that know the benchmark's exact observation model.

A noisy frame is ``rint((1 - l) c + l u)`` per pixel, u ~ U(0, 255), c the clean pixel, l the frame's noise
level (``drfkit.data.noise.blend_uniform_noise``). So, for l > 0,

    P(pixel = k | c, l) = |[k - 1/2, k + 1/2) ∩ [(1 - l) c, (1 - l) c + 255 l]| / (255 l)

and P(k | c, 0) = [k = c]. Pixels are independent given the clean frame, and a clean frame is one of the
bank's images (``drfkit.data.rod_bank``: every image the renderer can draw, each standing for its arc of
angles). Three estimators use it, none learned:

* ``frame_log_likelihoods`` -- log P(frame | image j) (F, J), with the noise level known (the true one) or
  marginalised over a grid of levels (uniform prior, ``LEVEL_GRID``).
* ``per_frame_bayes`` -- the posterior mean of (cos theta, sin theta) of one frame, no dynamics.
* ``pixel_particle_filter`` -- a particle filter with the TRUE physics (``drfkit.methods.oracle``'s
  propagation, velocity noise N(0, 0.1^2) per frame, start uniform at rest) weighting particles by the
  exact likelihood of the image their angle draws: the best that is physically possible on these
  pixels, up to Monte Carlo error (``particle_convergence`` shows it).

Shapes: N sequences, T frames, F = N*T frames, J bank images, M particles, K = the most inked pixels of
an image. A pixel outside a level's range gets probability ``FLOOR`` / (255 l) rather than 0, so one
rounding accident at a range's edge cannot veto the true image.
"""
from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
import torch

from drfkit.data import pendulum as pend
from drfkit.data.rod_bank import rod_bank
from drfkit.methods.oracle import normalised_weights, pendulum_propagate, resample_degenerate

FLOOR = 1e-4
# the marginal over an unknown level: l = 0 and 128 levels up to 1, equally likely a priori
LEVEL_GRID = (0.0, *np.linspace(1.0 / 128, 1.0, 128))
# Of the grid, each frame sums over the levels its never-inked pixels admit: a never-inked pixel holds at
# most rint(255 l), so levels below (max - 1/2) / 255 are out (a FLOOR penalty, the same for every image),
# and the max of the ~85 such pixels lies above LEVEL_SPAN * 255 l but with probability 0.85^85 ~ 1e-6, so
# levels above that bound / LEVEL_SPAN (+ a grid step) lose a factor (l_kept / l)^576 and are negligible
# (tests/test_pixel_bayes.py compares with the whole grid).
LEVEL_SPAN = 0.85
FRAME_CHUNK = 256  # frames per gather: (chunk, J, K) int64 ~ 50 MB


def _sparse_bank():
    """Pixel indices (J, K) and values (J, K) of each bank image's inked pixels, padded with (0, 0)."""
    bank = rod_bank()
    flat = bank.images.reshape(len(bank), -1).astype(np.int64)
    k = int((flat > 0).sum(1).max())
    pix, val = np.zeros((len(bank), k), np.int64), np.zeros((len(bank), k), np.int64)
    for j, row in enumerate(flat):
        nz = np.flatnonzero(row)
        pix[j, :nz.size], val[j, :nz.size] = nz, row[nz]
    return torch.from_numpy(pix), torch.from_numpy(val)


def pixel_log_prob(k: torch.Tensor, c: torch.Tensor, level: torch.Tensor) -> torch.Tensor:
    """log P(pixel = k | clean c, level l), broadcast over any shapes (float64 math, module docstring)."""
    k, c, level = k.double(), c.double(), level.double()
    lo = (1.0 - level) * c
    width = 255.0 * level
    overlap = (torch.minimum(k + 0.5, lo + width) - torch.maximum(k - 0.5, lo)).clamp(0.0, 1.0)
    noisy = torch.log(overlap.clamp_min(FLOOR)) - torch.log(width.clamp_min(1e-300))
    exact = torch.where(k == c, 0.0, math.log(FLOOR))
    return torch.where(level > 0, noisy, exact)


def frame_log_likelihoods(images: np.ndarray, levels: np.ndarray | None = None) -> np.ndarray:
    """log P(frame | bank image j) (F, J) of frames uint8 (F, 24, 24).

    ``levels`` (F,): each frame's true noise level; None: marginalised over ``LEVEL_GRID`` (uniform).
    Per frame, the sum over the 576 pixels is split into the sum as if every pixel were background
    (c = 0, one value per frame) plus, over each image's K inked pixels, the change their value makes."""
    images = np.asarray(images)
    if images.dtype != np.uint8 or images.ndim != 3 or images.shape[1:] != (pend.IMAGE_SIZE, pend.IMAGE_SIZE):
        raise ValueError(f"images must be uint8 (F, 24, 24), got {images.dtype} {images.shape}")
    x_all = torch.from_numpy(images.reshape(images.shape[0], -1).astype(np.int64))           # (F, 576)
    pix, val = _sparse_bank()
    if levels is not None:
        levels = np.asarray(levels, np.float64).reshape(-1)
        if levels.shape[0] != images.shape[0] or not np.all((levels >= 0) & (levels <= 1)):
            raise ValueError(f"levels must hold one level in [0, 1] per frame ({images.shape[0]}), got {levels.shape}")
    out = np.empty((images.shape[0], pix.shape[0]))
    if levels is not None:
        for start in range(0, images.shape[0], FRAME_CHUNK):
            x = x_all[start:start + FRAME_CHUNK]
            xk, lv = x[:, pix], torch.from_numpy(levels[start:start + FRAME_CHUNK])
            background = pixel_log_prob(x, torch.zeros(()), lv[:, None]).sum(1, keepdim=True)
            change = pixel_log_prob(xk, val, lv[:, None, None]) - pixel_log_prob(xk, torch.zeros(()), lv[:, None, None])
            out[start:start + x.shape[0]] = (background + change.sum(-1)).numpy()
        return out
    tables = _level_tables()                                                                # (G, 65536)
    grid = torch.tensor(LEVEL_GRID, dtype=torch.float64)
    blank_pixels = torch.from_numpy(np.flatnonzero(~(rod_bank().images > 0).any(0).reshape(-1)))
    for start in range(0, images.shape[0], FRAME_CHUNK):
        x = x_all[start:start + FRAME_CHUNK]
        xk = x[:, pix]                                                                      # (f, J, K)
        low = (x[:, blank_pixels].amax(1).double() - 0.5).clamp_min(0.0) / 255.0
        first = torch.searchsorted(grid, low - 1e-12)                                       # (f,)
        last = torch.searchsorted(grid, (low / LEVEL_SPAN + 1.0 / 128).clamp_max(1.0)).clamp_max(len(grid) - 1)
        codes = (x * 256, xk * 256 + val, xk * 256)
        terms = []
        for i in range(int((last - first).max()) + 1):
            level = (first + i).clamp_max(len(grid) - 1)
            term = _loglik_at(tables, level, *codes)
            terms.append(torch.where((first + i <= last)[:, None], term, -math.inf))
        out[start:start + x.shape[0]] = (torch.logsumexp(torch.stack(terms), 0) - math.log(len(grid))).numpy()
    return out


@lru_cache(maxsize=1)
def _level_tables() -> torch.Tensor:
    """log P(k | c, l) for every grid level: (G, 65536), entry k * 256 + c."""
    codes = torch.arange(256)
    return torch.stack([pixel_log_prob(codes[:, None], codes[None, :], torch.tensor(float(g))).flatten()
                        for g in LEVEL_GRID]).float()  # float32: sums of 576 terms stay within 1e-3 of float64


def _loglik_at(tables: torch.Tensor, level: torch.Tensor, bg_codes: torch.Tensor, inked_codes: torch.Tensor,
               blank_codes: torch.Tensor) -> torch.Tensor:
    """(f, J) log-likelihoods of f frames, frame i at grid level ``level[i]``: ``tables`` (G, 65536) =
    log P(k | c) at k * 256 + c; the frames' codes k * 256 + c at every pixel as background (f, 576) and
    at each image's inked pixels, inked (f, J, K) and as background (f, J, K)."""
    rows = level[:, None]
    background = tables[rows, bg_codes].sum(1, keepdim=True)                                # (f, 1)
    shape = inked_codes.shape
    inked = tables[rows, inked_codes.flatten(1)]                                            # padding: (0, 0) adds 0
    blank = tables[rows, blank_codes.flatten(1)]
    return background + (inked - blank).view(shape).sum(-1)


def per_frame_bayes(images: np.ndarray, levels: np.ndarray | None = None,
                    loglik: np.ndarray | None = None) -> np.ndarray:
    """Posterior mean of (cos theta, sin theta) (..., 2) of each frame uint8 (..., 24, 24) alone: angles
    uniform a priori (each bank image weighted by its arc), the exact likelihood (``frame_log_likelihoods``;
    pass ``loglik`` (F, J) to reuse one)."""
    images = np.asarray(images)
    lead = images.shape[:-2]
    if loglik is None:
        loglik = frame_log_likelihoods(images.reshape(-1, *images.shape[-2:]),
                                       None if levels is None else np.asarray(levels).reshape(-1))
    bank = rod_bank()
    log_post = loglik + np.log(bank.arc_weight)[None, :]
    log_post -= log_post.max(1, keepdims=True)
    post = np.exp(log_post)
    post /= post.sum(1, keepdims=True)
    return (post @ bank.arc_mean).reshape(*lead, 2)


def pixel_particle_filter(loglik: np.ndarray, *, n_particles: int = 2000, seed: int = 0,
                          velocity_noise: float = pend.TRANSITION_NOISE_STD) -> np.ndarray:
    """Causal posterior means of (cos theta, sin theta) (N, T, 2) under the true physics, from the exact
    per-frame log-likelihoods ``loglik`` (N, T, J) of the bank's images (``frame_log_likelihoods``
    reshaped). A particle's likelihood is that of the image its angle draws."""
    loglik = np.asarray(loglik, np.float64)
    bank = rod_bank()
    if loglik.ndim != 3 or loglik.shape[-1] != len(bank):
        raise ValueError(f"loglik must be (N, T, {len(bank)}) (one value per bank image), got {loglik.shape}")
    if n_particles < 1:
        raise ValueError(f"n_particles must be >= 1, got {n_particles}")
    rng = np.random.default_rng(seed)
    n, steps, _ = loglik.shape
    theta = rng.uniform(-np.pi, np.pi, size=(n, n_particles))        # the generator's start: uniform angle, at rest
    vel = np.zeros((n, n_particles))
    log_w = np.zeros((n, n_particles))
    rows = np.arange(n)[:, None]
    out = np.empty((n, steps, 2))
    for t in range(steps):
        if t > 0:
            theta, vel = pendulum_propagate(theta, vel, substeps=2)
            vel = vel + rng.normal(0.0, velocity_noise, size=vel.shape)
        idx = bank.lookup(theta)                                        # (N, M); -1: a tip outside the bank
        frame = loglik[:, t]
        like = np.where(idx >= 0, frame[rows, np.maximum(idx, 0)], frame.min(1, keepdims=True))
        log_w, w = normalised_weights(log_w + like)
        out[:, t, 0] = (w * np.cos(theta)).sum(1)
        out[:, t, 1] = (w * np.sin(theta)).sum(1)
        log_w = resample_degenerate(w, log_w, (theta, vel), rng)
    return out


def sequence_log_likelihoods(images: np.ndarray, levels: np.ndarray | None = None) -> np.ndarray:
    """``frame_log_likelihoods`` of sequences uint8 (N, T, 24, 24) -> (N, T, J) (levels (N, T) or None)."""
    images = np.asarray(images)
    n, steps = images.shape[:2]
    flat = frame_log_likelihoods(images.reshape(n * steps, *images.shape[2:]),
                                 None if levels is None else np.asarray(levels).reshape(-1))
    return flat.reshape(n, steps, -1)


__all__ = ["FLOOR", "LEVEL_GRID", "frame_log_likelihoods", "per_frame_bayes", "pixel_log_prob",
           "pixel_particle_filter", "sequence_log_likelihoods"]
