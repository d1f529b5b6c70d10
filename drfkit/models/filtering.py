"""The recursive filter's loop, shared by every model that filters (the DRF, the known-dynamics filter).

A filter is a start and a step (torchfilter's split of a filter into its parts, here as two functions the
model supplies):

    start(w_0, r_0)            -> carry_0, record_0        the belief after the first observation
    step(carry, w_t, r_t)      -> carry_t, record_t        predict with the model's transition, update with
                                                           its measurement model (t = 1 .. T-1)

``run_filter_loop`` runs it over observations w, r (B, T, m) and stacks every record's entries along time.
The carry is whatever the model's step needs (the DRF: z, P and its LSTM's memory; the known-dynamics
filter: the pendulum state and its covariance); a record holds tensors with a leading batch dimension
(means, variances, gains, the prior, the transition's F and q). The streaming path (``stream_step``) calls
the same ``step`` one frame at a time, so the loop and a stream compute the same values.

A forced gain (``gain``, (B, T): NaN = the filter's own gain, a number g = the update with gain g in the
observation's space; 0 = no update, z_t = F z_{t-1}, P_t = F P F^T + Q) is an intervention on the step, not on
its inputs: the dissection's clamped and oracle gains, and the training's skipped updates
(``TrainConfig.skip_spans``). It is passed to ``step(carry, w_t, r_t, gain_t)``; frame 0 (the start) is never
forced. ``select_forced`` merges the forced and the own update per row.
"""
from __future__ import annotations

from typing import Any, Callable

import torch

Record = dict[str, torch.Tensor]


def run_filter_loop(start: Callable[[torch.Tensor, torch.Tensor], tuple[Any, Record]],
                    step: Callable[[Any, torch.Tensor, torch.Tensor], tuple[Any, Record]],
                    w: torch.Tensor, r: torch.Tensor, gain: torch.Tensor | None = None
                    ) -> tuple[Record, dict[str, list[torch.Tensor]]]:
    """Run a filter over w, r (B, T, m); ``gain`` (B, T) a forced gain per frame (module doc; None: the filter's
    own everywhere, and ``step`` is called with three arguments). Returns (record_0, steps): ``steps`` maps each
    key of the step records to its T - 1 tensors in time order (``stack_steps`` stacks one)."""
    if w.ndim != 3 or r.shape != w.shape:
        raise ValueError(f"w and r must both be (B, T, m), got {tuple(w.shape)} and {tuple(r.shape)}")
    check_forced_gain(gain, w)
    # unbind once: indexing w[:, t] in the loop would make the backward pass build and sum T zero-padded
    # (B, T, m) gradients, one per step
    w_steps, r_steps = w.unbind(1), r.unbind(1)
    carry, first = start(w_steps[0], r_steps[0])
    steps: dict[str, list[torch.Tensor]] = {}
    g_steps = gain.to(w.dtype).unbind(1) if gain is not None else None
    for t in range(1, len(w_steps)):
        if g_steps is None:
            carry, record = step(carry, w_steps[t], r_steps[t])
        else:
            carry, record = step(carry, w_steps[t], r_steps[t], g_steps[t])
        for key, value in record.items():
            steps.setdefault(key, []).append(value)
    return first, steps


def stack_steps(steps: dict[str, list[torch.Tensor]], key: str, empty: torch.Tensor,
                first: torch.Tensor | None = None) -> torch.Tensor:
    """The steps' ``key`` stacked along time (B, T-1, ...), after ``first`` (B, ...) when given (B, T, ...);
    ``empty`` (B, 0, ...) when the sequence has no step."""
    values = steps.get(key, [])
    if first is not None:
        values = [first, *values]
    return torch.stack(values, dim=1) if values else empty


def check_forced_gain(gain: torch.Tensor | None, w: torch.Tensor) -> None:
    """A forced gain must be (B, T) of w's (B, T, m), each value NaN (the filter's own) or in [0, 1]."""
    if gain is None:
        return
    if not isinstance(gain, torch.Tensor) or gain.shape != w.shape[:2]:
        raise ValueError(f"a forced gain must be a tensor (B, T) = {tuple(w.shape[:2])} (NaN = the filter's own gain), "
                         f"got {getattr(gain, 'shape', type(gain).__name__)}")
    set_ = gain[~torch.isnan(gain)]
    if set_.numel() and (set_.min() < 0 or set_.max() > 1):
        raise ValueError(f"a forced gain must lie in [0, 1] (0 = no update, 1 = the observation replaces the "
                         f"state), got values in [{float(set_.min()):g}, {float(set_.max()):g}]")


def select_forced(gain_t: torch.Tensor, forced, own):
    """Per row of a batch, the forced update where ``gain_t`` (B,) is a number and the filter's own where it is
    NaN; ``forced`` and ``own`` are tuples of tensors with a leading batch dim (own may be None when every row
    is forced)."""
    if own is None:
        return forced
    use = ~torch.isnan(gain_t)
    return tuple(torch.where(use.reshape(-1, *([1] * (f.ndim - 1))), f, o) for f, o in zip(forced, own))


__all__ = ["Record", "check_forced_gain", "run_filter_loop", "select_forced", "stack_steps"]
