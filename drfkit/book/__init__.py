"""Layer 7, book: running the book: notebook start-up (``runtime``), the papermill runner
(``pipeline``), the Dask training grid (``grid``), the run manifest (``manifest``), cached
measurements (``measurements``), the training budget (``budget``), and the commands that
reach the grid or the report (``train_runs``, ``regime_map``). ``python -m drfkit`` lists every
command. Imports every layer below.

The modules are re-exported by name (``from drfkit.book import budget``), loaded on first use;
inside drfkit, import from the defining module (``from drfkit.book.budget import ...``).
"""
from __future__ import annotations

import importlib

__all__ = ['budget', 'grid', 'manifest', 'measurements', 'pipeline', 'regime_map', 'runtime', 'train_runs']


def __getattr__(name: str):
    if name in __all__:
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
