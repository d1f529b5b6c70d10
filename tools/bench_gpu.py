"""The accelerator measurement, prepared as one script of a few short runs: training and evaluation on
every device torch sees, against one and two CPU threads, and C6 on each device.

    .venv/bin/python tools/bench_gpu.py                                  # the book's sizes
    .venv/bin/python tools/bench_gpu.py --sequences 4 --devices cpu \\
        --min-run-time 0.05 --train-sequences 32                          # a smoke run (what the test does)

Rows (``torch.utils.benchmark``, which synchronises CUDA around its timings):
  train  one optimisation step (forward, the protocol's loss, backward, Adam) of the book protocol's
         DRF and no_dynamics on the paper's batch (16 windows of 25 frames): ms per step, and seconds
         per epoch = steps x ceil(--train-sequences / 16) (one window per sequence and epoch);
  eval   ``predict_rates`` (25 MC-dropout samples, batch 256) of the book protocol's DRF on --sequences
         sequences of 75 frames at max noise 0.75: frames per second; on CUDA twice, with the eager step
         loop and with the captured step (``drfkit.models.compiled``), so the launch-bound recursion's lever
         is measured against the plain GPU loop;
  filter the DRF's filter loop alone on 256 sequences of 75 frames: the checked loop (``run_filter``)
         against the captured step (``drfkit.models.compiled``; inductor, on CUDA with CUDA graphs);
         --no-cpu-capture skips the CPU capture (a 20 s compilation);
  C6     the pedestrian DRF with 25 batched samples against Monoloco as published, batch 1
         (``drfkit.study.bench.inference_benchmark``, as ``make bench``): the speed-up on each device.
Devices: ``cpu`` at 1 and 2 threads, and ``cuda`` where present (--devices). The GPU/CPU ratios are
printed against the two-thread CPU row. Untrained models (time does not depend on the weights).
"""
from __future__ import annotations

import argparse
import contextlib
import math
import sys
import time
from pathlib import Path

import pandas as pd
import torch
from torch.utils import benchmark

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from drfkit.data.noise import Noise  # noqa: E402
from drfkit.data.pendulum import generate_pendulum  # noqa: E402
from drfkit.methods import uncertainty  # noqa: E402
from drfkit.methods.objectives import batch_loss  # noqa: E402
from drfkit.methods.protocols import protocol_spec  # noqa: E402
from drfkit.models import build_model, default_config  # noqa: E402
from drfkit.models.compiled import CUDA_MODE, compile_step, filter_loop  # noqa: E402
from drfkit.study import bench  # noqa: E402
from drfkit.util.device import pick_device  # noqa: E402

BATCH, WINDOW, FRAMES = 16, 25, 75


def book_model(kind: str, device: torch.device):
    spec = protocol_spec("book", kind)
    return build_model(default_config(kind, "pendulum", 2, **spec["model"])).to(device), spec["train"]


def train_step(kind: str, device: torch.device, images: torch.Tensor, targets: torch.Tensor):
    model, train = book_model(kind, device)
    model.train()
    optimiser = torch.optim.Adam(model.parameters(), lr=1e-3)
    x, y = images[:BATCH, :WINDOW].to(device), targets[:BATCH, :WINDOW].to(device)

    def step():
        optimiser.zero_grad(set_to_none=True)
        batch_loss(model, train["objective"], train["beta"], x, y, None, train.get("prior_weight", 0.0),
                   train.get("obs_weight", 0.0)).backward()
        optimiser.step()
    return step


def median_seconds(fn, threads: int, min_run_time: float) -> float:
    fn()  # warm-up (a CUDA context, a capture)
    return benchmark.Timer("fn()", globals={"fn": fn}, num_threads=threads).blocked_autorange(
        min_run_time=min_run_time).median


@contextlib.contextmanager
def eager_loop():
    """``predict_rates`` without the captured step, also on CUDA."""
    saved = uncertainty.accelerated
    uncertainty.accelerated = lambda model, device: contextlib.nullcontext()
    try:
        yield
    finally:
        uncertainty.accelerated = saved


def settings(devices: list[str]) -> list[tuple[str, torch.device, int]]:
    out = []
    for name in devices:
        device = pick_device(name)
        out += [("cpu, 1 thread", device, 1), ("cpu, 2 threads", device, 2)] if device.type == "cpu" \
            else [(f"cuda ({torch.cuda.get_device_name(device)})", device, 1)]
    return out


def filter_rows(label: str, device: torch.device, threads: int, min_run_time: float, capture: bool) -> list[dict]:
    model, _ = book_model("drf", device)
    model.eval()
    g = torch.Generator().manual_seed(0)
    w = torch.randn(256, FRAMES, model.latent, generator=g).to(device)
    r = (torch.rand(256, FRAMES, model.latent, generator=g) * 0.5 + 0.05).to(device)
    fns = {"checked": lambda: model.run_filter(w, r)}
    if capture:
        step = compile_step(model.transition, "inductor", CUDA_MODE if device.type == "cuda" else None)
        fns["captured"] = lambda: filter_loop(step, model.transition, w, r)
    rows = []
    with torch.no_grad():
        for how, fn in fns.items():
            s = median_seconds(fn, threads, min_run_time)
            rows.append({"what": f"filter loop drf ({how} step)", "device": label, "ms": 1e3 * s,
                         "per_s": 256 * FRAMES / s, "unit": "frames", "epoch_s": float("nan")})
    return rows


def measure(devices: list[str], sequences: int, train_sequences: int, min_run_time: float,
            cpu_capture: bool = True) -> pd.DataFrame:
    data = generate_pendulum(max(sequences, BATCH), FRAMES, Noise("rkn_uniform", 0.75), 11)
    images, targets = torch.from_numpy(data["images"]), torch.from_numpy(data["targets"]).float()
    steps = math.ceil(train_sequences / BATCH)
    rows = []
    for label, device, threads in settings(devices):
        torch.set_num_threads(threads)
        for kind in ("drf", "no_dynamics"):
            s = median_seconds(train_step(kind, device, images, targets), threads, min_run_time)
            rows.append({"what": f"train {kind}", "device": label, "ms": 1e3 * s,
                         "per_s": 1.0 / s, "unit": "steps", "epoch_s": s * steps})
        model, _ = book_model("drf", device)
        ways = [("eager", eager_loop)] + ([("captured", contextlib.nullcontext)] if device.type == "cuda" else [])
        for how, context in ways:
            with context():
                run = lambda: uncertainty.predict_rates(model, images[:sequences], 25, batch_size=256,  # noqa: E731
                                                        device=device)
                run()  # warm-up: on CUDA the capture of each batch shape
                start = time.perf_counter()
                run()
                s = time.perf_counter() - start
            rows.append({"what": f"eval drf ({how} step)", "device": label, "ms": 1e3 * s,
                         "per_s": sequences * FRAMES / s, "unit": "frames", "epoch_s": float("nan")})
        rows += filter_rows(label, device, threads, min_run_time, cpu_capture or device.type == "cuda")
        timing = bench.inference_benchmark(25, (1,), (threads,), min_run_time, device.type, studies=("pedestrians",),
                                           rounds=1)
        speedup = bench.speedup_vs_monoloco(timing, 1, threads, device.type)
        rows.append({"what": "C6: Monoloco published / DRF 25 batched, batch 1", "device": label,
                     "ms": bench.lookup(timing, "pedestrians", "drf", "batched", 1, threads, device.type, "median_ms_per_call"),
                     "per_s": speedup, "unit": "x", "epoch_s": float("nan")})
    return pd.DataFrame(rows)


def gpu_ratios(table: pd.DataFrame) -> pd.DataFrame:
    """Per row kind: time on the two-thread CPU / time on each CUDA device (> 1: the GPU is faster)."""
    cpu = table[table["device"] == "cpu, 2 threads"].set_index("what")["ms"]
    gpu = table[table["device"].str.startswith("cuda")]
    return gpu.assign(gpu_over_cpu2=[cpu.get(w, float("nan")) / ms for w, ms in zip(gpu["what"], gpu["ms"])]
                      )[["what", "device", "gpu_over_cpu2"]]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--devices", nargs="+", default=["cpu", "auto"],
                    help="cpu, cuda or auto (cuda when present); default: cpu and auto")
    ap.add_argument("--sequences", type=int, default=1000, help="evaluation sequences (the paper's test set: 1000)")
    ap.add_argument("--train-sequences", type=int, default=2000, help="training sequences per epoch (paper: 2000)")
    ap.add_argument("--min-run-time", type=float, default=1.0, help="seconds per torch.utils.benchmark measurement")
    ap.add_argument("--no-cpu-capture", action="store_true", help="skip the captured step on the CPU")
    ap.add_argument("--out", type=Path, help="also write the table here (CSV)")
    args = ap.parse_args(argv)
    devices = list(dict.fromkeys(pick_device(d).type for d in args.devices))
    table = measure(devices, args.sequences, args.train_sequences, args.min_run_time, not args.no_cpu_capture)
    print(f"torch {torch.__version__}; CUDA {'available' if torch.cuda.is_available() else 'not available'}")
    with pd.option_context("display.width", 160, "display.max_columns", None):
        print(table.to_string(index=False, float_format=lambda v: f"{v:.4g}"))
        ratios = gpu_ratios(table)
        print("GPU over 2 CPU threads:\n" + ratios.to_string(index=False, float_format=lambda v: f"{v:.3g}")
              if len(ratios) else "no GPU seen: CPU rows only")
    if args.out:
        table.to_csv(args.out, index=False)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
