"""Layer 4, methods: what is done to models and arrays, with explicit arguments, never the
profile: training (``train``, ``run_config``, ``objectives``, ``protocols``), predictions with uncertainty
(``uncertainty``, ``predictions``), Kalman-gain gating (``gating``), mechanism diagnostics
(``diagnostics``), true-physics references (``references``), timing (``timing``). Imports util, core,
data and models.

The modules are re-exported by name (``from drfkit.methods import diagnostics``), loaded on first use;
inside drfkit, import from the defining module (``from drfkit.methods.diagnostics import ...``).
"""
from __future__ import annotations

from drfkit.util.lazy import lazy_modules

__all__ = ['diagnostics', 'gating', 'objectives', 'predictions', 'protocols', 'references', 'run_config', 'timing',
           'train', 'uncertainty']

__getattr__ = lazy_modules(__name__, __all__)
