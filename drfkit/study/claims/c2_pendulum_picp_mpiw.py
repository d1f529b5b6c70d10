"""Claim C2: on the pendulum, the DRF's PICP–MPIW curve (one point per inference dropout rate) lies
above no_dynamics' and the LSTM's (``drfkit.study.paper.PENDULUM_PICP_MPIW``)."""
from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from drfkit.study import paper
from drfkit.study.claims.standins import tag, variants
from drfkit.study.claims.table import CLAIMS, Claim, Rows
from drfkit.study.claims.verdicts import (CURVE_RULE, SATURATED_PICP, collapsed_curve, collapsed_text, curve_shares,
                                          curve_verdict, not_recalibrated, rows_of, share_text)


def c2_pendulum_picp_mpiw(curve: pd.DataFrame, levels=(0.5, 0.75)) -> dict[str, Any]:
    """DRF's PICP–MPIW curve lies above each baseline's (higher PICP at equal MPIW).
    curve: summary rows (model, noise, mpiw, picp, picp_lo, picp_hi), one per dropout rate."""
    shares, saturated, collapsed = {}, [], []
    for lv in levels:
        sub = curve[np.isclose(curve["noise"], lv)]
        for base in ("lstm", "no_dynamics"):
            if collapsed_curve(sub):
                collapsed.append(f"vs {base}@{lv}: {collapsed_text(sub, base)}")
                continue
            pair = sub[sub["model"].isin(["drf", base])]
            if len(pair) and bool((pair["picp"] >= SATURATED_PICP).all()):
                saturated.append(f"vs {base}@{lv}")  # every interval covers: coverage cannot rank them
                continue
            shares[(lv, base)] = curve_shares(sub, base)
    ours = ", ".join(f"vs {b}@{lv}: {share_text(*s)}" for (lv, b), s in shares.items())
    if saturated:
        ours += ("; " if ours else "") + "not informative (every PICP >= " + f"{100 * SATURATED_PICP:g}%): " \
            + ", ".join(saturated)
    if collapsed:
        ours += ("; " if ours else "") + "not testable, " + "; ".join(collapsed)
    return {"id": "C2", "claim": "Pendulum: DRF's PICP–MPIW curve dominates no_dynamics and LSTM",
            "paper": "DRF " + " ".join(f"({m:.2f}, {p:g}%)" for m, p in paper.PENDULUM_PICP_MPIW["drf"])
                     + " above both baselines",
            "ours": "share of DRF points above the baseline curve: " + ours,
            "rule": "over the PICP–MPIW curves (inference dropout rates) at every level; " + CURVE_RULE,
            "verdict": curve_verdict(shares)}


def judge(ood) -> Rows:
    """C2 per protocol on notebook 04's pendulum curves (``judge.OodTables``)."""
    if ood.curves is None:
        return [(protocol, not_recalibrated(c2_pendulum_picp_mpiw(_EMPTY_CURVE)))
                for protocol, judged in ood.by_protocol() if ("pendulum", protocol) in judged]
    return [(cell_, tag(c2_pendulum_picp_mpiw(curve, ood.paper_noise["pendulum"]), kind))
            for protocol, judged in ood.by_protocol() if ("pendulum", protocol) in judged
            for cell_, kind, (curve,) in variants(protocol, ood.judged_drfs("pendulum"),
                                                  rows_of(ood.curves, "pendulum", protocol))]


_EMPTY_CURVE = pd.DataFrame(columns=["model", "noise", "mpiw", "picp", "picp_lo", "picp_hi"])


CLAIM = CLAIMS.register("C2", Claim(
    "C2", "04_ood_noise_evaluation", "notebook 04, pendulum", "The paper's figures, redrawn", ("ood_picp_mpiw_recalibrated.csv",),
    ("pendulum_picp_mpiw.png",), judge, reads="ood"))

__all__ = ["c2_pendulum_picp_mpiw"]
