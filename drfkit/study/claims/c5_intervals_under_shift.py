"""Claim C5: under shift, the DRF keeps a higher PICP with a narrower MPIW than the baselines, on both
studies (the paper's pedestrian and pendulum figures at their out-of-distribution levels)."""
from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from drfkit.study.claims.monoloco import MATCHED_MONOLOCO, PUBLISHED_MONOLOCO
from drfkit.study.claims.table import CLAIMS, Claim, Rows
from drfkit.study.claims.verdicts import (CURVE_RULE, SATURATED_PICP, collapsed_curve, collapsed_text, curve_shares,
                                          curve_verdict, not_recalibrated, rows_of, share_text)


def c5_intervals_under_shift(curves: pd.DataFrame, conditions: list[tuple[str, float]],
                             baselines: dict[str, list[str]]) -> dict[str, Any]:
    """Under shift, DRF keeps a higher PICP with a narrower MPIW: judged over the PICP–MPIW curves
    (one point per inference dropout rate), as C2 is.

    curves: rows with columns study, model, noise, picp, mpiw (and picp_lo, picp_hi; one per dropout
    rate; a single rate per model reduces to comparing points); conditions: (study, noise) pairs out
    of distribution; baselines: study -> models. A comparison where every PICP of both is saturated
    is not informative and left out.
    """
    shares, parts = {}, []
    for study, lv in conditions:
        sub = curves[(curves["study"] == study) & np.isclose(curves["noise"].astype(float), lv)]
        for base in baselines[study]:
            if collapsed_curve(sub):
                parts.append(f"{study}@{lv} vs {base}: not testable, {collapsed_text(sub, base)}")
                continue
            pair = sub[sub["model"].isin(["drf", base])]
            if len(pair) and bool((pair["picp"] >= SATURATED_PICP).all()):
                parts.append(f"{study}@{lv} vs {base}: not informative (every PICP >= {100 * SATURATED_PICP:g}%)")
                continue
            shares[(study, lv, base)] = curve_shares(sub, base)
            parts.append(f"{study}@{lv} vs {base}: {share_text(*shares[(study, lv, base)])}")
    return {"id": "C5", "claim": "Under shift, DRF keeps a higher PICP with a narrower MPIW than the baselines",
            "paper": "pedestrians p 0.025/0.05: DRF's curve above all; pendulum at 0.75 likewise",
            "ours": "share of DRF curve points above the baseline's curve at equal MPIW: " + "; ".join(parts),
            "rule": "over the PICP–MPIW curves (inference dropout rates), at each out-of-distribution level; on the "
                    "pedestrians against Monoloco fed the DRF family's inputs (as C3 and C4; one point at its own "
                    "rate); " + CURVE_RULE,
            "verdict": curve_verdict(shares)}


def judge(ood) -> Rows:
    """C5 per protocol over every study of notebook 04 (``judge.OodTables``), each study's models of that
    protocol (or of the paper's, for a study that does not train it) at its shifted levels."""
    rows: Rows = []
    baselines = dict(ood.baselines)
    if ood.matched is not None and PUBLISHED_MONOLOCO in baselines.get("pedestrians", []):
        # as C3 and C4: Monoloco fed the DRF family's inputs (one point per level, its own dropout rate)
        baselines["pedestrians"] = [MATCHED_MONOLOCO if b == PUBLISHED_MONOLOCO else b for b in baselines["pedestrians"]]
    for protocol, judged in ood.by_protocol():
        if ood.curves is None:
            rows.append((protocol, not_recalibrated(c5_intervals_under_shift(
                pd.DataFrame(columns=["study", "model", "noise", "picp", "mpiw"]), [], baselines))))
            continue
        shift = pd.concat([rows_of(ood.curves, s, pr) for s, pr in judged], ignore_index=True)
        if ood.matched is not None and any(s == "pedestrians" for s, _ in judged):
            shift = pd.concat([shift, ood.matched.assign(study="pedestrians", protocol=protocol)], ignore_index=True)
        conditions = [(s, lv) for s, _ in judged for lv in ood.shifted[s]]
        rows.append((protocol, c5_intervals_under_shift(shift, conditions, baselines)))
    return rows


CLAIM = CLAIMS.register("C5", Claim(
    "C5", "04_ood_noise_evaluation", "notebook 04, both studies", "The paper's figures, redrawn",
    ("ood_all_metrics.csv", "ood_picp_mpiw_recalibrated.csv"), ("pendulum_picp_mpiw.png", "pedestrians_picp_mpiw.png"), judge,
    reads="ood"))

__all__ = ["c5_intervals_under_shift"]
