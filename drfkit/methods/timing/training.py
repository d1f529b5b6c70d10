"""Training-speed studies: one optimisation step, whole epochs, the recursion's scaling, FLOPs.

``training_step_times`` measures one optimisation step (forward, loss, backward) of each model
on the same batch, from which seconds per epoch follow. The models are timed in interleaved
rounds (``drfkit.methods.timing.clock.interleaved_times``), and a ratio is the median of the per-round
ratios: a slow spell of a shared machine then hits both sides of a ratio alike. Asked to, it also
counts each step's arithmetic (``count_flops``), which says what a time ratio could be at equal
arithmetic rates: the floor below which only a faster rate helps. ``epoch_times`` times whole
epochs of the training loop; ``recursion_scaling`` splits the DRF recursion's cost into a fixed
and a per-sequence part.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pandas as pd
import torch
from torch.utils.flop_counter import FlopCounterMode, register_flop_formula

from drfkit.methods.timing.clock import interleaved_times, torch_threads


def training_step(model, inputs: torch.Tensor, targets: torch.Tensor) -> Callable[[], Any]:
    """One optimisation step's work of ``model`` on a batch (forward, loss, gradients of every
    parameter), as a function to time or count."""
    params = list(model.parameters())

    def step():
        mean, sigma = model(inputs)
        return torch.autograd.grad(model.loss(mean, sigma, targets, None), params, allow_unused=True)
    return step


def epoch_times(configs: dict[str, dict[str, Any]], train, val, train_configs: dict[str, Any], rounds: int = 3,
                threads: int | None = None) -> pd.DataFrame:
    """Seconds of one whole training epoch per model, as ``drfkit.methods.train.train_model`` runs it:
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

    from drfkit.methods.train import train_model

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
    and the DRF's recursion alone (its ``one_node_recursion`` forward and backward, unit upstream
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

    ``drf_config`` builds any model that declares a one-node recursion (``one_node_recursion`` and
    ``recursion_weights``, ``drfkit.models.sequence``): the DRF.

    Returns rows (model, part) = (base kind, 'step'), (filter kind, 'step') and (filter kind,
    'recursion') per size, with columns batch, frames, threads, rounds, median_s, iqr_s, fit_s
    (recursion rows), fixed_s, per_sequence_s, ratio and floor_ratio (the filter's step row; NaN
    elsewhere).
    """
    from drfkit.models import build_model

    batch = int(inputs.shape[0])
    if targets.shape[0] != batch:
        raise ValueError(f"inputs and targets disagree on the batch: {batch} and {targets.shape[0]}")
    sizes = sorted({batch, *(sizes if sizes is not None else (batch // 2, 2 * batch))} - {0})
    if any(isinstance(b, bool) or not isinstance(b, int) or b < 1 for b in sizes) or len(sizes) < 2:
        raise ValueError(f"sizes must hold positive ints giving >= 2 distinct batch sizes with B = {batch}, "
                         f"got {sizes}")
    torch.manual_seed(seed)
    base, drf = build_model(base_config).train(), build_model(drf_config).train()
    if drf.one_node_recursion is None:
        raise ValueError(f"drf_config must build a DRF (a model that declares one_node_recursion), got kind "
                         f"{drf.kind!r}")

    with torch.no_grad():
        w, r = drf.observe(inputs)  # (B, T, n) each: realistic observations for the filter
    weights = drf.recursion_weights()

    def recursion(b):
        reps = -(-b // batch)
        w_b = w.repeat(reps, 1, 1)[:b].clone().requires_grad_()
        r_b = r.repeat(reps, 1, 1)[:b].clone().requires_grad_()
        ones = torch.ones_like(w_b)

        def run():
            z, p = drf.one_node_recursion(w_b, r_b)
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
    for key, model, part, b in ([("base", base.kind, "step", batch), ("drf", drf.kind, "step", batch)]
                                + [(f"recursion_{b}", drf.kind, "recursion", b) for b in sizes]):
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
