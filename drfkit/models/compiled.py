"""The DRF's inference loop as one captured step: the accelerator path.

On a GPU the per-step filter loop is launch-bound at the book's sizes: a step is a few dozen
small kernels (two LSTM cells, the transition head, the Kalman step on 30 x 30 matrices) and
one host synchronisation (``kalman_step`` asks the host whether every Cholesky factorisation
succeeded, to add jitter or raise). Here the same step defers that question to the end of the
sequence (``drfkit.core.filter.kalman_step_unchecked``), so ``torch.compile`` can capture it
whole: fused element-wise kernels and, on CUDA with ``mode='reduce-overhead'``, a CUDA graph
replayed once per step instead of a launch per small op.

    step = compile_step(model.transition, backend="inductor", mode="reduce-overhead")
    out = filter_loop(step, model.transition, w, r)   # None when some factorisation failed

A batch in which any factorisation failed is run again by the checked loop
(``DeepRecursiveFilter.run_filter`` does this), so values and errors are the checked loop's.
``accelerated(model, device)`` switches a model to the compiled step for a block of inference
on CUDA and restores it afterwards; on the CPU it changes nothing: there the captured step
(inductor) saves about a seventh of the filter loop, a few per cent of an evaluation, for a
compilation of about 20 s per batch shape (``tools/bench_gpu.py``). Inference only: training keeps the one-node recursion and its hand-written backward.
The CPU tests (tests/test_compiled.py) compare the captured step with the checked loop.
"""
from __future__ import annotations

import contextlib
from typing import Callable, Iterator

import torch

from drfkit.core.filter import kalman_step_unchecked

#: the mode ``accelerated`` compiles with on CUDA: CUDA graphs (one launch per step)
CUDA_MODE = "reduce-overhead"


def filter_step(transition: torch.nn.Module, z: torch.Tensor, P: torch.Tensor, state: tuple[torch.Tensor, ...],
                w_t: torch.Tensor, r_t: torch.Tensor):
    """One step of the DRF's filter without a host synchronisation: the transition network on
    z_{t-1} (B, n) gives F_t (B, n, n), q_t (B, n); the fused Kalman step on w_t, r_t (B, n) gives
    z_t, P_t, K_t. Returns (z_t, P_t, K_t, state, failed (B,) bool)."""
    F_t, q_t, state = transition(z, state)
    z, P, K, failed = kalman_step_unchecked(z, P, F_t, q_t, w_t, r_t)
    return z, P, K, state, failed


def compile_step(transition: torch.nn.Module, backend: str = "inductor", mode: str | None = None) -> Callable:
    """``filter_step`` for this transition, captured by ``torch.compile(backend, mode)`` (shapes
    static: one capture per batch size and dtype). The tests use backend 'aot_eager' (the captured
    graph without code generation) and 'inductor' on the CPU."""
    def step(z, P, state, w_t, r_t):
        return filter_step(transition, z, P, state, w_t, r_t)
    return torch.compile(step, backend=backend, mode=mode, dynamic=False)


def filter_loop(step: Callable, transition: torch.nn.Module, w: torch.Tensor, r: torch.Tensor,
                return_gains: bool = False) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None] | None:
    """The filter over w, r (B, T, n) with ``step`` (``filter_step`` or ``compile_step``'s):
    (z, diag P (B, T, n), gains K (B, T, n, n) or None) as the checked loop's, started the same
    way (z_0 = w_0, P_0 = diag r_0, K_0 = I); None when a factorisation failed in any step (one
    host synchronisation, after the loop: run the checked loop instead)."""
    batch, steps, n = w.shape
    w_steps, r_steps = w.unbind(1), r.unbind(1)
    z, P = w_steps[0], torch.diag_embed(r_steps[0])
    means, variances = [z], [r_steps[0]]
    gains = [transition.eye.expand(batch, n, n)] if return_gains else None
    failed = torch.zeros(batch, dtype=torch.bool, device=w.device)
    state = transition.initial_state(batch, w)
    graphs = w.device.type == "cuda"
    for t in range(1, steps):
        if graphs:  # a CUDA graph's outputs are overwritten by its next replay: keep copies
            torch.compiler.cudagraph_mark_step_begin()
        z, P, K, state, bad = step(z, P, state, w_steps[t], r_steps[t])
        if graphs:
            z, P, K, state, bad = z.clone(), P.clone(), K.clone(), tuple(s.clone() for s in state), bad.clone()
        means.append(z)
        variances.append(P.diagonal(dim1=-2, dim2=-1))
        if gains is not None:
            gains.append(K)
        failed |= bad
    if bool(failed.any()):
        return None
    return (torch.stack(means, dim=1), torch.stack(variances, dim=1),
            torch.stack(gains, dim=1) if gains is not None else None)


@contextlib.contextmanager
def accelerated(model: torch.nn.Module, device: torch.device | str, backend: str = "inductor",
                mode: str | None = CUDA_MODE) -> Iterator[None]:
    """Inside the block a model with a ``compiled_step`` slot (the DRF) filters with the captured
    step when ``device`` is CUDA; elsewhere, and for other models, nothing changes. The slot is
    restored in ``finally``; the capture is kept on the model for the next block."""
    if torch.device(device).type != "cuda" or not hasattr(model, "compiled_step"):
        yield
        return
    cache = model.__dict__.setdefault("_compiled_steps", {})
    key = (backend, mode)
    if key not in cache:
        cache[key] = compile_step(model.transition, backend, mode)
    before = model.compiled_step
    model.compiled_step = cache[key]
    try:
        yield
    finally:
        model.compiled_step = before
