"""The limit on pixels: Bayes estimates that know the benchmark's exact observation model.

A noisy frame is ``rint((1 - l) c + l u)`` per pixel, u ~ U(0, 255), c the clean pixel, l the frame's noise
level (``drfkit.data.noise.blend_uniform_noise``). So, for l > 0,

    P(pixel = k | c, l) = |[k - 1/2, k + 1/2) ∩ [(1 - l) c, (1 - l) c + 255 l]| / (255 l)

and P(k | c, 0) = [k = c]. The benchmark's code truncates the blend instead (``quantise="truncate"``, the noise
kind ``rkn_uniform_truncated``): then the interval is [k, k + 1). Pixels are independent given the clean frame, and a clean frame is one of the
bank's images (``drfkit.data.rod_bank``: every image the renderer can draw, each standing for its arc of
angles). Three estimators use it, none learned:

* ``frame_log_likelihoods`` -- log P(frame | image j) (F, J), with the noise level known (the true one) or
  marginalised over a grid of levels (uniform prior, ``LEVEL_GRID``).
* ``per_frame_bayes`` -- the posterior mean of (cos theta, sin theta) of one frame, no dynamics.
* ``pixel_particle_filter`` -- a particle filter with the TRUE physics (``drfkit.methods.references``'s
  propagation, velocity noise N(0, 0.1^2) per frame, start uniform at rest) weighting particles by the
  exact likelihood of the image their angle draws: the best that is physically possible on these
  pixels, up to Monte Carlo error (``particle_convergence`` shows it).

Shapes: N sequences, T frames, F = N*T frames, J bank images, M particles, K = the most inked pixels of
an image. A pixel outside a level's range gets probability ``FLOOR`` / (255 l) rather than 0, so one
rounding accident at a range's edge cannot veto the true image.
"""
from __future__ import annotations

import math
import warnings
from functools import lru_cache

import numpy as np
import torch

from drfkit.data import pendulum as pend
from drfkit.data.rod_bank import rod_bank
from drfkit.methods.references import normalised_weights, pendulum_propagate, resample_degenerate

FLOOR = 1e-4
# the marginal over an unknown level: l = 0 and 128 levels up to 1, equally likely a priori
LEVEL_GRID = (0.0, *np.linspace(1.0 / 128, 1.0, 128))
# Of the grid, each frame sums over the levels its never-inked pixels admit: a never-inked pixel holds at
# most rint(255 l) (truncated: floor(255 l)), so levels below (max - offset) / 255 are out (a FLOOR penalty, the same for every image),
# and the max of the ~85 such pixels lies above LEVEL_SPAN * 255 l but with probability 0.85^85 ~ 1e-6, so
# levels above that bound / LEVEL_SPAN (+ a grid step) lose a factor (l_kept / l)^576 and are negligible
# (tests/test_pixel_bayes.py compares with the whole grid).
LEVEL_SPAN = 0.85
FRAME_CHUNK = 256  # frames per gather with the level known: (chunk, U) codes ~ 20 MB
LEVEL_CHUNK = 32  # frames per gather over levels: up to ~25 levels each, (chunk * levels, U) codes ~ 70 MB


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


# how far below k the blend values that store as k start: rint keeps [k - 1/2, k + 1/2), truncation [k, k + 1)
QUANTISE_OFFSET = {"round": 0.5, "truncate": 0.0}


def _offset(quantise: str) -> float:
    if quantise not in QUANTISE_OFFSET:
        raise ValueError(f"quantise must be one of {sorted(QUANTISE_OFFSET)} (how the blend was stored), got {quantise!r}")
    return QUANTISE_OFFSET[quantise]


def pixel_log_prob(k: torch.Tensor, c: torch.Tensor, level: torch.Tensor, quantise: str = "round") -> torch.Tensor:
    """log P(pixel = k | clean c, level l), broadcast over any shapes (float64 math, module docstring); ``quantise``:
    how the blend was stored ('round', the book's generator; 'truncate', the benchmark's code)."""
    offset = _offset(quantise)
    k, c, level = k.double(), c.double(), level.double()
    lo = (1.0 - level) * c
    width = 255.0 * level
    overlap = (torch.minimum(k + 1.0 - offset, lo + width) - torch.maximum(k - offset, lo)).clamp(0.0, 1.0)
    noisy = torch.log(overlap.clamp_min(FLOOR)) - torch.log(width.clamp_min(1e-300))
    exact = torch.where(k == c, 0.0, math.log(FLOOR))
    return torch.where(level > 0, noisy, exact)


def frame_log_likelihoods(images: np.ndarray, levels: np.ndarray | None = None, quantise: str = "round"
                          ) -> np.ndarray:
    """log P(frame | bank image j) (F, J) of frames uint8 (F, 24, 24) (``quantise``: ``pixel_log_prob``'s).

    ``levels`` (F,): each frame's true noise level; None: marginalised over ``LEVEL_GRID`` (uniform).
    Per frame, the sum over the 576 pixels is split into the sum as if every pixel were background
    (c = 0, one value per frame) plus, over each image's inked pixels, the change their value makes. The
    bank's J images hold 21,553 inked pixels but only U ~ 10,000 distinct (pixel, value) pairs: each pair's
    change is computed once per frame (f, U) and an incidence matrix (J, U) sums them per image."""
    offset = _offset(quantise)
    images = np.asarray(images)
    if images.dtype != np.uint8 or images.ndim != 3 or images.shape[1:] != (pend.IMAGE_SIZE, pend.IMAGE_SIZE):
        raise ValueError(f"images must be uint8 (F, 24, 24), got {images.dtype} {images.shape}")
    x_all = torch.from_numpy(images.reshape(images.shape[0], -1).astype(np.int64))           # (F, 576)
    upix, uval, incidence = _bank_pairs()
    if levels is not None:
        levels = np.asarray(levels, np.float64).reshape(-1)
        if levels.shape[0] != images.shape[0] or not np.all((levels >= 0) & (levels <= 1)):
            raise ValueError(f"levels must hold one level in [0, 1] per frame ({images.shape[0]}), got {levels.shape}")
    out = np.empty((images.shape[0], incidence.shape[0]))
    if levels is not None:
        inc = incidence.double()
        for start in range(0, images.shape[0], FRAME_CHUNK):
            x = x_all[start:start + FRAME_CHUNK]
            lv = torch.from_numpy(levels[start:start + FRAME_CHUNK])[:, None]
            background = pixel_log_prob(x, torch.zeros(()), lv, quantise).sum(1)            # (f,)
            xu = x[:, upix]                                                                 # (f, U)
            change = pixel_log_prob(xu, uval, lv, quantise) - pixel_log_prob(xu, torch.zeros(()), lv, quantise)
            out[start:start + x.shape[0]] = (background[:, None] + (inc @ change.T).T).numpy()
        return out
    tables, changes = (t.view(-1) for t in _level_tables(quantise))                         # G * 65536 each
    grid = torch.tensor(LEVEL_GRID, dtype=torch.float64)
    blank_pixels = torch.from_numpy(np.flatnonzero(~(rod_bank().images > 0).any(0).reshape(-1)))
    for start in range(0, images.shape[0], LEVEL_CHUNK):
        x = x_all[start:start + LEVEL_CHUNK]                                                # (f, 576)
        low = (x[:, blank_pixels].amax(1).double() - offset).clamp_min(0.0) / 255.0
        first = torch.searchsorted(grid, low - 1e-12).clamp_max(len(grid) - 1)             # (f,)
        last = torch.searchsorted(grid, (low / LEVEL_SPAN + 1.0 / 128).clamp_max(1.0)).clamp_max(len(grid) - 1)
        # every (frame, level) pair the pruning keeps, and no other: (q,) each
        counts = last - first + 1
        frame = torch.repeat_interleave(torch.arange(x.shape[0]), counts)
        level = first[frame] + torch.arange(frame.numel()) - torch.repeat_interleave(counts.cumsum(0) - counts, counts)
        codes = level[:, None] * 65536 + x[frame] * 256                                    # (q, 576): row l, k * 256
        background = torch.take(tables, codes).sum(1)                                      # (q,)
        change = torch.take(changes, codes[:, upix] + uval)                                # (q, U)
        terms = background[:, None] + (incidence @ change.T).T                              # (q, J)
        peak = torch.full((x.shape[0], terms.shape[1]), -math.inf).scatter_reduce(
            0, frame[:, None].expand_as(terms), terms, "amax")                              # (f, J)
        summed = torch.zeros_like(peak).index_add_(0, frame, (terms - peak[frame]).exp())
        out[start:start + x.shape[0]] = (peak.double() + summed.double().log() - math.log(len(grid))).numpy()
    return out


@lru_cache(maxsize=1)
def _bank_pairs() -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The bank's inked pixels as distinct (pixel, value) pairs: pixels (U,), values (U,) int64, and the
    float32 incidence matrix (J, U) (sparse CSR) whose row j adds up image j's pairs."""
    pix, val = _sparse_bank()
    inked = val > 0
    pairs, which = torch.unique(pix[inked] * 256 + val[inked], return_inverse=True)
    rows = torch.arange(pix.shape[0])[:, None].expand_as(pix)[inked]
    incidence = torch.sparse_coo_tensor(torch.stack([rows, which]), torch.ones(rows.numel()),
                                        (pix.shape[0], pairs.numel()), check_invariants=True).coalesce()
    with warnings.catch_warnings():  # "sparse CSR support is in beta": a matrix product is all it does here
        warnings.simplefilter("ignore", UserWarning)
        incidence = incidence.to_sparse_csr()
    return pairs // 256, pairs % 256, incidence


@lru_cache(maxsize=len(QUANTISE_OFFSET))
def _level_tables(quantise: str = "round") -> tuple[torch.Tensor, torch.Tensor]:
    """log P(k | c, l) for every grid level (G, 65536), entry k * 256 + c, and the change an inked c makes
    to a background pixel's term, log P(k | c, l) - log P(k | 0, l), at the same entries."""
    codes = torch.arange(256)
    tables = torch.stack([pixel_log_prob(codes[:, None], codes[None, :], torch.tensor(float(g)), quantise)
                          for g in LEVEL_GRID])                                              # (G, k, c) float64
    # float32: sums of 576 terms stay within 1e-3 of float64
    return tables.flatten(1).float(), (tables - tables[:, :, :1]).flatten(1).float()


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


def sequence_log_likelihoods(images: np.ndarray, levels: np.ndarray | None = None, quantise: str = "round"
                             ) -> np.ndarray:
    """``frame_log_likelihoods`` of sequences uint8 (N, T, 24, 24) -> (N, T, J) (levels (N, T) or None)."""
    images = np.asarray(images)
    n, steps = images.shape[:2]
    flat = frame_log_likelihoods(images.reshape(n * steps, *images.shape[2:]),
                                 None if levels is None else np.asarray(levels).reshape(-1), quantise)
    return flat.reshape(n, steps, -1)


__all__ = ["FLOOR", "LEVEL_GRID", "QUANTISE_OFFSET", "frame_log_likelihoods", "per_frame_bayes", "pixel_log_prob",
           "pixel_particle_filter", "sequence_log_likelihoods"]
