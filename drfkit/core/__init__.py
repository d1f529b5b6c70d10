"""Layer 1, core: the differentiable Kalman filter (``filter``) and the uncertainty metrics on
arrays (``metrics``: MAE, PICP, MPIW, NLL, CRPS, calibration, rank correlation, seed intervals).
Imports only ``drfkit.util``.

The modules are re-exported by name (``from drfkit.core import filter``), loaded on first use;
inside drfkit, import from the defining module (``from drfkit.core.filter import ...``).
"""
from __future__ import annotations

from drfkit.util.lazy import lazy_modules

__all__ = ['filter', 'metrics']

__getattr__ = lazy_modules(__name__, __all__)
