"""Layer 1, core: the differentiable Kalman filter (``filter``) and the uncertainty metrics on
arrays (``metrics``: MAE, PICP, MPIW, NLL, CRPS, calibration, rank correlation, seed intervals).
Imports only ``drfkit.util``.

The modules are re-exported by name (``from drfkit.core import filter``), loaded on first use;
inside drfkit, import from the defining module (``from drfkit.core.filter import ...``).
"""
from __future__ import annotations

import importlib

__all__ = ['filter', 'metrics']


def __getattr__(name: str):
    if name in __all__:
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
