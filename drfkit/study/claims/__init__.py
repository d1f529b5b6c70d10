"""The paper's claims, each turned into a rule that code applies to our results.

Every row of ``results/<profile>/claims.csv`` says: the claim, the paper's figure, ours (with the
95 % t-interval over seeds of every number the verdict reads), the rule that decides the verdict,
and the verdict -- ``reproduced``, ``partly``, ``not reproduced`` (or ``not testable`` / ``better than
the paper's parity`` where the rule says so) -- computed here, never written by hand. Each rule is
written so that it can fail: it tests what the paper claims, on the data that can show it.

A claim is one module: its rule (tables -> a claims row), how it is judged from a profile's tables,
and its ``Claim`` (where its evidence lies), registered in ``CLAIMS`` when the module is imported.
Adding one is one file, here or an extension (``drfkit.util.registry``); ``judge`` finds it there.

* ``c1_pendulum_mae_ordering`` ... ``c5_intervals_under_shift`` -- C1-C5, accuracy and intervals in and
  out of distribution; ``c6_uncertainty_speedup`` -- C6, the cost of the uncertainty;
  ``c7a_gating_pendulum``, ``c7b_gating_pedestrians`` -- C7, Kalman-gain gating on its threshold sweep;
  ``f1_filter_mechanism``, ``f2_blackout_coasting`` -- the method's premise (the filter filters, the
  state coasts);
* ``verdicts``   -- the verdicts and what every rule shares (seed intervals, summary cells, curves);
* ``standins`` -- C1, C2, F1 and F2 judged again for another DRF in the paper's DRF's place (own rows);
* ``monoloco``, ``efficiency``, ``dynamics_table`` -- what C3/C4, C7a/C7b and F1/F2 share; ``mechanism``
  -- the premise F1 and F2 check, and what a protocol's DRF sees in training;
* ``table``      -- the ``Claim`` registry (``CLAIMS``), claims.csv (``upsert``) and claims.md;
* ``judge``      -- every registered claim judged from a profile's tables (what the notebooks call after
  writing them, and ``python -m drfkit claims --profile <profile>``); imported by name, not re-exported
  here, because building a claim's inputs reads the study registry, which the rules do not need.

``CLAIM_SOURCES``, ``CLAIM_EVIDENCE`` and ``PEDESTRIAN_CLAIMS`` are views of ``CLAIMS`` made when read.
"""
from __future__ import annotations

from drfkit.study.claims.verdicts import *  # noqa: F401,F403
from drfkit.study.claims.verdicts import __all__ as _verdicts
from drfkit.study.claims.table import *  # noqa: F401,F403
from drfkit.study.claims.table import VIEWS, __all__ as _table
from drfkit.study.claims.monoloco import *  # noqa: F401,F403
from drfkit.study.claims.monoloco import __all__ as _monoloco
# the paper's claims, in the order of the claims table's rows (each registers itself when imported)
from drfkit.study.claims.c1_pendulum_mae_ordering import *  # noqa: F401,F403
from drfkit.study.claims.c1_pendulum_mae_ordering import __all__ as _c1
from drfkit.study.claims.c2_pendulum_picp_mpiw import *  # noqa: F401,F403
from drfkit.study.claims.c2_pendulum_picp_mpiw import __all__ as _c2
from drfkit.study.claims.c3_pedestrian_ood_gain import *  # noqa: F401,F403
from drfkit.study.claims.c3_pedestrian_ood_gain import __all__ as _c3
from drfkit.study.claims.c4_pedestrian_parity import *  # noqa: F401,F403
from drfkit.study.claims.c4_pedestrian_parity import __all__ as _c4
from drfkit.study.claims.c5_intervals_under_shift import *  # noqa: F401,F403
from drfkit.study.claims.c5_intervals_under_shift import __all__ as _c5
from drfkit.study.claims.c6_uncertainty_speedup import *  # noqa: F401,F403
from drfkit.study.claims.c6_uncertainty_speedup import __all__ as _c6
from drfkit.study.claims.efficiency import *  # noqa: F401,F403
from drfkit.study.claims.efficiency import __all__ as _efficiency
from drfkit.study.claims import c7a_gating_pendulum, c7b_gating_pedestrians  # noqa: F401,E402
from drfkit.study.claims.mechanism import *  # noqa: F401,F403
from drfkit.study.claims.mechanism import __all__ as _mechanism
from drfkit.study.claims.f1_filter_mechanism import *  # noqa: F401,F403
from drfkit.study.claims.f1_filter_mechanism import __all__ as _f1
from drfkit.study.claims.f2_blackout_coasting import *  # noqa: F401,F403
from drfkit.study.claims.f2_blackout_coasting import __all__ as _f2

__all__ = [*_verdicts, *_table, *_monoloco, *_c1, *_c2, *_c3, *_c4, *_c5, *_c6, *_efficiency, *_mechanism, *_f1, *_f2,
           *VIEWS]


def __getattr__(name: str):
    if name in VIEWS:
        return VIEWS[name]()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
