"""The clock of the timing studies: thread counts, single calls, warm timers and interleaved rounds.

Everything is timed with ``torch.utils.benchmark``'s clock, which synchronises an accelerator
before reading the time. Ratios are taken only between measurements of the same run, and
``interleaved_times`` measures the functions to compare in interleaved rounds, so that a slow
spell of a shared machine hits both sides of a ratio alike: a ratio is then the median of the
per-round ratios.
"""
from __future__ import annotations

import contextlib
import math
import os
from typing import Any, Callable

import numpy as np
import torch
import torch.utils.benchmark as benchmark
from torch.utils.benchmark.utils.timer import timer as synchronised_clock


@contextlib.contextmanager
def torch_threads(threads: int):
    """Run the block at ``threads`` torch threads, restoring the previous count after it."""
    previous = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        yield
    finally:
        torch.set_num_threads(previous)


def single_calls(fn, threads: int, n_calls: int) -> list[float]:
    """Seconds of ``n_calls`` calls of fn at ``threads``, each timed alone with the
    benchmark's clock (which synchronises CUDA before reading the time)."""
    with torch_threads(threads):
        times = []
        for _ in range(n_calls):
            start = synchronised_clock()
            fn()
            times.append(synchronised_clock() - start)
        return times


def warm_timer(fn, threads: int, min_run_time: float, warmup: int, label: str = "",
               sub_label: str = "") -> tuple[benchmark.Timer, float]:
    """A ``benchmark.Timer`` of ``fn()`` at ``threads`` after warm-up, and the seconds of
    the last warm-up call.

    Warm-up (allocations, lazy init, CUDA context and kernels) runs at the measured thread
    count; calls after the first only while they are cheap next to min_run_time, so a slow
    configuration does not spend most of the benchmark warming up.
    """
    timer = benchmark.Timer(stmt="fn()", globals={"fn": fn}, label=label, sub_label=sub_label,
                            num_threads=threads)
    seconds = single_calls(fn, threads, 1)[0]
    for _ in range(warmup - 1):
        if seconds > 0.1 * min_run_time:
            break
        seconds = single_calls(fn, threads, 1)[0]
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


def load_average() -> float:
    """The 1-minute load average (runnable processes, all users), NaN where the OS has none."""
    try:
        return float(os.getloadavg()[0])
    except (AttributeError, OSError):
        return math.nan


def timing_subset(frames_per_sequence: torch.Tensor, max_frames: int) -> torch.Tensor:
    """Indices (k,) of the test sequences timed: k evenly spaced over all N, the same every
    run, with k = ceil(N * max_frames / total frames) so that about ``max_frames`` real frames
    are timed (0, or a set no larger than that: every sequence). Evenly spaced, not the first
    k, so a test set ordered by scene or noise is sampled across its whole range.
    frames_per_sequence: (N,) real frames of each sequence."""
    if isinstance(max_frames, bool) or not isinstance(max_frames, int) or max_frames < 0:
        raise ValueError(f"gating_timing_frames must be an int >= 0 (0 = every test frame), got {max_frames!r}")
    n, total = frames_per_sequence.numel(), int(frames_per_sequence.sum())
    if max_frames == 0 or total <= max_frames:
        return torch.arange(n)
    k = math.ceil(n * max_frames / total)
    return torch.linspace(0, n - 1, k, dtype=torch.float64).round().long()


def measure_interleaved(fns: dict[str, Callable[[], Any]], min_run_time: float, block_s: float = 0.01,
                        min_rounds: int = 5) -> dict[str, float]:
    """Median seconds per call of each fn over interleaved rounds (``interleaved_times``:
    blocks of about ``block_s`` seconds, the order rotated per round, at least ``min_rounds``
    rounds and about ``min_run_time`` seconds per fn), so a slow spell of a shared machine hits
    every setting alike."""
    with torch.no_grad():
        per_round = interleaved_times(fns, min_run_time, block_s=block_s, min_rounds=min_rounds)
    return {n: float(np.median(v)) for n, v in per_round.items()}
