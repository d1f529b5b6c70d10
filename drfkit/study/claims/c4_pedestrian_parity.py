"""Claim C4: on the pedestrians, in distribution (p 0.01), the DRF's MAE is comparable to Monoloco's
(``drfkit.study.paper.PEDESTRIAN_MAE``: equal, 2.56 m both)."""
from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd

from drfkit.study import paper
from drfkit.study.claims.monoloco import MATCHED_MONOLOCO, PUBLISHED_MONOLOCO, monoloco_name
from drfkit.study.claims.table import CLAIMS, Claim, Rows
from drfkit.study.claims.verdicts import (BETTER, INCONCLUSIVE, NOMINAL_PAIRING, NOT, NOT_TESTABLE, PARTLY, REPRODUCED,
                                          at_levels, at_most, cell, fmt, fmt_interval, rows_of, seed_interval)

PARITY_BAND = 0.10
PARTLY_MAX = 0.25  # partly: the DRF higher than the band allows, by at most a quarter


def parity_rule(band: float = PARITY_BAND, partly_max: float = PARTLY_MAX) -> str:
    """C4's rule in words, written from the constants ``parity_verdict`` applies (one place for both)."""
    b, q = f"{100 * band:g} %", f"{100 * partly_max:g} %"
    return (f"comparable = within {b} either way (the paper reports equal MAE; {b} is the book's band: about half "
            "the 18 % the paper calls an improvement in C3), against Monoloco fed the DRF family's inputs (as "
            "published it is a second, unjudged comparison); an equivalence test on the per-seed relative difference "
            f"MAE_DRF / MAE_Monoloco - 1 ({NOMINAL_PAIRING}): reproduced: its 95 % interval lies inside +/- {b}; "
            f"better than the paper's parity: the interval lies below -{b} (a different finding, not parity); partly: "
            f"the interval lies above +{b} and at most +{q} (the DRF higher, by at most a quarter); not reproduced: "
            f"the interval lies above +{b} and reaches beyond +{q}; inconclusive: otherwise (the interval straddles a "
            "band's edge, or is too wide to say equal or not); an interval that excludes 0 also says which model is "
            "the more accurate; without per-seed rows the seed means decide; not testable without that Monoloco. "
            "Beside it, the paper's other in-distribution statement (the DRF below no_dynamics and the LSTM: 2.56 vs "
            "3.42 / 2.88 m), paired by seed: 'holds' where the interval of each difference lies below 0")


def relative_difference(by_seed: pd.DataFrame, a: str, b: str, noise: float) -> tuple[float, float, float]:
    """Per seed MAE_a / MAE_b - 1 at ``noise`` (paired by seed), mean and 95 % t-interval."""
    rows = by_seed[np.isclose(by_seed["noise"].astype(float), noise)]
    table = rows.pivot_table(index="seed", columns="model", values="mae")
    if a not in table or b not in table:
        return math.nan, math.nan, math.nan
    return seed_interval((table[a] / table[b] - 1).dropna())


def c4_in_distribution_parity(mae: pd.DataFrame, noise: float = 0.01, by_seed: pd.DataFrame | None = None,
                              comparator: str = MATCHED_MONOLOCO, note: str = "") -> dict[str, Any]:
    """DRF's in-distribution MAE against ``comparator``'s (default: the input-matched Monoloco), from a
    summary ``mae``; ``by_seed`` (per-seed rows of both) adds the interval of the paired relative
    difference; ``note`` follows the comparator's number. Monoloco as published, when in ``mae``, is
    reported beside it."""
    name = monoloco_name
    row = {"id": "C4", "claim": "Pedestrians in distribution (p 0.01): DRF comparable to Monoloco",
           "paper": f"{paper.PEDESTRIAN_MAE[0.01]['drf']:.2f} m vs {paper.PEDESTRIAN_MAE[0.01]['monoloco']:.2f} m",
           "rule": parity_rule()}
    d = cell(mae, "drf", "mae", noise=noise)
    try:
        m = cell(mae, comparator, "mae", noise=noise)
    except KeyError:
        return {**row, "ours": f"DRF {fmt(mae, 'drf', 'mae', 3, noise=noise)} m; {name(comparator)} not evaluated "
                               "(notebook 03)", "verdict": NOT_TESTABLE}
    rel = (d - m) / m
    paired = relative_difference(by_seed, "drf", comparator, noise) if by_seed is not None else (rel, math.nan, math.nan)
    verdict = parity_verdict(rel, paired)
    ours = (f"DRF {fmt(mae, 'drf', 'mae', 3, noise=noise)} m vs {name(comparator)} "
            f"{fmt(mae, comparator, 'mae', 3, noise=noise)} m{note} ({100 * rel:+.1f}%"
            + ("" if math.isnan(paired[1]) else f"; paired by seed {fmt_interval(paired, 100, 1, True, '%')}") + ")")
    if not math.isnan(paired[1]) and (paired[1] > 0 or paired[2] < 0):  # the interval excludes 0: say which is better
        better, worse = ("DRF", name(comparator)) if paired[2] < 0 else (name(comparator), "DRF")
        ours += f"; the interval excludes 0: {better} is more accurate than {worse}"
    if comparator != PUBLISHED_MONOLOCO and (mae["model"] == PUBLISHED_MONOLOCO).any():
        p = cell(mae, PUBLISHED_MONOLOCO, "mae", noise=noise)
        ours += (f"; second comparison, not judged: {name(PUBLISHED_MONOLOCO)} "
                 f"{fmt(mae, PUBLISHED_MONOLOCO, 'mae', 3, noise=noise)} m ({100 * (d - p) / p:+.1f}%)")
    if by_seed is not None:
        ours += "; " + ordering_text(by_seed, noise)
    return {**row, "ours": ours, "verdict": verdict}


def parity_verdict(rel: float, paired: tuple[float, float, float], partly_max: float = PARTLY_MAX) -> str:
    """The equivalence test of C4's rule on the relative difference ``rel`` (seed means) and its paired interval
    ``paired`` (mean, lo, hi; NaN bounds: the seed means decide)."""
    lo, hi = paired[1], paired[2]
    if math.isnan(lo):
        return (REPRODUCED if at_most(abs(rel), PARITY_BAND) else BETTER if rel < 0
                else PARTLY if at_most(rel, partly_max) else NOT)
    if at_most(-PARITY_BAND, lo) and at_most(hi, PARITY_BAND):
        return REPRODUCED
    if hi < -PARITY_BAND:
        return BETTER
    if PARITY_BAND < lo and at_most(hi, partly_max):
        return PARTLY
    if partly_max < lo:
        return NOT
    if PARITY_BAND < lo:
        return NOT
    return INCONCLUSIVE


def ordering_text(by_seed: pd.DataFrame, noise: float) -> str:
    """The paper's in-distribution ordering (DRF below no_dynamics and the LSTM), paired by seed."""
    parts, holds = [], []
    for base in ("no_dynamics", "lstm"):
        diff = relative_difference(by_seed, "drf", base, noise)
        if math.isnan(diff[0]):
            continue
        holds.append(not math.isnan(diff[2]) and diff[2] < 0)
        parts.append(f"vs {base} {fmt_interval(diff, 100, 1, True, '%')}")
    if not parts:
        return "the paper's ordering (DRF below no_dynamics and the LSTM) not evaluated"
    word = "holds" if all(holds) and len(holds) == 2 else "does not hold beyond the seeds' intervals"
    return f"the paper's in-distribution ordering (DRF below no_dynamics and the LSTM) {word}: DRF " + ", ".join(parts)


def judge(ood) -> Rows:
    """C4 per protocol at the profile's training level (``pedestrians.train_p``) on notebook 04's pedestrian
    summary, with notebook 03's input-matched Monoloco (``judge.OodTables``)."""
    rows: Rows = []
    for protocol, by_seed in ood.pedestrian_seeds():
        mae = at_levels(rows_of(ood.summary, "pedestrians", protocol), ood.paper_noise["pedestrians"])
        if ood.matched is not None:
            mae = pd.concat([mae, ood.matched], ignore_index=True)
        rows.append((protocol, c4_in_distribution_parity(mae, ood.P.pedestrians.train_p, by_seed=by_seed,
                                                         note=ood.matched_note)))
    return rows


CLAIM = CLAIMS.register("C4", Claim(
    "C4", "04_ood_noise_evaluation", "notebook 04, pedestrians", "Claims C1–C5, with computed verdicts",
    ("ood_all_metrics.csv", "pedestrians_monoloco_inputs.csv"), ("pedestrians_mae.png",), judge, reads="ood",
    simulated=True))

__all__ = ["PARITY_BAND", "PARTLY_MAX", "parity_rule", "c4_in_distribution_parity", "ordering_text", "parity_verdict", "relative_difference"]
