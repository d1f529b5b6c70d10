"""Where a run's time went: each notebook's total (wall and CPU seconds, the cores it kept busy) and every cell
slower than a threshold, as markdown.

    .venv/bin/python tools/slow_cells.py results/paper [--over 30]

Reads what the pipeline writes after a run: ``manifest.json`` (each notebook's duration, the commit)
and ``cell_times.csv`` (papermill's seconds per cell, with the cell's first line). The tables of
docs/rerun_time.md are this script's output for the committed paper profile.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import pandas as pd


def slow_cells(results: Path, over: float = 30.0) -> str:
    """Markdown: one row per notebook (seconds, share, cells over ``over`` s), then the slow cells."""
    manifest_path, cells_path = results / "manifest.json", results / "cell_times.csv"
    for path in (manifest_path, cells_path):
        if not path.is_file():
            raise SystemExit(f"{path} is missing: run `make reproduce PROFILE=<profile>` first "
                             f"(or `python -m drfkit manifest --cell-times <profile>` for cell_times.csv)")
    manifest = json.loads(manifest_path.read_text())
    pipeline, git = manifest["pipeline"], manifest["environment"].get("git", {})
    durations = pipeline["durations_s"]
    cpu, cores = pipeline.get("cpu_s") or {}, pipeline.get("cores")  # runs before CPU was recorded have neither
    cells = pd.read_csv(cells_path)
    total = sum(durations.values())
    lines = [f"commit {git.get('commit', '?')[:7]}{' (dirty)' if git.get('dirty') else ''}, "
             f"started {pipeline.get('started', '?')}, total {total:,.0f} s ({total / 60:.0f} min)"
             + (f", {cores} cores" if cores else ""), "",
             "| notebook | seconds | share | CPU seconds | cores used | cells over %g s |" % over,
             "|---|---|---|---|---|---|"]
    for name, seconds in durations.items():
        n_slow = int(((cells["notebook"] == name) & (cells["seconds"] > over)).sum())
        used = cpu.get(name)
        cpu_cells = ("| | " if used is None else
                     f"| {used:,.0f} | {used / seconds:.2f}" + (f" of {cores}" if cores else "") + " ")
        lines.append(f"| {name} | {seconds:,.0f} | {seconds / total:.0%} {cpu_cells}| {n_slow} |")
    lines += ["", "| notebook | cell | seconds | first line |", "|---|---|---|---|"]
    slow = cells[cells["seconds"] > over].sort_values(["notebook", "cell"])
    for row in slow.itertuples():
        first = str(row.first_line).replace("|", "\\|")[:70]
        lines.append(f"| {row.notebook} | {row.cell} | {row.seconds:,.0f} | `{first}` |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results", type=Path, help="a profile's results folder, e.g. results/paper")
    parser.add_argument("--over", type=float, default=30.0, help="list cells slower than this (seconds)")
    args = parser.parse_args(argv)
    print(slow_cells(args.results, args.over))
    return 0


if __name__ == "__main__":
    sys.exit(main())
