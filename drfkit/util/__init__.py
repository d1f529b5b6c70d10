"""Layer 0, util: atomic files and caches (``io``), where things live (``paths``), progress in the
terminal (``progress``), threads, seeds and device (``device``). Imports no other drfkit module.

The modules are re-exported by name (``from drfkit.util import device``), loaded on first use;
inside drfkit, import from the defining module (``from drfkit.util.device import ...``).
"""
from __future__ import annotations

import importlib

__all__ = ['device', 'io', 'paths', 'progress']


def __getattr__(name: str):
    if name in __all__:
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
