"""Where a slow cell spends its time: every cell of a notebook under cProfile, kept for the slow ones.

``make reproduce CELL_PROFILE=30`` (``python -m drfkit reproduce --cell-profile 30``) sets
``DRFKIT_CELL_PROFILE=30`` for the notebooks' kernels; ``start_notebook`` then registers two IPython
events: before a cell, a fresh ``cProfile.Profile`` starts; after it, a cell that took at least that many
seconds leaves ``results/<profile>/cell_profiles/<notebook>-cell<NN>.txt``: its seconds, its first code
line and its ``TOP`` functions by cumulative time. Unset, nothing is installed and nothing is written.

cProfile adds a cost per Python call (the recursions over time make many), so a profiled run's cell
times are not the book's timings: profile in a run of its own (docs/rerun_time.md says which).
"""
from __future__ import annotations

import cProfile
import io
import os
import pstats
import time
from pathlib import Path
from typing import Any

from drfkit.util.io import atomic_write_text

ENV = "DRFKIT_CELL_PROFILE"
TOP = 25


def threshold_from_env() -> float | None:
    """The seconds ``DRFKIT_CELL_PROFILE`` asks for, None when unset or empty."""
    raw = os.environ.get(ENV, "").strip()
    if not raw:
        return None
    try:
        seconds = float(raw)
    except ValueError:
        seconds = -1.0
    if not seconds >= 0:
        raise ValueError(f"{ENV}={raw!r}: give the seconds above which a cell's profile is kept, e.g. 30 "
                         f"(make reproduce CELL_PROFILE=30), or leave it unset")
    return seconds


def first_code_line(source: str) -> str:
    """The first line of a cell that is neither blank nor a comment (what names the cell in a report)."""
    for line in source.splitlines():
        if line.strip() and not line.lstrip().startswith("#"):
            return line.strip()[:120]
    return ""


def install(notebook: str, out_dir: Path, threshold: float, shell: Any = None) -> bool:
    """Register the profiling events on ``shell`` (default: the running IPython); False when there is
    no IPython (a notebook's code run as a script)."""
    if shell is None:
        try:
            from IPython import get_ipython
        except ImportError:
            return False
        shell = get_ipython()
        if shell is None:
            return False
    state: dict[str, Any] = {}

    def before(info) -> None:
        state["source"] = getattr(info, "raw_cell", "") or ""
        state["profile"] = cProfile.Profile()
        state["start"] = time.perf_counter()
        state["profile"].enable()

    def after(result) -> None:
        profile = state.pop("profile", None)
        if profile is None:
            return
        profile.disable()
        seconds = time.perf_counter() - state["start"]
        if seconds < threshold:
            return
        count = getattr(result, "execution_count", None) or 0
        text = io.StringIO()
        pstats.Stats(profile, stream=text).sort_stats("cumulative").print_stats(TOP)
        atomic_write_text(Path(out_dir) / f"{notebook}-cell{count:02d}.txt",
                          f"{notebook}, cell {count}: {seconds:.1f} s\n{first_code_line(state['source'])}\n\n"
                          + text.getvalue())

    shell.events.register("pre_run_cell", before)
    shell.events.register("post_run_cell", after)
    return True


__all__ = ["ENV", "TOP", "first_code_line", "install", "threshold_from_env"]
