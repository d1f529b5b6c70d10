"""``python -m drfkit regime``: the noise-regime map of a profile (``drfkit.study.regime``) trained,
evaluated and written as tables and a figure, as notebook 02 writes them (``write_outputs``).
Here, in the book layer, because it writes through ``drfkit.report``.
"""
from __future__ import annotations

import pandas as pd

from drfkit.report.figures import plot_regime
from drfkit.report.writers import save_figure, save_table
from drfkit.study.regime import regime_summary


def write_outputs(P, table: pd.DataFrame) -> pd.DataFrame:
    """tables/pendulum_regime_map.csv, tables/pendulum_regime_summary.csv and
    figures/pendulum_regime_map.png of a profile; returns the summary."""
    summary = regime_summary(table)
    save_table(P.profile, "pendulum_regime_map", table)
    save_table(P.profile, "pendulum_regime_summary", summary)
    save_figure(P.profile, "pendulum_regime_map", plot_regime(table, P.pendulum.models))
    return summary
