"""The dissection's open-loop figure (``drfkit.study.dissection.dissect_filters``' horizons table)."""
from __future__ import annotations

import pandas as pd

from drfkit.methods.dissection import OPEN_LOOP_MAX
from drfkit.report.figures import _legend, color, label, new_figure


def plot_open_loop(horizons: pd.DataFrame):
    """Per protocol (a column of panels; one panel without a 'protocol' column), seed means by horizon h:
    top, each filter's open-loop error with its gain forced to 0 (solid), the same filter as it runs through the
    blackout (dotted) and zero-order hold of the last estimate (dashed grey, mean over the filters), the 0.10
    line; bottom, the gap's MAE with only its first k frames clamped and the own gain after."""
    frame = horizons if "protocol" in horizons else horizons.assign(protocol="")
    protocols = list(dict.fromkeys(frame["protocol"]))
    fig, axes = new_figure(len(protocols), 2, width=4.2, height=3.0)
    for col, protocol in enumerate(protocols):
        rows = frame[frame["protocol"] == protocol]
        top, bottom = axes[0][col], axes[1][col]
        means = rows.groupby(["model", "h"], sort=False).mean(numeric_only=True).reset_index()
        for kind, run in means.groupby("model", sort=False):
            top.plot(run["h"], run["mae_clamped"], color=color(kind), label=f"{label(kind)}, gain 0")
            top.plot(run["h"], run["mae_as_run"], color=color(kind), ls=":")
            bottom.plot(run["h"], run["mae_gap_partial"], color=color(kind), marker=".", label=label(kind))
        held = means.groupby("h")["mae_hold"].mean()
        top.plot(held.index, held.to_numpy(), color="gray", ls="--", label="hold the last estimate")
        top.axhline(OPEN_LOOP_MAX, color="black", lw=0.6)
        top.set_yscale("log")
        top.set_xlabel("horizon h (frames without an update)")
        top.set_ylabel("MAE (cos θ, sin θ), log scale")
        top.set_title(f"{protocol} protocol: open loop (dotted: as it runs)" if protocol else "open loop")
        bottom.set_xlabel("k: gap frames clamped, then the model's own gain")
        bottom.set_ylabel("MAE over the 15 gap frames")
        bottom.set_yscale("log")
        _legend(top)
        _legend(bottom)
    return fig


__all__ = ["plot_open_loop"]
