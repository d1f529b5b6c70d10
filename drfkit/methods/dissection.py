"""Why a filter does or does not filter: its internals frame by frame, their calibration per noise
level, and interventions on its gain that say whether the gain or the transition is at fault. Inference only.

A Kalman filter filters when three things hold; each is measured here on the observed block of the
state (the dims a frame observes, in the space the observation lives in: ``model.filter_internals``):

* r tracks the observation's real error:  E[err^2] / E[r] ~ 1 per noise level, err = w_t - x_t
* the prior variance tracks the prior's real error:  E[e^2] / E[P_prior] ~ 1, e = F z_{t-1} - x_t
* then the gain K = P_prior / (P_prior + r) falls on bad frames and the state coasts on the transition.

x_t is what the observed block should hold on frame t (``model.observed_truth``): the true (cos, sin)
where the state is in the output's units, else the encoder's observation of the same frame without noise.

The interventions force the filter's gain (``drfkit.models.filtering``: a flag of the step, not an input),
the same model and observations otherwise, nothing retrained:

(a1) the gain exactly 0 on a gap: z_t = F_t z_{t-1}, P_t = F P F^T + Q, no update. The gain is read back and
     one above ``GAIN_TOLERANCE`` is an error (``check_clamped``). A large r is no clamp: where F expands, P
     grows until P / (P + r) reads the frames again.
(a2) the open-loop error by horizon h = 1..``HORIZON`` in output space, and the angle error of the normalised
     output (bounded by pi), beside zero-order hold of the last decoded estimate (``hold``); the transition's
     horizon H (``open_loop_horizon``): the leading h where it beats hold and stays <= ``OPEN_LOOP_MAX``.
(a3) the gain clamped on the first k gap frames only, then the model's own gain: a gain failure (the error
     jumps when the own gain resumes on noise) apart from a stability failure (it grows while clamped).
(b)  an oracle GAIN per level bin, K* = e^2 / (e^2 + err^2), from output-space errors on the scored frames
     (e: the prior F z_{t-1} decoded with the previous belief's variance; err: the observation decoded alone),
     forced on every frame (``oracle_gain_table``, ``oracle_gain``): what a gain that knew each level's errors
     would give with the model's own transition and observations.

An intervened filter is decoded with the variance input its decoder saw without the intervention (held at the
last frame before a gap, ``held_variance``; as it ran elsewhere): a decoder that reads P (the paper's) never saw
the variances of a 15-frame coast, and its mean would report that rather than the state's.

The verdict per horizon, written before the measurement (``horizon_verdicts``): 'gain' where the clamped error
is below the model's as it runs (ignoring the frames would be better: the gain reads what it should not);
'transition' where the clamped error beats neither hold nor the model as it runs; else 'filtering'.

Shapes: N sequences, T frames, k observed dims, n state dims (w and r are (N, T, n)).
"""
from __future__ import annotations

import copy
import math

import numpy as np
import torch

from drfkit.models.frame_codes import distinct_frames_once

LEVEL_BIN = 0.05        # width of the noise-level bins of the calibration table and of the oracle gain
GAIN_TOLERANCE = 1e-6   # (a1) a clamped frame whose gain reads back above this is an error, not a measurement
HORIZON = 15            # (a2) open-loop horizons h = 1..HORIZON (the blackout's length)
OPEN_LOOP_MAX = 0.10    # (a2) the transition predicts at horizon h: output MAE <= this (chance is about 0.62)


def observations(model, images: torch.Tensor, batch_size: int = 200) -> tuple[torch.Tensor, torch.Tensor]:
    """w, r (N, T, n) of ``model.observe`` on images (N, T, ...), in eval mode, without gradients, each distinct
    frame encoded once (``distinct_frames_once``)."""
    was_training = model.training
    model.eval()
    try:
        with torch.no_grad(), distinct_frames_once(model):
            parts = [model.observe(images[i:i + batch_size]) for i in range(0, images.shape[0], batch_size)]
        return torch.cat([w for w, _ in parts]), torch.cat([r for _, r in parts])
    finally:
        model.train(was_training)


def observation_outputs(model, images: torch.Tensor, batch_size: int = 200) -> np.ndarray:
    """The output mean (N, T, out) decoded from each frame's observation alone (``model.observation_output``),
    dropout off: what the frame says without the filter (the oracle gain's err)."""
    was_training = model.training
    model.eval()
    try:
        with torch.no_grad():
            return torch.cat([model.observation_output(images[i:i + batch_size])[0]
                              for i in range(0, images.shape[0], batch_size)]).double().numpy()
    finally:
        model.train(was_training)


def forced_gain(shape: tuple[int, int], start: int, stop: int, value: float = 0.0) -> torch.Tensor:
    """A forced gain (N, T) for ``filter_pass``: ``value`` on frames [start, stop), NaN (the filter's own) elsewhere."""
    if not 1 <= start <= stop <= shape[1]:
        raise ValueError(f"a forced span must lie in frames [1, {shape[1]}] (frame 0 is the filter's start), got "
                         f"[{start}, {stop})")
    out = torch.full(shape, float("nan"), dtype=torch.float64)
    out[:, start:stop] = value
    return out


def check_clamped(trace: dict[str, np.ndarray], gain: torch.Tensor, tolerance: float = GAIN_TOLERANCE) -> float:
    """The largest |gain| the filter reported on the frames where ``gain`` forced 0; raises ValueError above
    ``tolerance``: an intervention that does not do what it says is not a measurement."""
    at = (gain == 0).numpy()
    worst = float(trace["gain_abs_max"][at].max()) if at.any() else 0.0
    if not worst <= tolerance:
        raise ValueError(f"the clamped gain reads back as {worst:.3g} on the clamped frames (> {tolerance:g}): the "
                         "filter did not skip its update there; check the model's forced-gain step")
    return worst


def filter_pass(model, w: torch.Tensor, r: torch.Tensor, truth: torch.Tensor, targets: np.ndarray,
                batch_size: int = 200, q_scale: float = 1.0, log_var: np.ndarray | None = None,
                float64: bool = False, gain: torch.Tensor | None = None) -> dict[str, np.ndarray]:
    """The filter on observations w, r (N, T, n), its q times ``q_scale`` and its gain forced where ``gain``
    (N, T) is not NaN (``forced_gain``), against ``truth`` (N, T, k) (``model.observed_truth``); ``log_var``
    (N, T, v): the output decoded with these belief log variances in place of the filter's own where not NaN
    (``model.with_belief_variance``; an intervened filter decoded with the variance input its decoder knows).
    ``float64``: the pass on a float64 copy of the model (the model itself is untouched): a transition that
    diverges while the gain is clamped grows P past float32's range within 15 frames, and the measurement is how
    far it diverges, not where float32 gives out.

    Returns per frame, on the observed block, as sums over its k dims (so ratios of means are ratios
    of traces): 'r' (N, T); 'obs_err2' (N, T) = ||w - x||^2 and 'obs_err2_dims' (N, T, k);
    'p_prior', 'q', 'prior_err2' (N, T-1) = trace of the prior's variance, of q, and ||F z - x||^2;
    'gain' (N, T) mean diag of the gain over the block and 'gain_abs_max' (N, T) its largest |entry|; 'log_var'
    (N, T, v) the belief's log variances the output read; 'mean' (N, T, out) the dropout-off output and 'abs_err'
    (N, T) its mean absolute error against ``targets`` (N, T, out); 'prior_mean' (N, T-1, out) the one-step prior
    decoded with the previous belief's log variances (what the filter expects of frame t before seeing it)."""
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
                forced = None if gain is None else gain[sl].to(w.dtype)
                out = model.filter_internals(w[sl], r[sl], q_scale=q_scale, gain=forced)
                x = truth[sl].to(w.dtype)
                err_dims = (w[sl, :, :k] - x).square()
                belief_var = model.belief_variance(out["h"])
                read_var = belief_var
                if log_var is not None:  # NaN entries: the filter's own variance there
                    given = torch.as_tensor(log_var[sl], dtype=out["h"].dtype)
                    read_var = torch.where(torch.isnan(given), belief_var, given)
                values = {"r": r[sl, :, :k].sum(-1), "obs_err2": err_dims.sum(-1), "obs_err2_dims": err_dims,
                          "p_prior": out["p_prior"].sum(-1), "q": out["q"].sum(-1),
                          "prior_err2": (out["prior"] - x[:, 1:]).square().sum(-1),
                          "gain": out["gain"].mean(-1), "gain_abs_max": out["gain"].abs().amax(-1),
                          "log_var": belief_var,
                          "mean": model.head(model.with_belief_variance(out["h"], read_var))[0],
                          "prior_mean": model.head(model.with_belief_variance(out["h_prior"], read_var[:, :-1]))[0]}
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




def held_variance(log_var: np.ndarray, start: int, stop: int, elsewhere: float | None = None) -> np.ndarray:
    """log_var (N, T, v) with frames [start, stop) holding frame start - 1's values: what the decoder
    reads through a clamped gap; ``elsewhere`` = NaN: the other frames left to the filter's own (``filter_pass``)."""
    out = np.array(log_var, copy=True)
    out[:, start:stop] = log_var[:, start - 1:start]
    if elsewhere is not None:
        out[:, :start], out[:, stop:] = elsewhere, elsewhere
    return out


# ------------------------------------------------------------------ (a2) the open loop, by horizon
def angle_error(mean: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """|wrapped angle of the output - the true angle| (N, T) in [0, pi]: the output (N, T, 2) read as
    (cos, sin) and normalised, so a state that grows without bound still has a bounded error."""
    diff = np.arctan2(mean[..., 1], mean[..., 0]) - np.arctan2(targets[..., 1], targets[..., 0])
    return np.abs(np.angle(np.exp(1j * diff)))


def hold(mean: np.ndarray, start: int, stop: int) -> np.ndarray:
    """Zero-order hold (N, T, out): frames [start, stop) carry frame start - 1's estimate, the others their own."""
    out = np.array(mean, dtype=np.float64, copy=True)
    out[:, start:stop] = mean[:, start - 1:start]
    return out


def per_horizon(err: np.ndarray, start: int, horizon: int = HORIZON) -> np.ndarray:
    """The mean over sequences of a per-frame error (N, T) at horizons h = 1..``horizon`` after a gap starting at
    ``start`` (frame start + h - 1): (horizon,)."""
    if start + horizon > err.shape[1]:
        raise ValueError(f"horizons 1..{horizon} from frame {start} need {start + horizon} frames, have {err.shape[1]}")
    return err[:, start:start + horizon].mean(0)


def open_loop_horizon(clamped: np.ndarray, held: np.ndarray, max_err: float = OPEN_LOOP_MAX) -> int:
    """H: how many leading horizons the open-loop error ``clamped`` (H,) is below hold's ``held`` (H,) and <=
    ``max_err`` (0 when it fails at h = 1; len(clamped) when it never fails)."""
    ok = (np.asarray(clamped) < np.asarray(held)) & (np.asarray(clamped) <= max_err)
    return int(ok.size if ok.all() else np.argmin(ok))


def verdict_runs(verdicts: list[str]) -> str:
    """The per-horizon verdicts as runs: ['gain', 'gain', 'transition'] -> 'gain h1-2, transition h3'."""
    runs, start = [], 0
    for i in range(1, len(verdicts) + 1):
        if i == len(verdicts) or verdicts[i] != verdicts[start]:
            span = f"h{start + 1}" if i - start == 1 else f"h{start + 1}-{i}"
            runs.append(f"{verdicts[start]} {span}")
            start = i
    return ", ".join(runs)


def horizon_verdicts(clamped: np.ndarray, as_run: np.ndarray, held: np.ndarray) -> list[str]:
    """The rule per horizon, written before the measurement: 'gain' where the clamped error is below the model's
    as it runs; 'transition' where it beats neither hold nor the model as it runs; else 'filtering' (the model as
    it runs is at least as good as ignoring the frames, and the transition beats hold)."""
    out = []
    for c, a, h in zip(np.asarray(clamped), np.asarray(as_run), np.asarray(held)):
        out.append("gain" if c < a else "transition" if c >= h else "filtering")
    return out


# ------------------------------------------------------------------ (b) the oracle gain
def oracle_gain_table(prior_err2: np.ndarray, obs_err2: np.ndarray, noise: np.ndarray,
                      width: float = LEVEL_BIN) -> list[dict]:
    """K* = e^2 / (e^2 + err^2) per level bin (frames t >= 1), from output-space squared errors (N, T-1) of the
    one-step prior (e) and of the observation decoded alone (err) on the frames' levels ``noise`` (N, T): the gain
    that weighs the two by their measured errors (a scalar Kalman gain). Rows: level_lo, level_hi, frames,
    prior_err2, obs_err2, gain."""
    bins = level_bins(noise, width)[:, 1:]
    rows = []
    for b in np.unique(bins):
        at = bins == b
        pure = b == np.iinfo(np.int32).max
        e2, err2 = float(prior_err2[at].mean()), float(obs_err2[at].mean())
        rows.append({"level_lo": 1.0 if pure else b * width, "level_hi": 1.0 if pure else (b + 1) * width,
                     "frames": int(at.sum()), "prior_err2": e2, "obs_err2": err2, "gain": e2 / (e2 + err2)})
    return rows


def oracle_gain(noise: np.ndarray, table: list[dict], width: float = LEVEL_BIN) -> torch.Tensor:
    """The forced gain (N, T) of ``oracle_gain_table``'s rows on frames of levels ``noise`` (N, T): each frame its
    bin's K*, NaN at t = 0 (the start) and in a bin the table has no row for."""
    bins = level_bins(noise, width)
    out = np.full(bins.shape, np.nan)
    for row in table:
        b = np.iinfo(np.int32).max if row["level_lo"] >= 1.0 else int(round(row["level_lo"] / width))
        out[bins == b] = row["gain"]
    out[:, 0] = np.nan
    return torch.from_numpy(out)


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




__all__ = ["GAIN_TOLERANCE", "HORIZON", "LEVEL_BIN", "OPEN_LOOP_MAX", "angle_error", "calibration_table", "check_clamped",
           "filter_pass", "forced_gain", "held_variance", "hold", "horizon_verdicts", "in_distribution_screen",
           "verdict_runs",
           "level_bins", "observation_outputs", "observations", "open_loop_horizon", "oracle_gain", "oracle_gain_table",
           "per_horizon"]
