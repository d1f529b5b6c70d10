"""Claims C1-C5: accuracy and intervals of the DRF against its baselines, in and out of distribution.

Input frames are the outputs of ``drfkit.study.evaluate.summarise`` (one row per model and condition
with ``<metric>``, ``<metric>_ci``, ``<metric>_lo``, ``<metric>_hi``) or per-seed rows (model, seed,
noise, metric). Every number a verdict reads is shown with its 95 % t-interval over seeds.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd

from drfkit.study import paper
from drfkit.study.claims.verdicts import (BETTER, NOT, NOT_TESTABLE, PARTLY, REPRODUCED, SATURATED_PICP, at_most,
                                          cell, fmt, fmt_interval, paired_difference, seed_interval)

# The Monoloco the pedestrian claims are judged against: the same network, loss and schedule as
# published, fed the DRF family's inputs (notebook 03). Monoloco as published reads a different input
# (every keypoint centred on the box around all 17, placeholders included, no confidences), so a gap to
# it mixes the network with the input; it stays in each row as a second, labelled comparison.
MATCHED_MONOLOCO = "monoloco_detected_inputs"
PUBLISHED_MONOLOCO = "monoloco"
MONOLOCO_NAMES = {MATCHED_MONOLOCO: "Monoloco on the DRF family's inputs", PUBLISHED_MONOLOCO: "Monoloco as published"}


# ------------------------------------------------------------------------------ C1
def c1_pendulum_mae_ordering(mae: pd.DataFrame, levels=(0.5, 0.75), by_seed: pd.DataFrame | None = None
                             ) -> dict[str, Any]:
    """DRF MAE < LSTM < no_dynamics at each pendulum noise level.

    ``by_seed`` (one row per model, seed, noise with 'mae'): "reproduced" needs each step of the
    ordering to hold beyond its seeds' interval (paired by seed: the upper bound of MAE_a - MAE_b
    below 0); orderings that hold in the seed means only are "partly". Without it (or with one
    seed) the means decide, and "reproduced" is not given: the evidence cannot exclude seed noise."""
    full, drf_best, beyond = [], [], []
    ours = []
    for lv in levels:
        m = {k: cell(mae, k, "mae", noise=lv) for k in ("drf", "lstm", "no_dynamics")}
        full.append(m["drf"] < m["lstm"] < m["no_dynamics"])
        drf_best.append(m["drf"] < min(m["lstm"], m["no_dynamics"]))
        if by_seed is not None:
            steps = [paired_difference(by_seed, a, b, lv) for a, b in (("drf", "lstm"), ("lstm", "no_dynamics"))]
            beyond.append(all(hi < 0 for _, _, hi in steps))  # NaN (one seed) compares False
        else:
            beyond.append(False)
        ours.append(f"@{lv}: DRF {fmt(mae, 'drf', 'mae', 3, noise=lv)}, LSTM {fmt(mae, 'lstm', 'mae', 3, noise=lv)}, "
                    f"no_dyn {fmt(mae, 'no_dynamics', 'mae', 3, noise=lv)}")
    verdict = REPRODUCED if all(beyond) else PARTLY if any(full) or all(drf_best) else NOT
    return {"id": "C1", "claim": "Pendulum MAE: DRF < LSTM < no_dynamics at max noise 0.5 and 0.75",
            "paper": "; ".join(f"@{lv:g}: " + " < ".join(f"{row[k]:.4f}" for k in ("drf", "lstm", "no_dynamics"))
                               for lv, row in paper.PENDULUM_MAE.items()),
            "ours": "; ".join(ours),
            "rule": "reproduced: at every level each step of the ordering holds beyond the seeds' 95 % interval "
                    "of the paired MAE difference (seeds differ in initialisation only, so a gap inside that "
                    "interval could be seed noise); partly: the seed-mean ordering holds at one level, or DRF "
                    "has the lowest mean at every level; else not reproduced",
            "verdict": verdict}


# ------------------------------------------------------------------------------ C2, C5
def dominance(curve: pd.DataFrame, model: str, baseline: str, x: str = "mpiw", y: str = "picp",
              y_model: str | None = None, y_base: str | None = None) -> float:
    """Fraction of ``model``'s curve points (within the baseline's x-range) lying above the
    baseline's curve interpolated linearly in x. NaN if the ranges do not overlap or a column is
    missing. ``y_model`` / ``y_base`` compare other columns than ``y`` (e.g. the model's lower
    interval bound against the baseline's upper one: above beyond the seeds' intervals)."""
    ya, yb = y_model or y, y_base or y
    a = curve[curve["model"] == model].sort_values(x)
    b = curve[curve["model"] == baseline].sort_values(x)
    if ya not in a.columns or yb not in b.columns or not len(b):
        return math.nan
    inside = a[(a[x] >= b[x].min()) & (a[x] <= b[x].max())]
    if len(inside) == 0 or len(b) < 2:
        # Outside the baseline's range: above-and-left of its narrowest point also dominates.
        left = a[(a[x] <= b[x].min()) & (a[ya] >= b.loc[b[x].idxmin(), yb])]
        return float(len(left) > 0) if len(a) else math.nan
    return float(np.mean(inside[ya].to_numpy() > np.interp(inside[x], b[x], b[yb])))


def _shares(sub: pd.DataFrame, base: str) -> tuple[float, float]:
    """(share of DRF points above the baseline's curve in seed means, share above it beyond the seeds'
    95 % intervals: DRF's lower PICP bound above the baseline's upper one)."""
    return dominance(sub, "drf", base), dominance(sub, "drf", base, y_model="picp_lo", y_base="picp_hi")


def _share_text(share: float, beyond: float) -> str:
    if math.isnan(share):
        return "n/a"
    return f"{100 * share:.0f}%" + ("" if math.isnan(beyond) else f" ({100 * beyond:.0f}% beyond the seeds' intervals)")


def _curve_verdict(shares: dict) -> str:
    vals = [s for s, _ in shares.values() if not math.isnan(s)]
    if not vals:
        return NOT_TESTABLE
    beyond = [b for s, b in shares.values() if not math.isnan(s)]
    return (REPRODUCED if all(at_most(1.0, b) for b in beyond) else PARTLY if np.mean(vals) >= 0.5 else NOT)


_CURVE_RULE = ("reproduced: every DRF point lies above every baseline's curve at equal MPIW beyond the seeds' 95 % "
               "intervals (DRF's lower PICP bound above the baseline's upper bound, interpolated); partly: on "
               "average at least half of the DRF points lie above in seed means; else not reproduced; a comparison "
               f"where every PICP is >= {100 * SATURATED_PICP:g}% is left out as not informative (intervals that "
               "cover everything cannot be ranked by coverage); not testable if none is left")


def c2_pendulum_picp_mpiw(curve: pd.DataFrame, levels=(0.5, 0.75)) -> dict[str, Any]:
    """DRF's PICP–MPIW curve lies above each baseline's (higher PICP at equal MPIW).
    curve: summary rows (model, noise, mpiw, picp, picp_lo, picp_hi), one per dropout rate."""
    shares, saturated = {}, []
    for lv in levels:
        sub = curve[np.isclose(curve["noise"], lv)]
        for base in ("lstm", "no_dynamics"):
            pair = sub[sub["model"].isin(["drf", base])]
            if len(pair) and bool((pair["picp"] >= SATURATED_PICP).all()):
                saturated.append(f"vs {base}@{lv}")  # every interval covers: coverage cannot rank them
                continue
            shares[(lv, base)] = _shares(sub, base)
    ours = ", ".join(f"vs {b}@{lv}: {_share_text(*s)}" for (lv, b), s in shares.items())
    if saturated:
        ours += ("; " if ours else "") + "not informative (every PICP >= " + f"{100 * SATURATED_PICP:g}%): " \
            + ", ".join(saturated)
    return {"id": "C2", "claim": "Pendulum: DRF's PICP–MPIW curve dominates no_dynamics and LSTM",
            "paper": "DRF " + " ".join(f"({m:.2f}, {p:g}%)" for m, p in paper.PENDULUM_PICP_MPIW["drf"])
                     + " above both baselines",
            "ours": "share of DRF points above the baseline curve: " + ours,
            "rule": "over the PICP–MPIW curves (inference dropout rates) at every level; " + _CURVE_RULE,
            "verdict": _curve_verdict(shares)}


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
            pair = sub[sub["model"].isin(["drf", base])]
            if len(pair) and bool((pair["picp"] >= SATURATED_PICP).all()):
                parts.append(f"{study}@{lv} vs {base}: not informative (every PICP >= {100 * SATURATED_PICP:g}%)")
                continue
            shares[(study, lv, base)] = _shares(sub, base)
            parts.append(f"{study}@{lv} vs {base}: {_share_text(*shares[(study, lv, base)])}")
    return {"id": "C5", "claim": "Under shift, DRF keeps a higher PICP with a narrower MPIW than the baselines",
            "paper": "pedestrians p 0.025/0.05: DRF's curve above all; pendulum at 0.75 likewise",
            "ours": "share of DRF curve points above the baseline's curve at equal MPIW: " + "; ".join(parts),
            "rule": "over the PICP–MPIW curves (inference dropout rates), at each out-of-distribution level; "
                    + _CURVE_RULE,
            "verdict": _curve_verdict(shares)}


# ------------------------------------------------------------------------------ C3
def improvement(by_seed: pd.DataFrame, base: str, levels) -> tuple[float, float, float]:
    """Relative MAE improvement of DRF over ``base``: per seed, 1 - MAE_drf / MAE_base averaged
    over ``levels`` (models paired by seed: same data, their own initialisation), then the
    mean over seeds and its 95 % t-interval (NaN bounds with one seed; all NaN without ``base``).

    by_seed: one row per (model, seed, noise) with a ``mae`` column.
    """
    rows = by_seed[by_seed["noise"].apply(lambda v: any(math.isclose(v, lv) for lv in levels))]
    table = rows.pivot_table(index=["seed", "noise"], columns="model", values="mae")
    if base not in table or "drf" not in table:
        return math.nan, math.nan, math.nan
    return seed_interval((1 - table["drf"] / table[base]).groupby(level="seed").mean().dropna())


def improvement_of_means(by_seed: pd.DataFrame, base_summary: pd.DataFrame, base: str, levels) -> float:
    """1 - mean MAE_drf / mean MAE_base averaged over ``levels``, from DRF's per-seed rows and the
    baseline's summary (when the baseline's per-seed rows are not available): no interval."""
    vals = []
    for lv in levels:
        drf = by_seed[(by_seed["model"] == "drf") & np.isclose(by_seed["noise"].astype(float), lv)]["mae"]
        try:
            vals.append(1 - float(drf.mean()) / cell(base_summary, base, "mae", noise=float(lv)))
        except KeyError:
            return math.nan
    return float(np.mean(vals)) if vals else math.nan


def c3_pedestrian_ood_gain(by_seed: pd.DataFrame, ood_levels=(0.025, 0.05),
                           matched_summary: pd.DataFrame | None = None) -> dict[str, Any]:
    """DRF's relative MAE improvement out of distribution over no_dynamics, the LSTM and the
    input-matched Monoloco (``MATCHED_MONOLOCO``: its per-seed rows in ``by_seed``, or, without them,
    its seed means in ``matched_summary``); Monoloco as published is reported beside them, not judged."""
    gains = {b: improvement(by_seed, b, ood_levels) for b in ("no_dynamics", "lstm", MATCHED_MONOLOCO)}
    notes = {}
    if math.isnan(gains[MATCHED_MONOLOCO][0]):
        mean = (improvement_of_means(by_seed, matched_summary, MATCHED_MONOLOCO, ood_levels)
                if matched_summary is not None else math.nan)
        gains[MATCHED_MONOLOCO] = (mean, math.nan, math.nan)
        notes[MATCHED_MONOLOCO] = (" (seed means only: its per-seed rows come with notebook 03's next run)"
                                   if not math.isnan(mean) else " not evaluated (notebook 03)")
    judged = [g for g in gains.values() if not math.isnan(g[0])]
    beyond = [g[1] > 0 for g in gains.values()]  # NaN bounds compare False
    verdict = (REPRODUCED if all(beyond) else
               PARTLY if any(beyond) or (len(judged) == len(gains) and all(g[0] > 0 for g in judged)) else NOT)
    name = lambda b: MONOLOCO_NAMES.get(b, b)  # noqa: E731
    ours = ", ".join(f"vs {name(b)}: " + ("n/a" if math.isnan(g[0]) else fmt_interval(g, 100, 1, True, "%"))
                     + notes.get(b, "") for b, g in gains.items())
    published = improvement(by_seed, PUBLISHED_MONOLOCO, ood_levels)
    if not math.isnan(published[0]):
        ours += f"; second comparison, not judged: vs {name(PUBLISHED_MONOLOCO)}: {fmt_interval(published, 100, 1, True, '%')}"
    return {"id": "C3", "claim": "Pedestrians, out of distribution (p 0.025, 0.05): DRF's MAE improves on "
                                 "no_dynamics, LSTM and Monoloco",
            "paper": ", ".join(f"{100 * v:.0f} %" for v in paper.PEDESTRIAN_OOD_IMPROVEMENT.values()) + " lower MAE",
            "ours": ours,
            "rule": "improvement = 1 - MAE_DRF/MAE_base per seed (paired by seed), averaged over the OOD levels; "
                    "mean over seeds with a 95 % t-interval; Monoloco is the one fed the DRF family's inputs (its "
                    "published input hides what the DRF family's encoder sees; as published it is a second, "
                    "unjudged comparison); reproduced: the interval is above 0 against all three; partly: above 0 "
                    "against at least one, or the mean above 0 against all three; else not reproduced",
            "verdict": verdict}


# ------------------------------------------------------------------------------ C4
PARITY_BAND = 0.10


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
    name = lambda b: MONOLOCO_NAMES.get(b, b)  # noqa: E731
    row = {"id": "C4", "claim": "Pedestrians in distribution (p 0.01): DRF comparable to Monoloco",
           "paper": f"{paper.PEDESTRIAN_MAE[0.01]['drf']:.2f} m vs {paper.PEDESTRIAN_MAE[0.01]['monoloco']:.2f} m",
           "rule": "comparable = within 10 % either way (the paper reports equal MAE; 10 % is the book's band: "
                   "half the 18 % the paper calls an improvement in C3), against Monoloco fed the DRF family's "
                   "inputs (as published it is a second, unjudged comparison); reproduced: /MAE_DRF / "
                   "MAE_Monoloco - 1/ <= 10 % in seed means (the paired per-seed interval shown beside it); better "
                   "than the paper's parity: DRF more than 10 % lower (a different finding, not parity); partly: "
                   "DRF 10-25 % higher; else not reproduced; not testable without that Monoloco"}
    d = cell(mae, "drf", "mae", noise=noise)
    try:
        m = cell(mae, comparator, "mae", noise=noise)
    except KeyError:
        return {**row, "ours": f"DRF {fmt(mae, 'drf', 'mae', 3, noise=noise)} m; {name(comparator)} not evaluated "
                               "(notebook 03)", "verdict": NOT_TESTABLE}
    rel = (d - m) / m
    paired = relative_difference(by_seed, "drf", comparator, noise) if by_seed is not None else (rel, math.nan, math.nan)
    verdict = (REPRODUCED if at_most(abs(rel), PARITY_BAND) else BETTER if rel < 0
               else PARTLY if at_most(rel, 0.25) else NOT)
    ours = (f"DRF {fmt(mae, 'drf', 'mae', 3, noise=noise)} m vs {name(comparator)} "
            f"{fmt(mae, comparator, 'mae', 3, noise=noise)} m{note} ({100 * rel:+.1f}%"
            + ("" if math.isnan(paired[1]) else f"; paired by seed {fmt_interval(paired, 100, 1, True, '%')}") + ")")
    if comparator != PUBLISHED_MONOLOCO and (mae["model"] == PUBLISHED_MONOLOCO).any():
        p = cell(mae, PUBLISHED_MONOLOCO, "mae", noise=noise)
        ours += (f"; second comparison, not judged: {name(PUBLISHED_MONOLOCO)} "
                 f"{fmt(mae, PUBLISHED_MONOLOCO, 'mae', 3, noise=noise)} m ({100 * (d - p) / p:+.1f}%)")
    return {**row, "ours": ours, "verdict": verdict}


# --------------------------------------------------------- a diagnostic beside C4 (notebook 03)
# Monoloco fed the DRF family's inputs closes this share of its in-distribution gap to no_dynamics or
# more: the gap is mostly its published inputs (else mostly its network, loss or schedule). Half,
# because it splits the gap into the larger and the smaller part.
INPUTS_SHARE = 0.5


def monoloco_inputs_reading(summary: pd.DataFrame, level: float) -> dict[str, Any]:
    """summary: ``drfkit.study.evaluate.summarise`` by model, noise with rows monoloco,
    monoloco_detected_inputs and no_dynamics. Returns the share of the gap closed and a sentence."""
    mae = summary[(summary["noise"] - level).abs() < 1e-9].set_index("model")["mae"]
    mono, fed, nd = (float(mae[m]) for m in (PUBLISHED_MONOLOCO, MATCHED_MONOLOCO, "no_dynamics"))
    if mono <= nd:
        return {"share": float("nan"), "text": f"Monoloco ({mono:.3g} m) is no worse than no_dynamics ({nd:.3g} m) at "
                                               f"p = {level:g}: there is no handicap to explain."}
    share = (mono - fed) / (mono - nd)
    cause = "its published inputs" if share >= INPUTS_SHARE else "its network, loss or schedule, not its inputs"
    return {"share": share, "text": f"At p = {level:g} Monoloco is at {mono:.3g} m, no_dynamics at {nd:.3g} m; the "
                                    f"same network fed the DRF family's inputs reaches {fed:.3g} m, closing "
                                    f"{100 * share:.0f} % of the gap: the gap is mostly {cause}."}


__all__ = ["MATCHED_MONOLOCO", "PUBLISHED_MONOLOCO", "c1_pendulum_mae_ordering", "dominance", "c2_pendulum_picp_mpiw",
           "c5_intervals_under_shift", "improvement", "improvement_of_means", "c3_pedestrian_ood_gain",
           "PARITY_BAND", "relative_difference", "c4_in_distribution_parity", "INPUTS_SHARE",
           "monoloco_inputs_reading"]
