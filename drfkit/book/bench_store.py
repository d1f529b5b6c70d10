"""The broad inference benchmark as a measurement of its own: ``make bench`` (``python -m drfkit bench``) times
every (model, mode, batch, threads, device) of a profile (``drfkit.study.bench.inference_benchmark``) and writes

    results/<profile>/bench/timing.csv      the table (``drfkit.study.bench.COLUMNS``)
    results/<profile>/bench/manifest.json   the command, the parameters, when, how long, the machine, the load
                                            around it, the versions and the git commit

Notebook 05 reads them (and says which command made them, where and when) instead of timing the grid again, so a
cold reproduce times only what the claims read (C6's pair in paired rounds, the epoch ratio). The notebook runs the
grid itself, through ``write_bench``, only where a profile has no table for its current parameters. One writer:
this module.
"""
from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any, Callable

import pandas as pd

from drfkit.util.io import atomic_write_bytes, atomic_write_csv
from drfkit.util.paths import results_dir

COMMAND = "make bench PROFILE={profile}"


def bench_dir(profile: str) -> Path:
    return results_dir(profile) / "bench"


def bench_params(P) -> dict[str, Any]:
    """What the table depends on: a stored table made with other values is not this profile's."""
    return {"n_samples": P.uncertainty.n_samples, "batch_sizes": list(P.timing.batch_sizes),
            "threads": list(P.timing.threads), "min_run_time": P.timing.min_run_time, "device": P.device,
            "seed": P.seeds[0]}


def write_bench(P, progress: Callable[[str], None] | None = None) -> tuple[pd.DataFrame, dict[str, Any]]:
    """Run the grid of profile ``P`` and write bench/timing.csv and bench/manifest.json (atomically, the table
    first); returns (table, record)."""
    from drfkit.book.manifest import environment, now_iso
    from drfkit.study.bench import inference_benchmark_with_load

    params, started, t0 = bench_params(P), now_iso(), time.perf_counter()
    load_before, table, load_after = inference_benchmark_with_load(
        params["n_samples"], params["batch_sizes"], params["threads"], params["min_run_time"], params["device"],
        seed=params["seed"], progress=progress)
    record = {"command": COMMAND.format(profile=P.profile), "profile": P.profile, "params": params,
              "started": started, "seconds": round(time.perf_counter() - t0, 1),
              "load_before": load_before, "load_after": load_after, "environment": environment()}
    folder = bench_dir(P.profile)
    atomic_write_csv(folder / "timing.csv", table)
    atomic_write_bytes(folder / "manifest.json", json.dumps(record, indent=1, default=str).encode())
    return table, record


def read_bench(P) -> tuple[pd.DataFrame, dict[str, Any]] | None:
    """(table, record) of the profile's stored benchmark, or None when there is none or it was made with other
    parameters than ``P``'s (then ``write_bench`` makes it again)."""
    folder = bench_dir(P.profile)
    if not (folder / "timing.csv").exists() or not (folder / "manifest.json").exists():
        return None
    record = json.loads((folder / "manifest.json").read_text())
    if record.get("params") != json.loads(json.dumps(bench_params(P))):
        return None
    return pd.read_csv(folder / "timing.csv"), record


def describe(record: dict[str, Any]) -> str:
    """One line: which command made the table, on which machine, when, how long it took and the load around it."""
    env = record.get("environment", {})
    commit = env.get("git", {}).get("commit", "?")
    return (f"`{record['command']}` on {env.get('cpu', '?')} ({env.get('cpu_count', '?')} cores), "
            f"{record['started']}, {record['seconds']:.0f} s, commit {str(commit)[:7]}; 1-min load "
            f"{record['load_before']:.1f} before, {record['load_after']:.1f} after")


__all__ = ["COMMAND", "bench_dir", "bench_params", "write_bench", "read_bench", "describe"]
