"""Layer 5, study: the book's studies, the readers of the profile ``P`` (with ``drfkit.book``): the
study registry (``registry``, its entries ``entry.Study``), the profile's schema (``schema``), the typed
profile made from it (``profile``), loading and validating a profile (``params``), each
study's data and runs (``pendulum_runs``, ``pedestrian_runs``), naming, training and loading them
(``studies``), evaluation over seeds (``evaluate``), the dynamics study (``dynamics``), the
protocol ablation (``ablation``), the noise-regime map (``regime``), gating on test data
(``gating_study``), the inference benchmark (``bench``), the simulator's statistics for a profile
(``sim_stats``), the paper's numbers (``paper``) and the claims' verdicts (``claims``).
Imports every layer below.

The modules are re-exported by name (``from drfkit.study import ablation``), loaded on first use;
inside drfkit, import from the defining module (``from drfkit.study.ablation import ...``).
"""
from __future__ import annotations

from drfkit.util.lazy import lazy_modules

__all__ = ['ablation', 'bench', 'claims', 'dynamics', 'entry', 'evaluate', 'gating_study', 'paper', 'params',
           'pedestrian_runs', 'pendulum_runs', 'profile', 'regime', 'registry', 'schema', 'sim_stats', 'studies']

__getattr__ = lazy_modules(__name__, __all__)
