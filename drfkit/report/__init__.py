"""Layer 6, report: presentation: every plot, a model's label and colour (``figures``), tables
and figures written atomically, the comparison with the paper, the README's results section
and report.md (``writers``). Imports every layer below.

The modules are re-exported by name (``from drfkit.report import figures``), loaded on first use;
inside drfkit, import from the defining module (``from drfkit.report.figures import ...``).
"""
from __future__ import annotations

from drfkit.util.lazy import lazy_modules

__all__ = ['figures', 'writers']

__getattr__ = lazy_modules(__name__, __all__)
