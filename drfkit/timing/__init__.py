"""Timing with ``torch.utils.benchmark``: medians over repeated blocks, ratios only
between measurements of the same run.

The package, by job (every public name is re-exported here, so ``from drfkit.timing import X``
works for all of them):

``drfkit.timing.clock``      the clock: ``torch_threads``, single calls, warm timers,
                             ``interleaved_times`` (rounds in rotated order, per-round ratios),
                             ``load_average``
``drfkit.timing.training``   training-speed studies: ``training_step_times`` (one optimisation
                             step per model, seconds per epoch, optionally ``count_flops``),
                             ``epoch_times``, ``recursion_scaling``, ``fit_fixed_and_per_item``
``drfkit.timing.inference``  the inference benchmark, the paper's Table "performance":
                             ``inference_benchmark`` (``inference_benchmark_with_load``: with the
                             machine's load around it) of a prediction with uncertainty for one new
                             frame (``make_frame_fn``), its table (``add_ratios``, ``lookup``,
                             ``speedup_vs_monoloco``) and the CLI ``main``
``python -m drfkit.timing --profile quick|paper|path.yaml``
                             runs the inference benchmark and writes results/<profile>/timing.csv

The streaming step the inference benchmark times is the models' own:
``model.initial_carry(first_frame)`` and ``model.stream_step(frame, carry)``
(``drfkit.models.sequence``).
"""
from drfkit.timing.clock import _single_calls, _warm_timer, interleaved_times, load_average, torch_threads
from drfkit.timing.inference import (BASELINE, COLUMNS, GROUP, MODES, STUDIES, add_ratios, build_timing_model,
                                     example_frames, inference_benchmark,
                                     inference_benchmark_with_load, lookup, main, make_frame_fn,
                                     speedup_vs_monoloco, timing_devices)
from drfkit.timing.training import (count_flops, epoch_times, fit_fixed_and_per_item, recursion_scaling,
                                    training_step, training_step_times)

__all__ = [
    "torch_threads", "interleaved_times", "load_average",
    "training_step", "training_step_times", "epoch_times", "recursion_scaling", "fit_fixed_and_per_item",
    "count_flops",
    "STUDIES", "MODES", "BASELINE", "COLUMNS", "GROUP", "build_timing_model", "example_frames", "make_frame_fn",
    "timing_devices", "inference_benchmark", "inference_benchmark_with_load", "add_ratios", "lookup", "speedup_vs_monoloco", "main",
]
