"""Kalman-gain competency gating: MC dropout only on the frames the filter is unsure of.

The paper's discussion proposes the Kalman gain as a measure of competency: run the
expensive epistemic (MC dropout) pass only where competency is low. Here, per frame:

    mean gain   k_t = mean_i K_t[i, i]            (B, T)  from the filter's gains (B, T, n, n)
    score       s_t = k_t        if direction = +1  (high gain = low competency)
                s_t = 1 - k_t    if direction = -1  (low gain = low competency)
    selected    s_t > threshold                    -> MC dropout on that frame, else one
                                                      deterministic pass (epistemic = 0)

Why the gain can say "low competency": with H = I the update is K = P⁻ (P⁻ + R)⁻¹. Where
the encoder is unsure it emits a large R and the gain drops (the filter leans on its
prediction); where it is sure the gain approaches 1. Which end goes with large errors is a
property of the trained model, so ``choose_direction`` decides it from a rank correlation
between k_t and the absolute error of the deterministic prediction, on VALIDATION frames.

Nothing here looks at test data before the gate is fixed: ``fit_gate`` takes only the
validation set; ``choose_direction`` / ``choose_threshold`` take only validation arrays
(their arguments say so); the test set enters only ``drfkit.methods.gate_evaluation`` (``score_gate``,
``time_gate`` and ``evaluate_gate`` / ``sweep_gate``, which call both), which applies a fitted ``Gate``. The threshold is the validation-score quantile of the
smallest dropout fraction whose validation PICP is within ``tolerance`` of
always-dropout's validation PICP. It is an absolute score value, so on noisier frames
more of them cross it. The study (``drfkit.study.gating_study``) fits on the ``val`` split (held-out sequences) at
the test's noise level by default: labelled data from the shifted condition, which a deployed
system does not have, so an optimistic reference; at the training noise (what a deployed system
can tune on, ``val_noise``), intervals without dropout may already cover as well as with it, and
the rule then turns dropout off. Neither tuned gate decides claim C7, which is judged on the
whole threshold sweep (``drfkit.study.claims.efficiency.c7_gating``).

Gated inference is real, not simulated: features (encoder + filter) run once, the head
runs with S samples on the gathered selected frames and once, deterministically, on the
others; the results are scattered back. Times are measured, interleaved across settings,
on the same test batch in the same run. The metrics of every setting and threshold are
assembled per frame from one deterministic and one always-dropout pass (``assemble``): the
head is per frame, so that is gated inference's result on common random numbers, at the
cost of two passes instead of one per threshold. Only a model that declares ``competency_gain``
(``drfkit.models.sequence``: square gains on its state, the DRF) is gated; ``fit_gate`` refuses others.

Settings (the paper's table): ``no_dropout`` (aleatoric only), ``random`` (the same number
of frames as the Kalman-gain gate selects on test, drawn uniformly, seeded),
``kalman_gain``, ``always`` (MC dropout on every frame). The threshold sweep adds an *oracle*
(``oracle_selection``: the same number of frames, those of largest true error), the best any
competency score could select; it reads the targets, so it is compared, never run or timed.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd
import torch

from drfkit.core.metrics import prediction_metrics
from drfkit.core.metrics import rank_correlation
from drfkit.models.frame_codes import distinct_frames_once
from drfkit.models.parts import check_dropout_p, check_n_samples
from drfkit.methods.uncertainty import as_model_input, summarise_samples

SETTINGS = ("no_dropout", "random", "kalman_gain", "always")
NEVER, ALWAYS = math.inf, -math.inf  # thresholds that select no frame / every frame
# The paper's intuition (image noise -> large R -> small gain): used only if the validation
# rank correlation is undefined (constant gains or errors).
DEFAULT_DIRECTION = -1
RANDOM_SEED_OFFSET = 7919  # random gating draws from seed + this, apart from the dropout masks


# --------------------------------------------------------------------------- scores
def mean_gain(gains: torch.Tensor) -> torch.Tensor:
    """Kalman gains (B, T, n, n) -> mean of diag(K_t) per frame (B, T)."""
    if not isinstance(gains, torch.Tensor) or gains.ndim != 4 or gains.shape[-1] != gains.shape[-2]:
        shape = tuple(gains.shape) if isinstance(gains, torch.Tensor) else type(gains).__name__
        raise ValueError(f"gains must be a tensor (B, T, n, n) of Kalman gains, got {shape}; "
                         f"only models that declare competency_gain (the DRF, kind 'drf') are gated on them")
    return gains.diagonal(dim1=-2, dim2=-1).mean(dim=-1)


def competency_score(gains: torch.Tensor, direction: int) -> torch.Tensor:
    """Low-competency score (B, T) from gains (B, T, n, n): higher = less competent.

    direction +1: the mean gain itself; -1: one minus it (same ranks, reversed).
    """
    if direction not in (1, -1):
        raise ValueError(f"direction must be +1 (high gain = low competency) or -1 (low gain = low "
                         f"competency), got {direction!r}")
    k = mean_gain(gains)
    return k if direction == 1 else 1.0 - k


def choose_direction(val_mean_gain, val_abs_error) -> tuple[int, float]:
    """From VALIDATION frames only: +1 if a higher mean gain goes with larger errors, else -1.

    val_mean_gain, val_abs_error: (N,) over valid validation frames. Returns (direction, rho).
    """
    rho = rank_correlation(val_mean_gain, val_abs_error)
    if math.isnan(rho):
        return DEFAULT_DIRECTION, rho
    return (1 if rho > 0 else -1), rho


# --------------------------------------------------------------------------- thresholds
def threshold_for_fraction(val_scores, fraction: float) -> float:
    """The score above which ``fraction`` of the VALIDATION scores lie (0 -> never, 1 -> always)."""
    if not 0.0 <= fraction <= 1.0:
        raise ValueError(f"fraction must lie in [0, 1], got {fraction}")
    if fraction == 0.0:
        return NEVER
    if fraction == 1.0:
        return ALWAYS
    return float(np.quantile(np.asarray(val_scores, dtype=np.float64), 1.0 - fraction))


def apply_gating(scores: torch.Tensor, threshold: float, mask: torch.Tensor | None = None) -> torch.Tensor:
    """Frames to run MC dropout on: score > threshold (and a real frame). (B, T) bool."""
    selected = scores > threshold
    return selected if mask is None else selected & mask.to(selected.device)


def _combine(selected: np.ndarray, det: tuple[np.ndarray, np.ndarray], mc: tuple[np.ndarray, np.ndarray]):
    """Per frame: the MC-dropout (mean, total) where selected, the deterministic one elsewhere."""
    pick = selected[:, None]
    return np.where(pick, mc[0], det[0]), np.where(pick, mc[1], det[1])


def choose_threshold(val_scores, val_targets, val_deterministic, val_always, *, tolerance: float,
                     n_points: int, level: float = 0.95) -> tuple[float, pd.DataFrame]:
    """Pick the gate's threshold from VALIDATION arrays only.

    val_scores (N,) low-competency scores of the valid validation frames; val_targets (N, out);
    val_deterministic and val_always: (mean, total sigma) pairs, each (N, out), of the
    no-dropout and the always-dropout predictions of the same frames.
    Candidates: fractions 0, 1/(n_points-1), ..., 1 of the frames, as score quantiles. The
    choice is the smallest fraction whose gated PICP >= always's PICP - tolerance (the
    fraction 1 always qualifies). Returns (threshold, table of the candidates).
    """
    scores = np.asarray(val_scores, dtype=np.float64).reshape(-1)
    y = np.asarray(val_targets, dtype=np.float64)
    det = tuple(np.asarray(a, dtype=np.float64) for a in val_deterministic)
    mc = tuple(np.asarray(a, dtype=np.float64) for a in val_always)
    if y.ndim != 2 or y.shape[0] != scores.size or any(a.shape != y.shape for a in det + mc):
        raise ValueError(f"val_targets and each prediction array must be (N, out) with N = {scores.size} "
                         f"scores; got targets {y.shape}, predictions {[a.shape for a in det + mc]}")
    if not 0.0 <= tolerance <= 1.0:
        raise ValueError(f"tolerance is a PICP fraction in [0, 1], got {tolerance}")
    if isinstance(n_points, bool) or not isinstance(n_points, int) or n_points < 2:
        raise ValueError(f"n_points must be an int >= 2 (never ... always), got {n_points!r}")
    always_picp = prediction_metrics(mc[0], mc[1], y, level=level)["picp"]
    rows = []
    for fraction in np.linspace(0.0, 1.0, n_points):
        threshold = threshold_for_fraction(scores, float(fraction))
        selected = scores > threshold
        m = prediction_metrics(*_combine(selected, det, mc), y, level=level)
        rows.append({"target_fraction": float(fraction), "threshold": threshold,
                     "val_fraction": float(selected.mean()), "val_picp": m["picp"], "val_mpiw": m["mpiw"],
                     "val_nll": m["nll"], "val_picp_always": always_picp})
    table = pd.DataFrame(rows)
    ok = table["val_picp"] >= always_picp - tolerance
    table["chosen"] = False
    table.loc[ok.idxmax() if ok.any() else table.index[-1], "chosen"] = True
    return float(table.loc[table["chosen"], "threshold"].iloc[0]), table


# --------------------------------------------------------------------------- random gating
def random_selection(mask: torch.Tensor, n_selected: int, seed: int) -> torch.Tensor:
    """Exactly ``n_selected`` of the True frames of ``mask`` (B, T), uniformly, seeded. (B, T) bool."""
    if mask.dtype != torch.bool or mask.ndim != 2:
        raise ValueError(f"mask must be a (B, T) bool tensor of real frames, got {mask.dtype} {tuple(mask.shape)}")
    valid = mask.reshape(-1).nonzero().squeeze(1)
    if isinstance(n_selected, bool) or not isinstance(n_selected, int) or not 0 <= n_selected <= valid.numel():
        raise ValueError(f"n_selected must be an int in [0, {valid.numel()}] (the real frames), got {n_selected!r}")
    gen = torch.Generator().manual_seed(int(seed))
    pick = valid[torch.randperm(valid.numel(), generator=gen)[:n_selected].to(valid.device)]
    out = torch.zeros(mask.numel(), dtype=torch.bool, device=mask.device)
    out[pick] = True
    return out.view_as(mask)


def oracle_selection(abs_error: torch.Tensor, mask: torch.Tensor, n_selected: int) -> torch.Tensor:
    """The ``n_selected`` True frames of ``mask`` (B, T) with the largest true error ``abs_error`` (B, T)
    of the deterministic prediction (ties by position). A gate nobody can run -- it reads the targets --
    and the far end of the gating sweep's comparison: what a perfect competency score would select
    with as many frames as the Kalman-gain gate. (B, T) bool."""
    if mask.dtype != torch.bool or mask.ndim != 2 or abs_error.shape != mask.shape:
        raise ValueError(f"abs_error and mask must both be (B, T) (mask bool), got {tuple(abs_error.shape)} and "
                         f"{mask.dtype} {tuple(mask.shape)}")
    n_real = int(mask.sum())
    if isinstance(n_selected, bool) or not isinstance(n_selected, int) or not 0 <= n_selected <= n_real:
        raise ValueError(f"n_selected must be an int in [0, {n_real}] (the real frames), got {n_selected!r}")
    error = abs_error.reshape(-1).double().masked_fill(~mask.reshape(-1), -math.inf)
    out = torch.zeros(mask.numel(), dtype=torch.bool, device=mask.device)
    out[torch.topk(error, n_selected).indices] = True
    return out.view_as(mask)


def random_gating(mask: torch.Tensor, fraction: float, seed: int) -> torch.Tensor:
    """round(fraction * N) of the N real frames of ``mask`` (B, T), uniformly, seeded."""
    if not 0.0 <= fraction <= 1.0:
        raise ValueError(f"fraction must lie in [0, 1], got {fraction}")
    return random_selection(mask, int(round(fraction * int(mask.sum()))), seed)


# --------------------------------------------------------------------------- gated inference
@dataclass(frozen=True)
class GatedPrediction:
    """Tensors (B, T, out) on the model's device; ``selected`` (B, T) bool (frames given MC dropout)."""

    mean: torch.Tensor
    aleatoric: torch.Tensor
    epistemic: torch.Tensor
    total: torch.Tensor
    selected: torch.Tensor


def gated_head(model, h: torch.Tensor, selected: torch.Tensor, n_samples: int, dropout_p: float
               ) -> GatedPrediction:
    """The head on features h (B, T, D): S dropout samples on the ``selected`` (B, T) frames only,
    one deterministic pass on the others. Gather -> head -> scatter; frames are independent in
    the head, so a frame's result does not depend on which other frames were selected (only
    on the dropout masks it draws)."""
    check_n_samples(n_samples)
    if selected.dtype != torch.bool or tuple(selected.shape) != tuple(h.shape[:2]):
        raise ValueError(f"selected must be a bool tensor of shape {tuple(h.shape[:2])}, "
                         f"got {selected.dtype} {tuple(selected.shape)}")
    if n_samples == 0 and bool(selected.any()):
        raise ValueError("n_samples must be >= 1 when some frame is selected for MC dropout")
    out_shape = (*h.shape[:2], model.out_dim)
    mean, aleatoric = h.new_empty(out_shape), h.new_empty(out_shape)
    epistemic, total = h.new_zeros(out_shape), h.new_empty(out_shape)
    rest = ~selected
    if bool(rest.any()):
        # (1, M, D): the head sees a batch of one "sequence" of M frames
        m, s = model.head(h[rest].unsqueeze(0))
        mean[rest], aleatoric[rest], total[rest] = m[0], s[0], s[0]
    if bool(selected.any()):
        means, sigmas = model.head(h[selected].unsqueeze(0), n_samples=n_samples, dropout_p=dropout_p)
        m, a, e, t = summarise_samples(means, sigmas)
        mean[selected], aleatoric[selected], epistemic[selected], total[selected] = m[0], a[0], e[0], t[0]
    return GatedPrediction(mean, aleatoric, epistemic, total, selected)


def uncertainty_stage(model, h: torch.Tensor, gains: torch.Tensor | None, mask: torch.Tensor, setting: str, *,
                      n_samples: int, dropout_p: float, direction: int | None = None,
                      threshold: float | None = None, n_random: int | None = None,
                      random_seed: int = 0) -> GatedPrediction:
    """Everything of ``setting`` after the features h (B, T, D) (and gains (B, T, n, n)):

    no_dropout / always: the head with 0 / S samples on every frame.
    kalman_gain: score the gains (``direction``), select score > ``threshold`` among the real
        frames ``mask`` (B, T), gated head.
    random: draw ``n_random`` real frames with ``random_seed``, gated head.
    """
    if setting not in SETTINGS:
        raise ValueError(f"setting must be one of {SETTINGS}, got {setting!r}")
    if setting == "no_dropout":
        selected = torch.zeros(h.shape[:2], dtype=torch.bool, device=h.device)
        m, s = model.head(h)
        return GatedPrediction(m, s, torch.zeros_like(m), s, selected)
    if setting == "always":
        selected = torch.ones(h.shape[:2], dtype=torch.bool, device=h.device)
        m, a, e, t = summarise_samples(*model.head(h, n_samples=n_samples, dropout_p=dropout_p))
        return GatedPrediction(m, a, e, t, selected)
    selected = select_frames(setting, gains, mask, direction=direction, threshold=threshold, n_random=n_random,
                             random_seed=random_seed, kind=model.config.get("kind"))
    return gated_head(model, h, selected, n_samples, dropout_p)


def select_frames(setting: str, gains: torch.Tensor | None, mask: torch.Tensor, *, direction: int | None = None,
                  threshold: float | None = None, n_random: int | None = None, random_seed: int = 0,
                  kind: str | None = None) -> torch.Tensor:
    """The (B, T) bool frames a gated ``setting`` ('kalman_gain' or 'random') sends to MC dropout,
    among the real frames ``mask`` (B, T); gains (B, T, n, n) for 'kalman_gain' (``kind``: the
    model's, named in the error when it has none)."""
    if setting == "kalman_gain":
        if direction is None or threshold is None:
            raise ValueError("the kalman_gain setting needs the direction and threshold of a gate fitted "
                             "on validation data (fit_gate)")
        if gains is None:
            raise ValueError(f"model kind {kind!r} has no Kalman filter, so no gains "
                             f"to gate on; gating needs a model that declares competency_gain (the DRF, 'drf')")
        return apply_gating(competency_score(gains, direction), threshold, mask)
    if setting == "random":
        if n_random is None:
            raise ValueError("the random setting needs n_random (the Kalman-gain gate's frame count)")
        return random_selection(mask, n_random, random_seed)
    raise ValueError(f"select_frames takes the gated settings 'kalman_gain' and 'random', got {setting!r}")


def assemble(deterministic: GatedPrediction, always: GatedPrediction, selected: torch.Tensor) -> GatedPrediction:
    """A gated prediction from two full passes: ``always``'s result on the ``selected`` (B, T)
    frames, ``deterministic``'s (epistemic 0) elsewhere. The head is per frame, so this is what
    ``gated_head`` computes, up to which random numbers the selected frames' masks draw."""
    pick = selected.unsqueeze(-1)
    both = lambda a, b: torch.where(pick, a, b)  # noqa: E731
    return GatedPrediction(both(always.mean, deterministic.mean), both(always.aleatoric, deterministic.aleatoric),
                           both(always.epistemic, torch.zeros_like(always.epistemic)),
                           both(always.total, deterministic.total), selected)


@torch.no_grad()
def run_setting(model, inputs: torch.Tensor, mask: torch.Tensor, setting: str, **stage_kwargs
                ) -> GatedPrediction:
    """One whole inference of ``setting`` on ``inputs`` (B, T, ...), real frames ``mask`` (B, T):
    the features once (with gains only for kalman_gain), then ``uncertainty_stage``. Everything
    the setting costs is inside this call, so timing it times the setting."""
    h, gains = model.features(inputs, return_gains=setting == "kalman_gain")
    return uncertainty_stage(model, h, gains, mask, setting, **stage_kwargs)


# --------------------------------------------------------------------------- fit on validation
@dataclass(frozen=True)
class Gate:
    """A gate fitted on validation data: frames with competency_score(gains, direction) > threshold
    get MC dropout. ``sweep_thresholds`` are the validation-score quantiles for the fractions
    0 ... 1 (never ... always) that ``sweep_gate`` applies to test data."""

    direction: int
    threshold: float
    rank_correlation: float
    val_fraction: float
    val_picp: float
    val_picp_always: float
    sweep_fractions: tuple[float, ...]
    sweep_thresholds: tuple[float, ...]

    def scores(self, gains: torch.Tensor) -> torch.Tensor:
        return competency_score(gains, self.direction)

    def select(self, gains: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
        return apply_gating(self.scores(gains), self.threshold, mask)


def real_mask(data) -> torch.Tensor:
    """(N, T) bool: the frames of a SequenceData that are real (all of them when it has no mask)."""
    n, t = data.targets.shape[:2]
    return torch.ones(n, t, dtype=torch.bool) if data.mask is None else data.mask.bool()


def eval_mode(model) -> bool:
    """Put ``model`` in eval mode; returns whether it was training (restore it with ``model.train(was)``)."""
    was = model.training
    model.eval()
    return was


@torch.no_grad()
def fit_gate(model, val, *, n_samples: int, dropout_p: float | None = None, tolerance: float,
             n_points: int, level: float = 0.95, seed: int = 0, device=None) -> tuple[Gate, pd.DataFrame]:
    """Fit direction and threshold on the VALIDATION set ``val`` (a SequenceData) only.

    Returns the gate and the validation table of candidate fractions (see choose_threshold). A model
    that declares no ``competency_gain`` (``drfkit.models.sequence``) is refused.
    """
    n_samples = check_n_samples(n_samples)
    if n_samples < 1:
        raise ValueError("n_samples must be >= 1: the always-dropout reference needs MC samples")
    if not getattr(model, "competency_gain", False):
        raise ValueError(f"model kind {model.config.get('kind')!r} declares no competency_gain "
                         f"(drfkit.models.sequence): its gains, if any, do not score competency; gating needs "
                         f"a model that does (the DRF, 'drf')")
    p = model.default_dropout_p if dropout_p is None else check_dropout_p(dropout_p)
    device = torch.device(device) if device is not None else next(model.parameters()).device
    was = eval_mode(model)
    try:
        x = as_model_input(model, val.inputs).to(device)
        with distinct_frames_once(model):  # not timed: each distinct frame encoded once, the same numbers
            h, gains = model.features(x, return_gains=True)
        if gains is None:
            raise ValueError(f"model kind {model.config.get('kind')!r} has no Kalman filter; gating needs a model that "
                             f"declares competency_gain (the DRF, 'drf')")
        det_mean, det_sigma = model.head(h)
        torch.manual_seed(seed)
        mc_mean, _, _, mc_total = summarise_samples(*model.head(h, n_samples=n_samples, dropout_p=p))
    finally:
        model.train(was)
    real = real_mask(val).to(device)
    y = val.targets.to(device)
    k = mean_gain(gains)
    abs_error = (det_mean - y).abs().mean(dim=-1)
    direction, rho = choose_direction(k[real].cpu().numpy(), abs_error[real].cpu().numpy())
    scores = competency_score(gains, direction)[real].cpu().numpy()
    # Each candidate's gated prediction is assembled from the two full passes: a frame's head
    # output depends only on its own features and dropout masks, which is what gated_head computes.
    as_np = lambda t: t[real].double().cpu().numpy()  # noqa: E731  (N, out) over real frames
    threshold, table = choose_threshold(scores, as_np(y), (as_np(det_mean), as_np(det_sigma)),
                                        (as_np(mc_mean), as_np(mc_total)), tolerance=tolerance,
                                        n_points=n_points, level=level)
    chosen = table[table["chosen"]].iloc[0]
    gate = Gate(direction=direction, threshold=threshold, rank_correlation=rho,
                val_fraction=float(chosen["val_fraction"]), val_picp=float(chosen["val_picp"]),
                val_picp_always=float(chosen["val_picp_always"]),
                sweep_fractions=tuple(table["target_fraction"]), sweep_thresholds=tuple(table["threshold"]))
    return gate, table.assign(direction=direction, rank_correlation=rho)


__all__ = [
    "SETTINGS", "NEVER", "ALWAYS", "mean_gain", "competency_score", "choose_direction",
    "threshold_for_fraction", "apply_gating", "choose_threshold", "random_selection", "oracle_selection", "random_gating",
    "GatedPrediction", "gated_head", "uncertainty_stage", "select_frames", "assemble", "run_setting",
    "Gate", "fit_gate", "real_mask", "eval_mode",
]
