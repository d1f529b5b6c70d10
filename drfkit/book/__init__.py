"""Layer 7, book: running the book: notebook start-up (``runtime``), the papermill runner
(``pipeline``), the Dask training grid (``grid``), the run manifest (``manifest``), cached
measurements (``measurements``), the training budget (``budget``) and the regime map's writer
(``regime_map``). Imports every layer below; their command lines are ``drfkit.cli``'s.

The modules are re-exported by name (``from drfkit.book import budget``), loaded on first use;
inside drfkit, import from the defining module (``from drfkit.book.budget import ...``).
"""
from __future__ import annotations

from drfkit.util.lazy import lazy_modules

__all__ = ['budget', 'grid', 'manifest', 'measurements', 'pipeline', 'regime_map', 'runtime']

__getattr__ = lazy_modules(__name__, __all__)
