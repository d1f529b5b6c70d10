"""Training objectives of the DRF family (what the gradient asks of the mean and of sigma), and the
optimiser, schedule and random windows that ``drfkit.methods.train`` fits them with.

Every objective takes ``mean``, ``sigma``, ``targets`` of one shape (B, T, out) and a (B, T)
bool ``mask`` of real frames (None = all), and returns the mean over the valid values.

* ``nll``      -- the paper's Gaussian NLL, log(sqrt(2 pi) sigma) + (y - mu)^2 / (2 sigma^2).
  Its gradient in mu is (mu - y) / sigma^2: where the network has learnt a small sigma the mean
  is pushed hard, where sigma is large it is barely fitted, and sigma shrinks fastest on easy
  frames. On the pendulum the training NLL keeps falling while the validation MAE doubles.
* ``beta_nll`` -- beta-NLL (Seitzer et al., ICLR 2022): the NLL of each value weighted by
  stopgrad(sigma^(2 beta)). beta = 0 is the NLL; beta = 1 gives the mean the gradient of
  (y - mu)^2 / 2 (that of MSE), while sigma still gets the NLL's gradient (scaled), so it still
  learns the spread of the errors.
* ``mse``      -- (y - mu)^2 / 2 on the mean alone; sigma gets no gradient (used as a warm-up:
  ``TrainConfig.mse_warmup`` epochs of it before the objective, the staged fit that BackpropKF and
  Kloss et al. 2021 recommend when a sensor model does not learn under the NLL).

``batch_loss`` adds, for a filter, the same objective on its one-step prior (``prior_weight``) and on its
observation alone (``obs_weight``).
"""
from __future__ import annotations

import math

import torch

from drfkit.methods.run_config import OBJECTIVES  # named once, with TrainConfig
from drfkit.models.sequence import check_loss_args, fill_padding, frame_mask, masked_mean

_HALF_LOG_2PI = 0.5 * math.log(2.0 * math.pi)


def _per_value_nll(mean, sigma, targets):
    return torch.log(sigma) + _HALF_LOG_2PI + 0.5 * ((targets - mean) / sigma) ** 2


def beta_nll(mean: torch.Tensor, sigma: torch.Tensor, targets: torch.Tensor, mask: torch.Tensor | None = None,
             beta: float = 1.0) -> torch.Tensor:
    """sum_valid stopgrad(sigma^(2 beta)) * NLL / n_valid; beta in [0, 1] (0 = the plain NLL)."""
    if not 0.0 <= float(beta) <= 1.0:
        raise ValueError(f"beta-NLL takes beta in [0, 1] (0 = the NLL, 1 = the mean fitted like MSE), got {beta!r}")
    check_loss_args(mean, sigma, targets)
    mask = frame_mask(mask, mean.shape)
    targets = fill_padding(targets, mask)
    per_value = _per_value_nll(mean, sigma, targets)
    if beta > 0:
        per_value = per_value * sigma.detach() ** (2.0 * beta)
    return masked_mean(per_value, mask)


def mse(mean: torch.Tensor, sigma: torch.Tensor, targets: torch.Tensor,
        mask: torch.Tensor | None = None) -> torch.Tensor:
    """(y - mu)^2 / 2 averaged over the valid values; ``sigma`` is checked but gets no gradient."""
    check_loss_args(mean, sigma, targets)
    mask = frame_mask(mask, mean.shape)
    targets = fill_padding(targets, mask)
    return masked_mean(0.5 * (targets - mean) ** 2, mask)


def objective_loss(model, objective: str, beta: float, mean, sigma, targets, mask=None) -> torch.Tensor:
    """The loss of one batch under ``objective`` (``OBJECTIVES``; 'model' = the model's own loss:
    the Gaussian NLL for the DRF family, Monoloco's relative Laplace loss)."""
    if objective == "model":
        return model.loss(mean, sigma, targets, mask)
    if objective == "nll":
        return beta_nll(mean, sigma, targets, mask, beta=0.0)
    if objective == "beta_nll":
        return beta_nll(mean, sigma, targets, mask, beta=beta)
    if objective == "mse":
        return mse(mean, sigma, targets, mask)
    raise ValueError(f"unknown training objective {objective!r}; choose from {OBJECTIVES}")


def batch_loss(model, objective: str, beta: float, inputs, targets, mask=None, prior_weight: float = 0.0,
               obs_weight: float = 0.0, gain: torch.Tensor | None = None) -> torch.Tensor:
    """The training loss of one batch: ``objective_loss`` of the model's output (with ``gain`` (B, T), a filter's
    forced gain per frame: ``skip_spans``' skipped updates, NaN elsewhere), plus

    * ``prior_weight`` > 0: that weight times the same objective of the one-step prior decoded for
      frames 1..T-1 (``forward_with_prior``; a filter's prediction of each frame before seeing it, so
      the transition is trained to predict rather than only to carry the posterior);
    * ``obs_weight`` > 0: that weight times the same objective of the observation alone
      (``observation_output``: w_t with r_t as its variance), so that r_t is fitted as the variance of
      what frame t shows -- high on a bad frame, which is what lowers a filter's gain there;
    * the model's own ``regulariser()`` (0 for most; the known-dynamics filter's pull of a learned
      transition toward the true one).
    """
    if gain is not None and not hasattr(model, "filter_internals"):
        raise ValueError(f"TrainConfig.skip_spans skips a filter's updates, but {type(model).__name__} has no filter; "
                         "set skip_spans = None for it")
    forced = {} if gain is None else {"gain": gain}
    if prior_weight > 0:
        if not hasattr(model, "forward_with_prior"):
            raise ValueError(f"TrainConfig.prior_weight = {prior_weight} asks for the one-step prior's loss, but "
                             f"{type(model).__name__} has no filter prior; set prior_weight = 0 for it")
        (mean, sigma), (prior_mean, prior_sigma) = model.forward_with_prior(inputs, **forced)
    else:
        mean, sigma = model(inputs, **forced)
    loss = objective_loss(model, objective, beta, mean, sigma, targets, mask)
    if prior_weight > 0 and targets.shape[1] >= 2:
        prior_mask = None if mask is None else mask[:, 1:]
        loss = loss + prior_weight * objective_loss(model, objective, beta, prior_mean, prior_sigma,
                                                    targets[:, 1:], prior_mask)
    if obs_weight > 0:
        if not hasattr(model, "observation_output"):
            raise ValueError(f"TrainConfig.obs_weight = {obs_weight} asks for an observation loss, but "
                             f"{type(model).__name__} has no observation; set obs_weight = 0 for it")
        obs_mean, obs_sigma = model.observation_output(inputs)
        loss = loss + obs_weight * objective_loss(model, objective, beta, obs_mean, obs_sigma, targets, mask)
    return loss + model.regulariser()


def make_optimiser(model, cfg):
    """Adam (AdamW when ``cfg.weight_decay`` > 0) and its schedule (``cfg.lr_schedule``), stepped once
    per epoch; ``cfg`` a ``drfkit.methods.train.TrainConfig``."""
    if cfg.weight_decay > 0:
        optimiser = torch.optim.AdamW(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    else:
        optimiser = torch.optim.Adam(model.parameters(), lr=cfg.lr)
    if cfg.lr_schedule == "cosine":
        scheduler = torch.optim.lr_scheduler.CosineAnnealingLR(optimiser, T_max=cfg.epochs, eta_min=0.0)
    else:
        scheduler = torch.optim.lr_scheduler.StepLR(optimiser, step_size=cfg.lr_step or 10**9, gamma=cfg.lr_gamma)
    return optimiser, scheduler


def random_windows(inputs: torch.Tensor, targets: torch.Tensor, mask: torch.Tensor | None, window: int,
                   generator: torch.Generator):
    """One window of ``window`` consecutive frames per sequence, its start uniform in [0, T - window]:
    (B, T, ...) -> (B, window, ...). Sequences no longer than ``window`` are returned whole."""
    b, t = targets.shape[:2]
    if t <= window:
        return inputs, targets, mask
    start = torch.randint(0, t - window + 1, (b,), generator=generator)
    rows = torch.arange(b)[:, None]
    cols = start[:, None] + torch.arange(window)[None, :]  # (B, window)
    dev = targets.device
    rows, cols = rows.to(dev), cols.to(dev)
    return inputs[rows, cols], targets[rows, cols], None if mask is None else mask[rows, cols]


def skip_spans(batch: int, frames: int, spans, fraction: float, generator: torch.Generator) -> torch.Tensor:
    """The forced gain (B, T) of a batch with skipped updates: in each window, with probability ``fraction``, one
    span of L frames, L uniform in spans = [lo, hi] (cut to T - 1), starting uniform in [1, T - L] (frame 0, the
    filter's start, is never skipped), gain 0 there; NaN (the filter's own gain) elsewhere. The frames themselves
    stay ordinary training frames: only the filter is told to ignore them, so the loss on them asks the transition
    to predict open loop over L frames (RKN's imputation)."""
    lo, hi = int(spans[0]), int(spans[1])
    gain = torch.full((batch, frames), float("nan"))
    if frames < 2:
        return gain
    hi = min(hi, frames - 1)
    lo = min(lo, hi)
    use = torch.rand(batch, generator=generator) < fraction
    length = torch.randint(lo, hi + 1, (batch,), generator=generator)
    start = 1 + (torch.rand(batch, generator=generator) * (frames - length).to(torch.float64)).long()    # [1, T - L]
    t = torch.arange(frames)[None, :]
    inside = use[:, None] & (t >= start[:, None]) & (t < (start + length)[:, None])
    return gain.masked_fill(inside, 0.0)


__all__ = ["OBJECTIVES", "batch_loss", "beta_nll", "make_optimiser", "mse", "objective_loss", "random_windows", "skip_spans"]
