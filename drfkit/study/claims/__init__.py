"""The paper's claims, each turned into a rule that code applies to our results.

Every row of ``results/<profile>/claims.csv`` says: the claim, the paper's figure, ours (with the
95 % t-interval over seeds of every number the verdict reads), the rule that decides the verdict,
and the verdict -- ``reproduced``, ``partly``, ``not reproduced`` (or ``not testable`` / ``better than
the paper's parity`` where the rule says so) -- computed here, never written by hand. Each rule is
written so that it can fail: it tests what the paper claims, on the data that can show it.

* ``verdicts``   -- the verdicts and what every rule shares (seed intervals, summary cells);
* ``accuracy``   -- C1-C5, accuracy and intervals in and out of distribution;
* ``efficiency`` -- C6, the cost of the uncertainty, and C7, Kalman-gain gating on its threshold sweep;
* ``mechanism``  -- F1 and F2, the method's premise (the filter filters, the state coasts);
* ``table``      -- every claim listed once (``CLAIMS``), claims.csv (``upsert``) and claims.md;
* ``judge``      -- every claim judged from a profile's tables (what the notebooks call after writing
  them, and ``python -m drfkit claims --profile <profile>``); imported by name, not re-exported here.
"""
from __future__ import annotations

from drfkit.study.claims.accuracy import *  # noqa: F401,F403
from drfkit.study.claims.accuracy import __all__ as _accuracy
from drfkit.study.claims.efficiency import *  # noqa: F401,F403
from drfkit.study.claims.efficiency import __all__ as _efficiency
from drfkit.study.claims.mechanism import *  # noqa: F401,F403
from drfkit.study.claims.mechanism import __all__ as _mechanism
from drfkit.study.claims.table import *  # noqa: F401,F403
from drfkit.study.claims.table import __all__ as _table
from drfkit.study.claims.verdicts import *  # noqa: F401,F403
from drfkit.study.claims.verdicts import __all__ as _verdicts

__all__ = [*_verdicts, *_accuracy, *_efficiency, *_mechanism, *_table]
