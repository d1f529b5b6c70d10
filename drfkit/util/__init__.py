"""Layer 0, util: atomic files and caches (``io``), where things live (``paths``), progress in the
terminal (``progress``), threads, seeds and device (``device``). Imports no other drfkit module.

The modules are re-exported by name (``from drfkit.util import device``), loaded on first use;
inside drfkit, import from the defining module (``from drfkit.util.device import ...``).
"""
from __future__ import annotations

from drfkit.util.lazy import lazy_modules

__all__ = ['device', 'io', 'lazy', 'paths', 'progress']

__getattr__ = lazy_modules(__name__, __all__)
