"""The inference benchmark (the paper's Table "performance") and its CLI, ``python -m drfkit bench``.

``inference_benchmark`` measures the cost of a prediction *with uncertainty* for one new
frame per pedestrian (or pendulum), after keypoint extraction -- the paper's Table
"performance" (25 forward passes, Monoloco 36.1 ms vs DRF 12.3 ms on a GTX 1080).

What one timed call does (``make_frame_fn``), for B pedestrians at once:

* streaming, one frame: the sequence models run ONE step on the new frame from a carried
  state (DRF: encoder, one transition + Kalman predict/update step from the previous
  posterior; LSTM: one LSTM step from the previous (h, c); no_dynamics and Monoloco have
  no state). Each model owns its step: ``model.initial_carry(first_frame)`` and
  ``model.stream_step(frame, carry)`` (``drfkit.models.sequence``). The carried state is
  computed once beforehand from a first frame and is not advanced by the timed call, so
  every call does the same work. A frame is thus one
  filter step, as in an online tracker; a length-1 sequence would skip the filter
  entirely, and dividing a T-step sequence by T would amortise the encoder's and the
  decoder's per-call cost over T frames that an online system does not have yet.
* then the uncertainty, in one of the modes (S = n_samples):
    - ``no_sampling``  one deterministic pass (dropout off): mean and aleatoric sigma;
    - ``batched``      the deterministic part once, S dropout samples of the stochastic
                       part in one call (``model.head(h, S)``), then the mixture moments
                       (``drfkit.methods.uncertainty.summarise_samples``);
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

from collections.abc import Mapping
from typing import Callable

import numpy as np
import pandas as pd
import torch

from drfkit.models.kinds import MODEL_CLASSES, model_spec
from drfkit.models.spec import DEFAULT_BENCH_MODES
from drfkit.study.registry import STUDIES as REGISTRY
from drfkit.methods.timing.clock import single_calls, warm_timer, load_average

BASELINE = ("monoloco", "published")  # the denominator of ratio_to_monoloco_published

class _TimedStudies(Mapping):
    """study -> (input kind, out_dim, models), read from ``drfkit.study.registry`` when asked (a model
    or study registered later is timed too); the pedestrian study, the one the paper times, first, and
    Monoloco (the baseline of every ratio) first among its models."""

    def _table(self) -> dict[str, tuple[str, int, tuple[str, ...]]]:
        return {name: (s.input_kind, s.out_dim, tuple(sorted(s.kinds, key=lambda k: k != BASELINE[0])))
                for name, s in sorted(REGISTRY.items(), key=lambda item: item[0] != "pedestrians")}

    def __getitem__(self, study: str):
        return self._table()[study]

    def __iter__(self):
        return iter(self._table())

    def __len__(self) -> int:
        return len(REGISTRY)


class _Modes(Mapping):
    """model -> the modes it is timed in (see the module docstring), read from its spec
    (``ModelSpec.bench_modes``, by default with and without sampling: ``DEFAULT_MODES``) when asked;
    a kind not registered is timed in the default modes."""

    def __getitem__(self, kind: str) -> tuple[str, ...]:
        return model_spec(kind).bench_modes if kind in MODEL_CLASSES else DEFAULT_MODES

    def __contains__(self, kind: object) -> bool:
        return kind in MODEL_CLASSES

    def __iter__(self):
        return iter(MODEL_CLASSES)

    def __len__(self) -> int:
        return len(MODEL_CLASSES)


STUDIES = _TimedStudies()
DEFAULT_MODES = DEFAULT_BENCH_MODES
MODES: Mapping[str, tuple[str, ...]] = _Modes()
COLUMNS = ["study", "model", "mode", "n_samples", "batch", "threads", "device", "median_ms_per_frame",
           "iqr_ms_per_frame", "median_ms_per_call", "ratio_to_monoloco_published", "ratio_to_no_sampling",
           "load_1min"]
GROUP = ["batch", "threads", "device"]  # ratios are taken only inside one such group of one run


# ---------------------------------------------------------------------- one timed call
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
    if study not in STUDIES:
        raise ValueError(f"unknown study {study!r}; expected one of {sorted(STUDIES)}")
    gen = torch.Generator().manual_seed(seed)
    input_kind = STUDIES[study][0]
    if input_kind == "keypoints":
        xy = torch.randn(batch, n_frames, 17, 2, generator=gen)
        conf = 0.1 + 0.9 * torch.rand(batch, n_frames, 17, 1, generator=gen)
        return torch.cat([xy, conf], dim=-1).to(device)
    if input_kind == "pendulum":
        return torch.randint(0, 256, (batch, n_frames, 24, 24), dtype=torch.uint8, generator=gen).to(device)
    raise ValueError(f"no example frames for input kind {input_kind!r} (study {study!r})")


def make_frame_fn(model, mode: str, frame: torch.Tensor, carry: tuple | None, n_samples: int
                  ) -> Callable[[], tuple[torch.Tensor, ...]]:
    """A no-argument function doing one frame's prediction with uncertainty in ``mode``.

    Returns what a caller would use: (mean, sigma) for ``no_sampling`` (B, 1, out), else
    (mean, aleatoric, epistemic, total), each (B, 1, out).
    """
    from drfkit.methods.uncertainty import summarise_samples

    allowed = MODES[model.kind]
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
                draws = [model.head(model.stream_step(frame, carry)[0], 1) for _ in range(n_samples)]
                return summarise_samples(torch.cat([m for m, _ in draws]), torch.cat([s for _, s in draws]))
            h, _ = model.stream_step(frame, carry)
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
                            carry = model.initial_carry(first)
                        fns[kind, mode] = make_frame_fn(model, mode, frame, carry, n_samples)
                        timers[kind, mode], call_s[kind, mode] = warm_timer(fns[kind, mode], n_threads,
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
                            times[key] += (single_calls(fns[key], n_threads, 1) if call_s[key] > budget
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


def paired_rounds(n_samples: int, rounds: int, threads: int = 1, device: str = "cpu", seed: int = 0,
                  block_s: float = 0.02) -> pd.DataFrame:
    """Claim C6's pair timed round by round: Monoloco as published and the DRF with S sequential decoder passes,
    pedestrians, batch 1, in ``rounds`` interleaved rounds (``interleaved_times``: a block of about ``block_s``
    seconds of each per round, the order rotated), so each round's ratio is paired: a slow spell of the machine
    hits both sides of it. One row per round: round, monoloco_ms, drf_ms (per frame) and ratio = Monoloco / DRF.
    """
    from drfkit.methods.timing.clock import interleaved_times, torch_threads

    if isinstance(rounds, bool) or not isinstance(rounds, int) or rounds < 2:
        raise ValueError(f"paired rounds must be an integer >= 2 (an interval needs two), got {rounds!r}")
    frames = example_frames("pedestrians", 1, 2, seed, device)
    first, frame = frames[:, :1], frames[:, 1:]
    fns = {}
    for kind, mode in (("monoloco", "published"), ("drf", "sequential")):
        model = build_timing_model(kind, "pedestrians", mode, seed, device)
        with torch.inference_mode():
            carry = model.initial_carry(first)
        fns[kind] = make_frame_fn(model, mode, frame, carry, n_samples)
    # min_run_time ~0: exactly ``rounds`` rounds, whatever a block costs on this machine
    with torch_threads(threads), torch.inference_mode():
        per_round = interleaved_times(fns, min_run_time=1e-9, block_s=block_s, min_rounds=rounds)
    mono, drf = (np.asarray(per_round[k]) * 1e3 for k in ("monoloco", "drf"))
    return pd.DataFrame({"round": np.arange(rounds), "monoloco_ms": mono, "drf_ms": drf, "ratio": mono / drf,
                         "threads": threads, "device": device, "n_samples": n_samples})


def inference_benchmark_with_load(*args, **kwargs) -> tuple[float, pd.DataFrame, float]:
    """``(load before, inference_benchmark(*args, **kwargs), load after)``: the machine's 1-minute
    load average around the run, kept with its table (a reused measurement keeps its own loads)."""
    before = load_average()
    table = inference_benchmark(*args, **kwargs)
    return before, table, load_average()


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


def device_ratios(table: pd.DataFrame) -> pd.DataFrame:
    """CPU / GPU time per frame of each (study, model, mode, batch) measured on both, the CPU at its
    largest thread count of the run (> 1: the GPU is faster); empty when the run saw no GPU."""
    gpu = table[table["device"].astype(str).str.startswith("cuda")]
    cpu = table[table["device"] == "cpu"]
    if gpu.empty or cpu.empty:
        return pd.DataFrame(columns=["study", "model", "mode", "batch", "cpu_threads", "gpu_over_cpu_speedup"])
    cpu = cpu[cpu["threads"] == cpu["threads"].max()]
    keys = ["study", "model", "mode", "batch"]
    both = cpu.merge(gpu, on=keys, suffixes=("_cpu", "_gpu"))
    return both.assign(cpu_threads=both["threads_cpu"],
                       gpu_over_cpu_speedup=both["median_ms_per_frame_cpu"] / both["median_ms_per_frame_gpu"]
                       )[[*keys, "cpu_threads", "gpu_over_cpu_speedup"]].reset_index(drop=True)

