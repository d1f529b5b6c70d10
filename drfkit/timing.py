"""Timing with ``torch.utils.benchmark``: medians over repeated blocks, ratios only
between measurements of the same run.

Two studies:

``training_step_times`` measures one optimisation step (forward, loss, backward) of
each model on the same batch, from which seconds per epoch follow. The models are timed
in interleaved rounds (``interleaved_times``), and a ratio is the median of the per-round
ratios: a slow spell of a shared machine then hits both sides of a ratio alike. Asked to,
it also counts each step's arithmetic (``count_flops``), which says what a time ratio
could be at equal arithmetic rates: the floor below which only a faster rate helps.

``inference_benchmark`` measures the cost of a prediction *with uncertainty* for one new
frame per pedestrian (or pendulum), after keypoint extraction -- the paper's Table
"performance" (25 forward passes, Monoloco 36.1 ms vs DRF 12.3 ms on a GTX 1080).

What one timed call does (``make_frame_fn``), for B pedestrians at once:

* streaming, one frame: the sequence models run ONE step on the new frame from a carried
  state (DRF: encoder, one transition + Kalman predict/update step from the previous
  posterior; LSTM: one LSTM step from the previous (h, c); no_dynamics and Monoloco have
  no state). The carried state is computed once beforehand from a first frame and is not
  advanced by the timed call, so every call does the same work. A frame is thus one
  filter step, as in an online tracker; a length-1 sequence would skip the filter
  entirely, and dividing a T-step sequence by T would amortise the encoder's and the
  decoder's per-call cost over T frames that an online system does not have yet.
* then the uncertainty, in one of the modes (S = n_samples):
    - ``no_sampling``  one deterministic pass (dropout off): mean and aleatoric sigma;
    - ``batched``      the deterministic part once, S dropout samples of the stochastic
                       part in one call (``model.head(h, S)``), then the mixture moments
                       (``drfkit.uncertainty.summarise_samples``);
    - ``sequential``   (DRF) the filter step once, then S separate ``head(h, 1)`` calls;
    - ``naive``        (DRF) S complete forward passes (filter step + one sample each);
    - ``published``    (Monoloco) S dropout passes through the whole MLP one after the
                       other, as Monoloco's code does (``mc_mode='sequential'``);
                       Monoloco's ``batched`` folds them into one call.
* under ``torch.inference_mode`` and in eval mode.

Models are built fresh from their default configs under a fixed seed: the weights do not
change the cost (no data-dependent control flow), so no training is needed to time them.
"""
from __future__ import annotations

import argparse
import contextlib
import math
import os
import sys
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pandas as pd
import torch
import torch.utils.benchmark as benchmark
from torch.utils.flop_counter import FlopCounterMode, register_flop_formula
from torch.utils.benchmark.utils.timer import timer as synchronised_clock

# study -> (input kind, out_dim, models); the pedestrian study is the one the paper times.
STUDIES: dict[str, tuple[str, int, tuple[str, ...]]] = {
    "pedestrians": ("keypoints", 1, ("monoloco", "drf", "no_dynamics", "lstm")),
    "pendulum": ("pendulum", 2, ("drf", "no_dynamics", "lstm")),
}
# model -> the modes it is timed in (see the module docstring)
MODES: dict[str, tuple[str, ...]] = {
    "monoloco": ("published", "batched", "no_sampling"),
    "drf": ("batched", "sequential", "naive", "no_sampling"),
    "no_dynamics": ("batched", "no_sampling"),
    "lstm": ("batched", "no_sampling"),
}
BASELINE = ("monoloco", "published")  # the denominator of ratio_to_monoloco_published
COLUMNS = ["study", "model", "mode", "n_samples", "batch", "threads", "device", "median_ms_per_frame",
           "iqr_ms_per_frame", "median_ms_per_call", "ratio_to_monoloco_published", "ratio_to_no_sampling",
           "load_1min"]
GROUP = ["batch", "threads", "device"]  # ratios are taken only inside one such group of one run


@contextlib.contextmanager
def torch_threads(threads: int):
    """Run the block at ``threads`` torch threads, restoring the previous count after it."""
    previous = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        yield
    finally:
        torch.set_num_threads(previous)


def training_step(model, inputs: torch.Tensor, targets: torch.Tensor) -> Callable[[], Any]:
    """One optimisation step's work of ``model`` on a batch (forward, loss, gradients of every
    parameter), as a function to time or count."""
    params = list(model.parameters())

    def step():
        mean, sigma = model(inputs)
        return torch.autograd.grad(model.loss(mean, sigma, targets, None), params, allow_unused=True)
    return step


def _single_calls(fn, threads: int, n_calls: int) -> list[float]:
    """Seconds of ``n_calls`` calls of fn at ``threads``, each timed alone with the
    benchmark's clock (which synchronises CUDA before reading the time)."""
    with torch_threads(threads):
        times = []
        for _ in range(n_calls):
            start = synchronised_clock()
            fn()
            times.append(synchronised_clock() - start)
        return times


def _warm_timer(fn, threads: int, min_run_time: float, warmup: int, label: str = "",
                sub_label: str = "") -> tuple[benchmark.Timer, float]:
    """A ``benchmark.Timer`` of ``fn()`` at ``threads`` after warm-up, and the seconds of
    the last warm-up call.

    Warm-up (allocations, lazy init, CUDA context and kernels) runs at the measured thread
    count; calls after the first only while they are cheap next to min_run_time, so a slow
    configuration does not spend most of the benchmark warming up.
    """
    timer = benchmark.Timer(stmt="fn()", globals={"fn": fn}, label=label, sub_label=sub_label,
                            num_threads=threads)
    seconds = _single_calls(fn, threads, 1)[0]
    for _ in range(warmup - 1):
        if seconds > 0.1 * min_run_time:
            break
        seconds = _single_calls(fn, threads, 1)[0]
    return timer, seconds


def interleaved_times(fns: dict[str, Callable[[], Any]], min_run_time: float, block_s: float = 0.01,
                      min_rounds: int = 5) -> dict[str, list[float]]:
    """Seconds per call of each fn, one value per round, measured in interleaved rounds.

    Each round times one block of calls (about ``block_s`` seconds, at least one call) of
    every fn in turn, the order rotated per round, so a slow spell of a shared machine hits
    every fn alike; per-round values of two fns can be divided to get a ratio in which such
    spells cancel. At least ``min_rounds`` rounds, and about ``min_run_time`` seconds per fn.
    One warm-up call each. The clock is ``torch.utils.benchmark``'s, which synchronises an
    accelerator before reading the time, so GPU work of a block is inside its time.
    """
    names = list(fns)
    if not names:
        raise ValueError("fns is empty: give at least one function to time")
    reps, block = {}, {}
    for name in names:  # warm-up, and how many calls make a block
        fns[name]()
        start = synchronised_clock()
        fns[name]()
        once = max(synchronised_clock() - start, 1e-7)
        reps[name] = max(1, int(block_s / once))
        block[name] = reps[name] * once
    per_call: dict[str, list[float]] = {n: [] for n in names}
    rounds = max(min_rounds, math.ceil(min_run_time / float(np.median(list(block.values())))))
    for r in range(rounds):
        for name in names[r % len(names):] + names[:r % len(names)]:
            fn, n = fns[name], reps[name]
            start = synchronised_clock()
            for _ in range(n):
                fn()
            per_call[name].append((synchronised_clock() - start) / n)
    return per_call


def epoch_times(configs: dict[str, dict[str, Any]], train, val, train_configs: dict[str, Any], rounds: int = 3,
                threads: int | None = None) -> pd.DataFrame:
    """Seconds of one whole training epoch per model, as ``drfkit.train.train_model`` runs it:
    every batch of ``train`` (forward, loss, backward, clipping, Adam), the validation loss
    on ``val`` and the epoch's checkpoint writes (into a temporary folder).

    configs: name -> model config; train_configs: name -> its ``TrainConfig`` (batch size,
    seed). Each of ``rounds`` rounds trains a fresh model of every config for one epoch, in
    an order rotated per round; the time is the training loop's own epoch clock (history
    ``seconds``: model building and the first optimiser state are outside it). Returns model,
    threads, rounds, sequences, batch, epoch_median_s, epoch_iqr_s, ratio_to_<first model>
    (the median over rounds of the per-round ratio) and ratio_to_<first model>_iqr.
    """
    import tempfile

    from drfkit.train import train_model

    names = list(configs)
    if not names or set(train_configs) != set(names):
        raise ValueError(f"configs and train_configs must name the same models, got {names} and {list(train_configs)}")
    if isinstance(rounds, bool) or not isinstance(rounds, int) or rounds < 1:
        raise ValueError(f"rounds must be a positive int, got {rounds!r}")
    threads = threads or torch.get_num_threads()
    seconds: dict[str, list[float]] = {n: [] for n in names}
    with torch_threads(threads), tempfile.TemporaryDirectory() as folder:
        for r in range(rounds):
            for name in names[r % len(names):] + names[:r % len(names)]:
                stem = Path(folder) / f"{name}-round{r}"
                result = train_model(configs[name], train, val, train_configs[name], stem, progress=False,
                                     stop_after_epochs=1)
                seconds[name].append(float(result.history[-1]["seconds"]))
    base = names[0]
    rows = []
    for name in names:
        t, ratio = np.asarray(seconds[name]), np.asarray(seconds[name]) / np.asarray(seconds[base])
        rows.append({"model": name, "threads": threads, "rounds": rounds, "sequences": len(train),
                     "batch": train_configs[name].batch_size, "epoch_median_s": float(np.median(t)),
                     "epoch_iqr_s": float(np.subtract(*np.quantile(t, [0.75, 0.25]))),
                     f"ratio_to_{base}": float(np.median(ratio)),
                     f"ratio_to_{base}_iqr": float(np.subtract(*np.quantile(ratio, [0.75, 0.25])))})
    return pd.DataFrame(rows)


def fit_fixed_and_per_item(sizes, seconds) -> tuple[float, float]:
    """Least-squares line seconds = fixed + per_item * size over >= 2 distinct sizes:
    (fixed, per_item)."""
    sizes, seconds = np.asarray(sizes, dtype=float), np.asarray(seconds, dtype=float)
    if sizes.shape != seconds.shape or len(np.unique(sizes)) < 2:
        raise ValueError(f"need seconds at >= 2 distinct sizes, got sizes {sizes.tolist()} "
                         f"and {seconds.size} times")
    per_item, fixed = np.polyfit(sizes, seconds, 1)
    return float(fixed), float(per_item)


def recursion_scaling(base_config: dict[str, Any], drf_config: dict[str, Any], inputs: torch.Tensor,
                      targets: torch.Tensor, sizes: tuple[int, ...] | None = None, min_run_time: float = 1.0,
                      threads: int | None = None, seed: int = 0, min_rounds: int = 5) -> pd.DataFrame:
    """How much of the DRF step's extra time is per-call cost, and what is left without it.

    Times in one interleaved run (``interleaved_times``, at ``threads``): a training step
    of the base model and of the DRF on ``inputs`` (B, T, ...) and ``targets`` (B, T, out),
    and the DRF's recursion alone (``drf_recursion`` forward and backward, unit upstream
    gradients) on the DRF's encoder outputs for these inputs, tiled to each batch size of
    ``sizes`` (default (B // 2, B, 2 B); B is always added). A least-squares line
    t(b) = fixed + per_sequence * b through the recursion's median times splits it into a
    part that does not grow with the batch -- the interpreter's and the dispatcher's cost of
    the recursion's hundreds of small ops per step, LAPACK's per-call setup -- and a part
    that does: the arithmetic and memory traffic of b sequences, with torch's kernels as
    they run at this thread count.

    ``floor_ratio`` (DRF step row) is the median over rounds of
    (drf_step - recursion(B) + per_sequence * B) / base_step: the DRF/base step ratio if the
    recursion's fixed part were gone and its kernels ran as fast as now -- what a compiled
    recursion calling the same kernels could reach at best. ``ratio`` is the plain median of
    per-round DRF/base step ratios of the same run.

    Returns rows (model, part) = (base kind, 'step'), ('drf', 'step') and ('drf', 'recursion')
    per size, with columns batch, frames, threads, rounds, median_s, iqr_s, fit_s (recursion
    rows), fixed_s, per_sequence_s, ratio and floor_ratio (DRF step row; NaN elsewhere).
    """
    from drfkit.models import build_model
    from drfkit.models.recursion import drf_recursion

    batch = int(inputs.shape[0])
    if targets.shape[0] != batch:
        raise ValueError(f"inputs and targets disagree on the batch: {batch} and {targets.shape[0]}")
    sizes = sorted({batch, *(sizes if sizes is not None else (batch // 2, 2 * batch))} - {0})
    if any(isinstance(b, bool) or not isinstance(b, int) or b < 1 for b in sizes) or len(sizes) < 2:
        raise ValueError(f"sizes must hold positive ints giving >= 2 distinct batch sizes with B = {batch}, "
                         f"got {sizes}")
    torch.manual_seed(seed)
    base, drf = build_model(base_config).train(), build_model(drf_config).train()
    if drf.kind != "drf":
        raise ValueError(f"drf_config must build a DRF, got kind {drf.kind!r}")

    with torch.no_grad():
        w, r = drf.observe(inputs)  # (B, T, n) each: realistic observations for the filter
    weights = list(drf.transition.parameters())

    def recursion(b):
        reps = -(-b // batch)
        w_b = w.repeat(reps, 1, 1)[:b].clone().requires_grad_()
        r_b = r.repeat(reps, 1, 1)[:b].clone().requires_grad_()
        ones = torch.ones_like(w_b)

        def run():
            z, p = drf_recursion(drf.transition, w_b, r_b)
            return torch.autograd.grad((z, p), [w_b, r_b, *weights], (ones, ones))
        return run

    fns = ({"base": training_step(base, inputs, targets), "drf": training_step(drf, inputs, targets)}
           | {f"recursion_{b}": recursion(b) for b in sizes})
    threads = threads or torch.get_num_threads()
    with torch_threads(threads):
        times = {k: np.asarray(v) for k, v in
                 interleaved_times(fns, min_run_time, block_s=0.0, min_rounds=min_rounds).items()}
    medians = {k: float(np.median(v)) for k, v in times.items()}
    fixed, per_sequence = fit_fixed_and_per_item(sizes, [medians[f"recursion_{b}"] for b in sizes])
    floor = (times["drf"] - times[f"recursion_{batch}"] + per_sequence * batch) / times["base"]
    rows = []
    for key, model, part, b in ([("base", base.kind, "step", batch), ("drf", "drf", "step", batch)]
                                + [(f"recursion_{b}", "drf", "recursion", b) for b in sizes]):
        q1, q3 = np.quantile(times[key], [0.25, 0.75])
        rows.append({"model": model, "part": part, "batch": b, "frames": int(inputs.shape[1]),
                     "threads": threads, "rounds": len(times[key]), "median_s": medians[key],
                     "iqr_s": float(q3 - q1), "fit_s": fixed + per_sequence * b if part == "recursion" else np.nan,
                     "fixed_s": fixed, "per_sequence_s": per_sequence,
                     "ratio": float(np.median(times["drf"] / times["base"])) if key == "drf" else np.nan,
                     "floor_ratio": float(np.median(floor)) if key == "drf" else np.nan})
    return pd.DataFrame(rows)


@register_flop_formula(torch.ops.aten.mkldnn_rnn_layer)
def _lstm_layer_flops(input_shape, weight0_shape, weight1_shape, *args, **kwargs) -> int:
    """One oneDNN LSTM layer over a sequence (what ``nn.LSTM`` runs on the CPU, and torch's
    FLOP counter has no formula for): per frame and item, the gate products W_ih x (4H x in)
    and W_hh h (4H x H), as ``nn.LSTMCell``'s two linears count them."""
    gates, inputs = weight0_shape
    frames = math.prod(input_shape) // inputs  # T * B, whichever of the two comes first
    return 2 * frames * gates * (inputs + weight1_shape[1])


@register_flop_formula(torch.ops.aten.mkldnn_rnn_layer_backward)
def _lstm_layer_backward_flops(input_shape, weight1_shape, weight2_shape, *args, **kwargs) -> int:
    """Its backward: the same products for dL/dx and dL/dh, and again for the weights'
    gradients, twice the forward (the arguments are numbered from weight1 here)."""
    return 2 * _lstm_layer_flops(input_shape, weight1_shape, weight2_shape)


def count_flops(fn: Callable[[], Any]) -> int:
    """Floating point operations of one call of ``fn``, as ``torch.utils.flop_counter``
    counts them: matrix products, convolutions and (formula above) the CPU LSTM layer,
    forward and backward (2 per multiply-add). Not counted: LAPACK calls (the filter's
    Cholesky factor and inverse) and elementwise ops, so the count is a lower bound of the
    work done."""
    counter = FlopCounterMode(display=False)
    with counter:
        fn()
    return int(counter.get_total_flops())


def training_step_times(configs: dict[str, dict[str, Any]], inputs: torch.Tensor, targets: torch.Tensor,
                        n_batches_per_epoch: int, min_run_time: float = 1.0,
                        threads: int | None = None, seed: int = 0, min_rounds: int = 5,
                        model_attrs: dict[str, dict[str, Any]] | None = None,
                        with_flops: bool = False) -> pd.DataFrame:
    """Median seconds of one training step per model, and the implied seconds per epoch.

    configs: name -> model config; inputs (B, T, ...) and targets (B, T, out): one batch.
    model_attrs: name -> attributes to set on that built model, e.g. ``{"whole_sequence": False}``
    to time a DRF that differentiates its per-step loop with autograd (attributes must exist).
    The models are timed in interleaved rounds (``interleaved_times``, about ``min_run_time``
    seconds each, at ``threads``). Returns columns model, batch, frames, threads, rounds,
    step_median_s, step_iqr_s (over rounds), epoch_s, ratio_to_<first model>: the median
    over rounds of this model's step time over the first model's in the same round, and
    ratio_to_<first model>_iqr: the interquartile range of those per-round ratios.
    ``with_flops`` adds gflop (one step's :func:`count_flops`, in 1e9), gflop_per_s (at the
    median step time) and flop_ratio_to_<first model>: the time ratio the models would
    have if both ran their counted arithmetic at the same rate.
    """
    from drfkit.models import build_model

    threads = threads or torch.get_num_threads()
    steps = {}
    for name, config in configs.items():
        torch.manual_seed(seed)
        model = build_model(config).train()
        for attr, value in (model_attrs or {}).get(name, {}).items():
            if not hasattr(model, attr):
                raise ValueError(f"model_attrs[{name!r}]: {type(model).__name__} has no attribute {attr!r}")
            setattr(model, attr, value)
        steps[name] = training_step(model, inputs, targets)
    flops = {name: count_flops(step) for name, step in steps.items()} if with_flops else {}
    with torch_threads(threads):
        times = interleaved_times(steps, min_run_time, block_s=0.0, min_rounds=min_rounds)
    base = next(iter(configs))
    rows = []
    for name, per_round in times.items():
        t = np.asarray(per_round)
        q1, q3 = np.quantile(t, [0.25, 0.75])
        per_round_ratio = t / np.asarray(times[base])
        rows.append({"model": name, "batch": int(inputs.shape[0]), "frames": int(inputs.shape[1]),
                     "threads": threads, "rounds": len(t), "step_median_s": float(np.median(t)),
                     "step_iqr_s": float(q3 - q1), "epoch_s": float(np.median(t)) * n_batches_per_epoch,
                     f"ratio_to_{base}": float(np.median(per_round_ratio)),
                     f"ratio_to_{base}_iqr": float(np.subtract(*np.quantile(per_round_ratio, [0.75, 0.25])))})
        if with_flops:
            rows[-1].update({"gflop": flops[name] / 1e9, "gflop_per_s": flops[name] / 1e9 / float(np.median(t)),
                             f"flop_ratio_to_{base}": flops[name] / flops[base]})
    return pd.DataFrame(rows)


# ------------------------------------------------------------------ one streaming step
def build_timing_model(kind: str, study: str, mode: str = "batched", seed: int = 0,
                       device: str | torch.device = "cpu"):
    """A fresh model of ``kind`` with its default config for ``study``, in eval mode.

    Monoloco in mode ``published`` samples its S passes one after the other
    (``mc_mode='sequential'``), otherwise folded into one batch. Same seed, same weights.
    """
    from drfkit.models import build_model, default_config

    if study not in STUDIES:
        raise ValueError(f"unknown study {study!r}; expected one of {sorted(STUDIES)}")
    input_kind, out_dim, kinds = STUDIES[study]
    if kind not in kinds:
        raise ValueError(f"model {kind!r} is not part of the {study} study; expected one of {kinds}")
    overrides = {"mc_mode": "sequential" if mode == "published" else "batched"} if kind == "monoloco" else {}
    torch.manual_seed(seed)
    return build_model(default_config(kind, input_kind, out_dim, **overrides)).to(device).eval()


def example_frames(study: str, batch: int, n_frames: int = 1, seed: int = 0,
                   device: str | torch.device = "cpu") -> torch.Tensor:
    """Random inputs of the right kind: keypoints (B, T, 17, 3) float32 (normalised x, y
    of order 1, confidences in (0.1, 1]) or pendulum images (B, T, 24, 24) uint8."""
    gen = torch.Generator().manual_seed(seed)
    if study == "pedestrians":
        xy = torch.randn(batch, n_frames, 17, 2, generator=gen)
        conf = 0.1 + 0.9 * torch.rand(batch, n_frames, 17, 1, generator=gen)
        return torch.cat([xy, conf], dim=-1).to(device)
    if study == "pendulum":
        return torch.randint(0, 256, (batch, n_frames, 24, 24), dtype=torch.uint8, generator=gen).to(device)
    raise ValueError(f"unknown study {study!r}; expected one of {sorted(STUDIES)}")


def initial_carry(model, frame: torch.Tensor) -> tuple | None:
    """The state a sequence model carries after its first frame ``frame`` (B, 1, ...).

    DRF: (z_0 = w_0 (B, n), P_0 = diag(r_0) (B, n, n), transition LSTM state) -- exactly
    what ``DeepRecursiveFilter.run_filter`` starts from; LSTM: its (h, c); else None.
    """
    _check_frame(frame)
    if model.kind == "drf":
        w, r = model.observe(frame)
        z, p_diag = w[:, 0], r[:, 0]
        return z, torch.diag_embed(p_diag), model.transition.initial_state(z.shape[0], z)
    if model.kind == "lstm":
        from drfkit.models.parts import mean_and_log_variance

        _, hc = model.lstm(mean_and_log_variance(*model.observe(frame)))
        return hc
    return None


def step_features(model, frame: torch.Tensor, carry: tuple | None) -> tuple[torch.Tensor, tuple | None]:
    """One streaming step: the deterministic features h (B, 1, D) of the new ``frame``
    (B, 1, ...) given the carried state, and the state after it.

    Stepping a sequence frame by frame from ``initial_carry`` of its first frame gives the
    same h as ``model.features`` on the whole sequence (tests/test_timing.py checks it).
    """
    _check_frame(frame)
    if model.kind == "drf":
        from drfkit.filter import kalman_step
        from drfkit.models.parts import mean_and_log_variance

        z, P, state = carry
        w, r = model.observe(frame)
        F_t, q_t, state = model.transition(z, state)
        z, P, _ = kalman_step(z, P, F_t, q_t, w[:, 0], r[:, 0])
        h = mean_and_log_variance(z, P.diagonal(dim1=-2, dim2=-1)).unsqueeze(1)
        return h, (z, P, state)
    if model.kind == "lstm":
        from drfkit.models.parts import mean_and_log_variance

        h, hc = model.lstm(mean_and_log_variance(*model.observe(frame)), carry)
        return h, hc
    return model.features(frame)[0], None


def _check_frame(frame: torch.Tensor) -> None:
    if not isinstance(frame, torch.Tensor) or frame.ndim != 4 or frame.shape[1] != 1:
        shape = tuple(frame.shape) if isinstance(frame, torch.Tensor) else type(frame).__name__
        raise ValueError(f"a streaming step takes one frame per sequence, shape (B, 1, ...), got {shape}; "
                         f"slice a sequence with x[:, t:t + 1]")


def make_frame_fn(model, mode: str, frame: torch.Tensor, carry: tuple | None, n_samples: int
                  ) -> Callable[[], tuple[torch.Tensor, ...]]:
    """A no-argument function doing one frame's prediction with uncertainty in ``mode``.

    Returns what a caller would use: (mean, sigma) for ``no_sampling`` (B, 1, out), else
    (mean, aleatoric, epistemic, total), each (B, 1, out).
    """
    from drfkit.uncertainty import summarise_samples

    allowed = MODES.get(model.kind, ())
    if mode not in allowed:
        raise ValueError(f"mode {mode!r} is not timed for {model.kind}; expected one of {allowed}")
    if mode == "published" and getattr(model, "mc_mode", None) != "sequential":
        raise ValueError("Monoloco 'published' needs a model built with mc_mode='sequential' "
                         "(build_timing_model(kind, study, mode='published'))")
    if n_samples < 1 and mode != "no_sampling":
        raise ValueError(f"mode {mode!r} needs n_samples >= 1, got {n_samples}")

    def run() -> tuple[torch.Tensor, ...]:
        with torch.inference_mode():
            if mode == "naive":  # S complete passes, the filter step included in each
                draws = [model.head(step_features(model, frame, carry)[0], 1) for _ in range(n_samples)]
                return summarise_samples(torch.cat([m for m, _ in draws]), torch.cat([s for _, s in draws]))
            h, _ = step_features(model, frame, carry)
            if mode == "no_sampling":
                return model.head(h)
            if mode == "sequential":  # the filter step once, S separate decoder calls
                draws = [model.head(h, 1) for _ in range(n_samples)]
                return summarise_samples(torch.cat([m for m, _ in draws]), torch.cat([s for _, s in draws]))
            return summarise_samples(*model.head(h, n_samples))  # batched / published

    return run


# ------------------------------------------------------------------------ the study
def timing_devices(device: str) -> list[str]:
    """'auto' -> CPU, and CUDA too when torch sees a GPU; 'cpu'; 'cuda' (error without one)."""
    if device == "auto":
        return ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
    if device == "cpu":
        return ["cpu"]
    if device == "cuda":
        if not torch.cuda.is_available():
            raise RuntimeError("device 'cuda' was asked for but torch sees no GPU; use device 'auto' or 'cpu'")
        return ["cuda"]
    raise ValueError(f"device must be 'auto', 'cpu' or 'cuda', got {device!r}")


def load_average() -> float:
    """The 1-minute load average (runnable processes, all users), NaN where the OS has none."""
    try:
        return float(os.getloadavg()[0])
    except (AttributeError, OSError):
        return math.nan


def _check_int_list(name: str, values) -> list[int]:
    if isinstance(values, int) or not values or any(isinstance(v, bool) or not isinstance(v, int) or v < 1
                                                    for v in values):
        raise ValueError(f"{name} must be a non-empty list of integers >= 1, got {values!r}")
    return list(values)


def inference_benchmark(n_samples: int = 25, batch_sizes=(1, 16, 256), threads=(1, 2),
                        min_run_time: float = 0.2, device: str = "auto", seed: int = 0,
                        studies=("pedestrians", "pendulum"), rounds: int = 3,
                        progress: Callable[[str], None] | None = None) -> pd.DataFrame:
    """Per-frame cost of a prediction with uncertainty, every model and mode, in one run.

    For each device ('auto': CPU, plus CUDA when available), batch size B (frames timed
    together, one per pedestrian) and thread count (``benchmark.Timer(num_threads=...)``),
    each (study, model, mode) of ``STUDIES`` x ``MODES`` is warmed up, then timed with
    ``blocked_autorange(min_run_time / rounds)`` in each of ``rounds`` interleaved rounds
    over the group's configurations; median and IQR are over all the blocks' per-call times.

    Returns one row per measurement, columns ``COLUMNS``:
        median_ms_per_frame, iqr_ms_per_frame   median and IQR of a call, in ms, / B
        median_ms_per_call                      the latency of the whole call (B frames)
        ratio_to_monoloco_published             / Monoloco-as-published of the same
            (batch, threads, device) group; NaN for the pendulum (no Monoloco there)
        ratio_to_no_sampling                    / the same model's no_sampling pass in the group
        load_1min                               the machine's 1-minute load average after the
            group's measurements (other processes competing for the cores; NaN where unknown)
    """
    if isinstance(n_samples, bool) or not isinstance(n_samples, int) or n_samples < 1:
        raise ValueError(f"n_samples must be an integer >= 1 (MC dropout passes), got {n_samples!r}")
    batch_sizes = _check_int_list("batch_sizes", batch_sizes)
    threads = _check_int_list("threads", threads)
    if isinstance(min_run_time, bool) or not isinstance(min_run_time, (int, float)) or not min_run_time > 0:
        raise ValueError(f"min_run_time must be a number of seconds > 0, got {min_run_time!r}")
    if isinstance(rounds, bool) or not isinstance(rounds, int) or rounds < 1:
        raise ValueError(f"rounds must be an integer >= 1, got {rounds!r}")
    unknown = set(studies) - set(STUDIES)
    if unknown or not studies:
        raise ValueError(f"studies must be a non-empty subset of {sorted(STUDIES)}, got {studies!r}")

    rows = []
    for dev in timing_devices(device):
        for study in studies:
            models = {(kind, mode): build_timing_model(kind, study, mode, seed, dev)
                      for kind in STUDIES[study][2] for mode in MODES[kind]}
            for batch in batch_sizes:
                frames = example_frames(study, batch, 2, seed, dev)
                first, frame = frames[:, :1], frames[:, 1:]
                for n_threads in threads:
                    if progress:
                        progress(f"{dev} {study} batch {batch} threads {n_threads}")
                    timers, fns, call_s = {}, {}, {}
                    for (kind, mode), model in models.items():
                        with torch.inference_mode():
                            carry = initial_carry(model, first)
                        fns[kind, mode] = make_frame_fn(model, mode, frame, carry, n_samples)
                        timers[kind, mode], call_s[kind, mode] = _warm_timer(fns[kind, mode], n_threads,
                                                                             min_run_time, warmup=3)
                    # Interleaved rounds: every configuration of the group is measured in each
                    # round, so a change in machine load during the group hits all of them
                    # alike instead of biasing the ratios between them. A call longer than a
                    # round's budget is timed alone: blocked_autorange would spend one more
                    # call estimating a block size of 1.
                    budget = min_run_time / rounds
                    times: dict[tuple[str, str], list[float]] = {key: [] for key in timers}
                    for _ in range(rounds):
                        for key, tm in timers.items():
                            times[key] += (_single_calls(fns[key], n_threads, 1) if call_s[key] > budget
                                           else tm.blocked_autorange(min_run_time=budget).times)
                    load = load_average()
                    for (kind, mode), per_call in times.items():
                        q25, median, q75 = (float(v) for v in np.percentile(per_call, [25, 50, 75]))
                        rows.append({"study": study, "model": kind, "mode": mode,
                                     "n_samples": 0 if mode == "no_sampling" else n_samples,
                                     "batch": batch, "threads": n_threads, "device": dev,
                                     "median_ms_per_frame": 1e3 * median / batch,
                                     "iqr_ms_per_frame": 1e3 * (q75 - q25) / batch,
                                     "median_ms_per_call": 1e3 * median, "load_1min": load})
    return add_ratios(pd.DataFrame(rows))


def add_ratios(frame: pd.DataFrame) -> pd.DataFrame:
    """Fill ratio_to_monoloco_published and ratio_to_no_sampling from median_ms_per_frame,
    dividing only inside one (batch, threads, device) group (see ``inference_benchmark``)."""
    frame = frame.copy()
    keys = ["study", *GROUP]
    base = frame[(frame["model"] == BASELINE[0]) & (frame["mode"] == BASELINE[1])]
    if base.duplicated(keys).any():
        raise ValueError("more than one Monoloco-published row per (batch, threads, device): "
                         "ratios need one measurement per group")
    base = base.set_index(keys)["median_ms_per_frame"].rename("_base")
    frame = frame.join(base, on=keys)
    frame["ratio_to_monoloco_published"] = frame["median_ms_per_frame"] / frame.pop("_base")
    keys = ["study", "model", *GROUP]
    det = frame[frame["mode"] == "no_sampling"].set_index(keys)["median_ms_per_frame"].rename("_det")
    frame = frame.join(det, on=keys)
    frame["ratio_to_no_sampling"] = frame["median_ms_per_frame"] / frame.pop("_det")
    return frame[COLUMNS]


def lookup(table: pd.DataFrame, study: str, model: str, mode: str, batch: int, threads: int,
           device: str, column: str = "median_ms_per_frame") -> float:
    """One value of the ``inference_benchmark`` table; KeyError naming the cell if absent."""
    rows = table[(table["study"] == study) & (table["model"] == model) & (table["mode"] == mode)
                 & (table["batch"] == batch) & (table["threads"] == threads) & (table["device"] == device)]
    if len(rows) != 1:
        raise KeyError(f"expected one row for {study}/{model}/{mode} batch {batch} threads {threads} "
                       f"on {device}, found {len(rows)}")
    return float(rows[column].iloc[0])


def speedup_vs_monoloco(table: pd.DataFrame, batch: int, threads: int, device: str,
                        mode: str = "batched") -> float:
    """Monoloco as published / DRF in ``mode`` (per frame, same group of the same run)."""
    return 1.0 / lookup(table, "pedestrians", "drf", mode, batch, threads, device, "ratio_to_monoloco_published")


# ------------------------------------------------------------------------------ CLI
def main(argv: list[str] | None = None) -> int:
    """``python -m drfkit.timing --profile quick|paper|path.yaml``: run the inference
    benchmark with the profile's n_samples and timing_* keys, print the table and write
    results/<profile>/timing.csv."""
    from drfkit.io import atomic_write_csv
    from drfkit.params import load_profile, notebook_params
    from drfkit.paths import results_dir

    ap = argparse.ArgumentParser(prog="python -m drfkit.timing", description=main.__doc__)
    ap.add_argument("--profile", default="quick", help="a profile name in params/ or a YAML path")
    args = ap.parse_args(argv)
    P = notebook_params("04_timing", load_profile(args.profile))
    if P["threads"]:
        torch.set_num_threads(P["threads"])
    table = inference_benchmark(P["n_samples"], P["timing_batch_sizes"], P["timing_threads"],
                                P["timing_min_run_time"], P["device"], seed=P["seeds"][0],
                                progress=lambda msg: print(f"timing {msg}", file=sys.stderr, flush=True))
    with pd.option_context("display.width", 200, "display.max_rows", None, "display.max_columns", None):
        print(table.to_string(index=False, float_format=lambda v: "nan" if math.isnan(v) else f"{v:.4g}"))
    path = atomic_write_csv(results_dir(P["profile"]) / "timing.csv", table)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
