"""Timing with ``torch.utils.benchmark``: medians over repeated blocks, ratios only
between measurements of the same run.

The package, by job (every public name is re-exported here, so ``from drfkit.methods.timing import X``
works for all of them; inside drfkit, import from the defining module):

``drfkit.methods.timing.clock``      the clock: ``torch_threads``, single calls, warm timers,
                                     ``interleaved_times`` (rounds in rotated order, per-round ratios) and
                                     their medians (``measure_interleaved``), ``timing_subset`` (which test
                                     sequences a timing uses), ``load_average``
``drfkit.methods.timing.training``   training-speed studies: ``training_step_times`` (one optimisation
                                     step per model, seconds per epoch, optionally ``count_flops``),
                                     ``epoch_times``, ``recursion_scaling``, ``fit_fixed_and_per_item``

The inference benchmark (the paper's Table "performance", per study of ``drfkit.study.registry``)
is a study: ``drfkit.study.bench``, ``python -m drfkit bench --profile quick|paper|path.yaml``.
"""
from drfkit.methods.timing.clock import (interleaved_times, load_average, measure_interleaved, single_calls, timing_subset,
                                         torch_threads, warm_timer)
from drfkit.methods.timing.training import (count_flops, epoch_times, fit_fixed_and_per_item, recursion_scaling,
                                            training_step, training_step_times)

__all__ = [
    "torch_threads", "interleaved_times", "measure_interleaved", "timing_subset", "load_average", "single_calls",
    "warm_timer",
    "training_step", "training_step_times", "epoch_times", "recursion_scaling", "fit_fixed_and_per_item",
    "count_flops",
]
