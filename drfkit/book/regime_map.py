"""``python -m drfkit regime``: the noise-regime map of a profile (``drfkit.study.regime``) trained,
evaluated and written as tables and a figure, as notebook 02 writes them (``write_outputs``).
Here, in the book layer, because it writes through ``drfkit.report``.
"""
from __future__ import annotations

import pandas as pd

from drfkit.report.figures import plot_regime
from drfkit.report.writers import save_figure, save_table
from drfkit.study.params import for_command
from drfkit.study.regime import profile_map, regime_summary


def main(argv: list[str] | None = None) -> int:
    """``python -m drfkit regime --profile paper``: train what the profile's regime map misses
    (one thread), evaluate it, write its tables and figure (as notebook 02 does) and print the
    seed-mean summary."""
    import argparse

    import torch

    parser = argparse.ArgumentParser(description=main.__doc__.splitlines()[0])
    parser.add_argument("--profile", default="paper")
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args(argv)
    P = for_command("02_pendulum_dynamics", args.profile)
    if P is None:
        return 2
    torch.set_num_threads(args.threads)
    import matplotlib

    matplotlib.use("Agg")  # a command writes the figure, it shows nothing
    table = profile_map(P, progress=True)
    summary = write_outputs(P, table)
    with pd.option_context("display.width", 200, "display.max_columns", 30, "display.precision", 4):
        print(summary.to_string(index=False))
    return 0


def write_outputs(P, table: pd.DataFrame) -> pd.DataFrame:
    """tables/pendulum_regime_map.csv, tables/pendulum_regime_summary.csv and
    figures/pendulum_regime_map.png of a profile; returns the summary."""
    summary = regime_summary(table)
    save_table(P.profile, "pendulum_regime_map", table)
    save_table(P.profile, "pendulum_regime_summary", summary)
    save_figure(P.profile, "pendulum_regime_map", plot_regime(table, P.pendulum.models))
    return summary


if __name__ == "__main__":
    raise SystemExit(main())
