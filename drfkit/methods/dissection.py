"""Why a filter does or does not filter: its internals frame by frame, their calibration per noise
level, and two interventions that say whether the gain or the transition is at fault. Inference only.

A Kalman filter filters when three things hold; each is measured here on the observed block of the
state (the dims a frame observes, in the space the observation lives in: ``model.filter_internals``):

* r tracks the observation's real error:  E[err^2] / E[r] ~ 1 per noise level, err = w_t - x_t
* the prior variance tracks the prior's real error:  E[e^2] / E[P_prior] ~ 1, e = F z_{t-1} - x_t
* then the gain K = P_prior / (P_prior + r) falls on bad frames and the state coasts on the transition.

x_t is what the observed block should hold on frame t (``model.observed_truth``): the true (cos, sin)
where the state is in the output's units, else the encoder's observation of the same frame without noise.

The interventions replace r and rerun the same filter, nothing retrained:

(a) clamped gain: r = ``R_CLAMP`` on the blackout frames (gain ~ 0): can the learned transition coast?
(b) a competent r at a level no training frame had: r_t = a_i exp(b_i level_t) per observed dim, fit on
    validation frames of the training levels (``fit_log_linear_r``), and r_t = each level bin's own
    error variance on the scored frames (``r_from_levels``, an oracle no model has). Both are put on the
    model's own scale of r (divided per dim by E[err^2] / E[r] on validation, ``r_scale``): a latent
    filter's r need not be its error's variance, and its decoder reads P on the scale it learned.
(c) (b)'s oracle r with q scaled so that the prior's variance matches its error on validation
    (``calibrate_q_scale``): F's prediction alone, with both variances competent.

An intervened filter is decoded with the variance input its decoder saw without the intervention (in (a)
held at the last frame before the gap): a decoder that reads P (the paper's) never saw the variances of a
15-frame coast or of an r on another scale, and its mean would report that rather than the state's.

Shapes: N sequences, T frames, k observed dims, n state dims (w and r are (N, T, n)).
"""
from __future__ import annotations

import copy
import math

import numpy as np
import torch

R_CLAMP = 1e6          # an observation variance that makes the gain ~ P / 1e6: the frame is ignored
LEVEL_BIN = 0.05       # width of the noise-level bins of the calibration table and of the r fits
COAST_MAX_MAE = 0.10   # (a) the transition coasts: blackout MAE with the gain clamped <= this
COMPETENT_RATIO = 0.5  # (b) a competent gain helps: MAE at the OOD level <= this x no_dynamics'
Q_SCALES = (30.0, 10.0, 3.0, 1.0, 0.3, 0.1, 0.03, 0.01, 0.003, 0.001)  # (c) the q scales tried when calibrating the prior's variance


def observations(model, images: torch.Tensor, batch_size: int = 200) -> tuple[torch.Tensor, torch.Tensor]:
    """w, r (N, T, n) of ``model.observe`` on images (N, T, ...), in eval mode, without gradients."""
    was_training = model.training
    model.eval()
    try:
        with torch.no_grad():
            parts = [model.observe(images[i:i + batch_size]) for i in range(0, images.shape[0], batch_size)]
        return torch.cat([w for w, _ in parts]), torch.cat([r for _, r in parts])
    finally:
        model.train(was_training)


def override_r(r: torch.Tensor, r_new: np.ndarray | torch.Tensor, k: int) -> torch.Tensor:
    """r (N, T, n) with its observed block [..., :k] replaced by ``r_new`` (N, T, k) where that is not NaN."""
    r_new = torch.as_tensor(np.asarray(r_new), dtype=r.dtype)
    if r_new.shape != (*r.shape[:2], k):
        raise ValueError(f"r_new must be (N, T, k) = {(*r.shape[:2], k)}, got {tuple(r_new.shape)}")
    out = r.clone()
    out[..., :k] = torch.where(torch.isnan(r_new), r[..., :k], r_new)
    return out


def filter_pass(model, w: torch.Tensor, r: torch.Tensor, truth: torch.Tensor, targets: np.ndarray,
                batch_size: int = 200, q_scale: float = 1.0, log_var: np.ndarray | None = None,
                float64: bool = False) -> dict[str, np.ndarray]:
    """The filter on observations w, r (N, T, n), its q times ``q_scale``, against ``truth`` (N, T, k)
    (``model.observed_truth``); ``log_var`` (N, T, v): the output decoded with these belief log variances
    in place of the filter's own (``model.with_belief_variance``; an intervened filter decoded with the
    variance input its decoder knows). ``float64``: the pass on a float64 copy of the model (the model
    itself is untouched): a transition that diverges while the gain is clamped grows P past what float32
    keeps positive definite next to r = R_CLAMP, and the measurement is how far it diverges, not where
    float32 gives out.

    Returns per frame, on the observed block, as sums over its k dims (so ratios of means are ratios
    of traces): 'r' (N, T); 'obs_err2' (N, T) = ||w - x||^2 and 'obs_err2_dims' (N, T, k);
    'p_prior', 'q', 'prior_err2' (N, T-1) = trace of the prior's variance, of q, and ||F z - x||^2;
    'gain' (N, T) mean diag of the gain over the block; 'log_var' (N, T, v) the belief's log variances the
    output read; 'mean' (N, T, out) the dropout-off output and 'abs_err' (N, T) its mean absolute error
    against ``targets`` (N, T, out)."""
    k = model.observed_dims
    if truth.shape != (*w.shape[:2], k):
        raise ValueError(f"truth must be (N, T, k) = {(*w.shape[:2], k)}, got {tuple(truth.shape)}")
    if float64:
        model = copy.deepcopy(model).double()
        w, r, truth = w.double(), r.double(), truth.double()
    was_training = model.training
    model.eval()
    parts: dict[str, list[np.ndarray]] = {}
    try:
        with torch.no_grad():
            for i in range(0, w.shape[0], batch_size):
                sl = slice(i, i + batch_size)
                out = model.filter_internals(w[sl], r[sl], q_scale=q_scale)
                x = truth[sl].to(w.dtype)
                err_dims = (w[sl, :, :k] - x).square()
                values = {"r": r[sl, :, :k].sum(-1), "obs_err2": err_dims.sum(-1), "obs_err2_dims": err_dims,
                          "p_prior": out["p_prior"].sum(-1), "q": out["q"].sum(-1),
                          "prior_err2": (out["prior"] - x[:, 1:]).square().sum(-1),
                          "gain": out["gain"].mean(-1), "log_var": model.belief_variance(out["h"]),
                          "mean": model.head(out["h"] if log_var is None else model.with_belief_variance(
                              out["h"], torch.as_tensor(log_var[sl], dtype=out["h"].dtype)))[0]}
                for name, value in values.items():
                    parts.setdefault(name, []).append(value.double().numpy())
    finally:
        model.train(was_training)
    trace = {name: np.concatenate(v) for name, v in parts.items()}
    trace["abs_err"] = np.abs(trace["mean"] - np.asarray(targets, dtype=np.float64)).mean(-1)
    return trace


def level_bins(noise: np.ndarray, width: float = LEVEL_BIN) -> np.ndarray:
    """The bin index of each frame's noise level (N, T): [0, w), [w, 2w), ...; level 1 (pure noise) is
    a bin of its own, so a blackout's frames are never pooled with a graded level."""
    noise = np.asarray(noise, dtype=np.float64)
    return np.where(noise >= 1.0, np.iinfo(np.int32).max, np.floor(noise / width + 1e-9)).astype(np.int64)


def calibration_table(trace: dict[str, np.ndarray], noise: np.ndarray, width: float = LEVEL_BIN) -> list[dict]:
    """One row per noise-level bin (frames t >= 1, where a prior exists): level_lo, level_hi, frames,
    mean r, p_prior, q, gain, obs_err2, prior_err2 (per observed dim), 'err2_over_r' = E[||w - x||^2] /
    E[r] and 'e2_over_p' = E[||F z - x||^2] / E[P_prior] (~1 where each variance is calibrated; a
    ratio << 1 is a variance far larger than its error), and the MAE of the output."""
    bins = level_bins(noise, width)[:, 1:]
    rows = []
    for b in np.unique(bins):
        at = bins == b
        pure = b == np.iinfo(np.int32).max
        mean = {name: float(trace[name][:, 1:][at].mean()) for name in ("r", "obs_err2", "gain", "abs_err")}
        mean |= {name: float(trace[name][at].mean()) for name in ("p_prior", "q", "prior_err2")}
        rows.append({"level_lo": 1.0 if pure else b * width, "level_hi": 1.0 if pure else (b + 1) * width,
                     "frames": int(at.sum()), "r": mean["r"], "p_prior": mean["p_prior"], "q": mean["q"],
                     "gain": mean["gain"], "obs_err2": mean["obs_err2"], "prior_err2": mean["prior_err2"],
                     "err2_over_r": mean["obs_err2"] / mean["r"], "e2_over_p": mean["prior_err2"] / mean["p_prior"],
                     "mae": mean["abs_err"]})
    return rows


def fit_log_linear_r(obs_err2_dims: np.ndarray, noise: np.ndarray, max_level: float = 0.5,
                     width: float = LEVEL_BIN) -> tuple[np.ndarray, np.ndarray]:
    """log r_i(level) = log a_i + b_i level per observed dim i: least squares of each level bin's log mean
    squared error (obs_err2_dims (N, T, k)) on the bin's mean level, over bins of levels <= ``max_level``
    (the training levels: fit on validation frames). Returns (log_a, b), each (k,). A link that is
    log-linear in the level extrapolates by construction to levels no training frame had."""
    noise = np.asarray(noise, dtype=np.float64)
    bins = level_bins(noise, width)
    keep = noise <= max_level
    xs, ys = [], []
    for b in np.unique(bins[keep]):
        at = keep & (bins == b)
        xs.append(noise[at].mean())
        ys.append(np.log(obs_err2_dims[at].mean(0)))                  # (k,)
    if len(xs) < 2:
        raise ValueError(f"fitting r against the level needs frames in at least two bins of width {width} at "
                         f"levels <= {max_level}; got {len(xs)}")
    A = np.stack([np.ones(len(xs)), np.asarray(xs)], 1)                   # (bins, 2)
    coef, *_ = np.linalg.lstsq(A, np.stack(ys), rcond=None)               # (2, k)
    return coef[0], coef[1]


def r_scale(trace: dict[str, np.ndarray], r: torch.Tensor) -> np.ndarray:
    """E[err_i^2] / E[r_i] per observed dim i (k,) of a :func:`filter_pass` on r (N, T, n): how many times
    its error's variance r is (1 where r is calibrated); a competent r divided by it is on the model's scale."""
    k = trace["obs_err2_dims"].shape[-1]
    return trace["obs_err2_dims"].reshape(-1, k).mean(0) / r[..., :k].double().reshape(-1, k).mean(0).numpy()


def r_from_fit(noise: np.ndarray, log_a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """r (N, T, k) = exp(log_a + b level) from a :func:`fit_log_linear_r` fit and the frames' levels."""
    return np.exp(np.asarray(log_a) + np.asarray(b) * np.asarray(noise, dtype=np.float64)[..., None])


def r_from_levels(obs_err2_dims: np.ndarray, noise: np.ndarray, width: float = LEVEL_BIN) -> np.ndarray:
    """r (N, T, k): each frame's level bin's mean squared observation error per dim, on the frames
    themselves (an oracle: it reads the errors it is meant to predict)."""
    bins = level_bins(noise, width)
    out = np.empty(obs_err2_dims.shape)
    for b in np.unique(bins):
        at = bins == b
        out[at] = obs_err2_dims[at].mean(0)
    return out


def held_variance(log_var: np.ndarray, start: int, stop: int) -> np.ndarray:
    """log_var (N, T, v) with frames [start, stop) holding frame start - 1's values: what the decoder
    reads through a gap in intervention (a)."""
    out = np.array(log_var, copy=True)
    out[:, start:stop] = log_var[:, start - 1:start]
    return out


def clamp_frames(shape: tuple[int, int, int], start: int, stop: int) -> np.ndarray:
    """r_new (N, T, k) for ``override_r``: ``R_CLAMP`` on frames [start, stop), NaN (keep r) elsewhere."""
    out = np.full(shape, np.nan)
    out[:, start:stop] = R_CLAMP
    return out


def calibrate_q_scale(model, w: torch.Tensor, r: torch.Tensor, truth: torch.Tensor, targets: np.ndarray,
                      scales=Q_SCALES) -> tuple[float, float]:
    """The q scale of ``scales`` whose prior variance best matches the prior's error on these frames
    (smallest |log E[||F z - x||^2] / E[P_prior]|; read them from validation). Returns (scale, ratio)."""
    best = (math.inf, 1.0, math.nan)
    for scale in scales:
        trace = filter_pass(model, w, r, truth, targets, q_scale=scale)
        ratio = float(trace["prior_err2"].mean() / trace["p_prior"].mean())
        if abs(math.log(ratio)) < best[0]:
            best = (abs(math.log(ratio)), float(scale), ratio)
    return best[1], best[2]


def in_distribution_screen(trace: dict[str, np.ndarray], noise: np.ndarray, max_level: float,
                           width: float = LEVEL_BIN) -> dict[str, float]:
    """What the calibrated-gain screen reads of a :func:`filter_pass` on frames of levels <= ``max_level``
    only (validation at the training noise; frames t >= 1): 'r_level_spearman' rank correlation of log r
    with the level over frames, 'r_log_slope' and 'gain_slope' least-squares slopes of each level bin's mean
    log r and mean gain on its mean level, and 'mae' of the dropout-off output."""
    from drfkit.core.metrics import rank_correlation

    noise = np.asarray(noise, dtype=np.float64)[:, 1:]
    keep = noise <= max_level
    r, gain = trace["r"][:, 1:], trace["gain"][:, 1:]
    bins = level_bins(noise, width)
    xs, log_r, gains = [], [], []
    for b in np.unique(bins[keep]):
        at = keep & (bins == b)
        xs.append(noise[at].mean()), log_r.append(np.log(r[at]).mean()), gains.append(gain[at].mean())
    slope = (lambda y: float(np.polyfit(xs, y, 1)[0])) if len(xs) >= 2 else (lambda y: math.nan)
    return {"r_level_spearman": rank_correlation(np.log(r[keep]), noise[keep]), "r_log_slope": slope(log_r),
            "gain_slope": slope(gains), "mae": float(trace["abs_err"][:, 1:][keep].mean())}


def failure_verdict(mae_blackout_clamped: float, mae_ood_competent: float, mae_ood_no_dynamics: float,
                    mae_ood_competent_q: float = math.nan, coast_max: float = COAST_MAX_MAE,
                    ratio_max: float = COMPETENT_RATIO) -> str:
    """The rule written before the measurement: with the gain clamped on the blackout the transition
    coasts (MAE <= ``coast_max``) AND with a competent r the MAE at the OOD level is <= ``ratio_max`` x
    no_dynamics' -- then the transition suffices and what fails is the gain's calibration: 'gain'.
    Otherwise, if it coasts and a competent r with q calibrated on validation (``mae_ood_competent_q``,
    intervention c) meets the same bound, F predicts and q misstates the prior's error: 'prior variance';
    else the transition's prediction fails too: 'transition'. NaN in (a), (b) or no_dynamics': 'not measured'."""
    values = (mae_blackout_clamped, mae_ood_competent, mae_ood_no_dynamics)
    if any(v is None or math.isnan(v) for v in values):
        return "not measured"
    coasts = mae_blackout_clamped <= coast_max
    bound = ratio_max * mae_ood_no_dynamics
    if coasts and mae_ood_competent <= bound:
        return "gain"
    if coasts and not math.isnan(mae_ood_competent_q) and mae_ood_competent_q <= bound:
        return "prior variance"
    return "transition"


__all__ = ["COAST_MAX_MAE", "COMPETENT_RATIO", "LEVEL_BIN", "Q_SCALES", "R_CLAMP", "calibrate_q_scale",
           "calibration_table", "clamp_frames", "held_variance",
           "failure_verdict", "filter_pass", "in_distribution_screen", "fit_log_linear_r", "level_bins", "observations", "override_r",
           "r_from_fit", "r_from_levels", "r_scale"]
