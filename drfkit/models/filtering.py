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
"""
from __future__ import annotations

from typing import Any, Callable

import torch

Record = dict[str, torch.Tensor]


def run_filter_loop(start: Callable[[torch.Tensor, torch.Tensor], tuple[Any, Record]],
                    step: Callable[[Any, torch.Tensor, torch.Tensor], tuple[Any, Record]],
                    w: torch.Tensor, r: torch.Tensor) -> tuple[Record, dict[str, list[torch.Tensor]]]:
    """Run a filter over w, r (B, T, m). Returns (record_0, steps): ``steps`` maps each key of the step records to
    its T - 1 tensors in time order (``stack_steps`` stacks one)."""
    if w.ndim != 3 or r.shape != w.shape:
        raise ValueError(f"w and r must both be (B, T, m), got {tuple(w.shape)} and {tuple(r.shape)}")
    # unbind once: indexing w[:, t] in the loop would make the backward pass build and sum T zero-padded
    # (B, T, m) gradients, one per step
    w_steps, r_steps = w.unbind(1), r.unbind(1)
    carry, first = start(w_steps[0], r_steps[0])
    steps: dict[str, list[torch.Tensor]] = {}
    for t in range(1, len(w_steps)):
        carry, record = step(carry, w_steps[t], r_steps[t])
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


__all__ = ["Record", "run_filter_loop", "stack_steps"]
