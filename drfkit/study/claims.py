"""The paper's claims, each turned into a rule that code applies to our results.

Every row of ``results/<profile>/claims.csv`` says: the claim, the paper's figure, ours
(with its 95 % interval over seeds where there is one), the rule that decides the verdict,
and the verdict — ``reproduced``, ``partly`` or ``not reproduced`` — computed here, never
written by hand. Notebooks fill their own rows (03: C1–C5, 04: C6, 05: C7) through
``upsert``; the table is re-rendered as ``claims.md`` each time.

Input frames are the outputs of ``drfkit.study.evaluate.summarise`` (one row per model and
condition with ``<metric>``, ``<metric>_lo``, ``<metric>_hi``).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd

from drfkit.study import paper
from drfkit.util.io import atomic_write_csv, atomic_write_text
from drfkit.util.paths import results_dir

REPRODUCED, PARTLY, NOT = "reproduced", "partly", "not reproduced"
NOT_TESTABLE = "not testable"  # the data cannot decide (e.g. a gate that selects no frame or every frame)
BETTER = "better than the paper's parity"  # a parity claim (C4) where the DRF is far better, not equal
VERDICTS = (REPRODUCED, PARTLY, NOT, NOT_TESTABLE, BETTER)

# A PICP at or above this is saturated: the 95 % intervals cover (almost) everything, so coverage
# cannot rank two models there, and differences in the last decimals are noise, not evidence.
SATURATED_PICP = 0.995
# C7: a gate selecting fewer than 10 % or more than 90 % of the frames is within 10 % of never or
# always dropping out, so PICP near always-dropout (or near random gating) follows from the
# fraction itself, not from the Kalman gain.
GATE_FRACTION_RANGE = (0.10, 0.90)
# Notebook 05's two targets of the book (not claims of the paper; C6 judges the paper's 2.93x):
# DRF's S-sample prediction at least 3x faster per frame than Monoloco as published at batch 1,
# because the paper's claim is "~3x faster" and the book's DRF should meet that round figure itself.
TIMING_SPEEDUP_TARGET = 3.0
# ... and at most 1.25x DRF's own deterministic pass, because only the decoder is sampled, in one
# batched call, so the S samples should add at most a quarter to the features' cost.
SAMPLING_OVERHEAD_TARGET = 1.25
# A value exactly at a threshold is inside it; this absorbs the rounding of e.g. (2.2 - 2.0) / 2.0.
_EPS = 1e-9


def _at_most(value: float, limit: float) -> bool:
    return value <= limit + _EPS
COLUMNS = ["id", "protocol", "claim", "paper", "ours", "rule", "verdict"]
# Every claim row and what fills it: claims.md lists the ones a profile has not evaluated yet.
CLAIM_SOURCES = {
    "C1": "notebook 04, pendulum", "C2": "notebook 04, pendulum", "C3": "notebook 04, pedestrians",
    "C4": "notebook 04, pedestrians", "C5": "notebook 04, both studies", "C6": "notebook 05",
    "C7a": "notebook 06, pendulum", "C7b": "notebook 06, pedestrians",
    "F1": "notebook 02, pendulum", "F2": "notebook 02, pendulum",
}


# Where each claim is judged: the notebook and its section, the tables and figures the verdict reads
# (under results/<profile>/; a protocol other than the paper's has its figures as <study>_<protocol>_...).
CLAIM_EVIDENCE = {
    "C1": ("04_ood_noise_evaluation", "Claims C1–C5, with computed verdicts",
           ["ood_all_metrics.csv", "ood_all_metrics_by_seed.csv"], ["pendulum_mae.png"]),
    "C2": ("04_ood_noise_evaluation", "The paper's figures, redrawn", ["ood_picp_mpiw.csv"], ["pendulum_picp_mpiw.png"]),
    "C3": ("04_ood_noise_evaluation", "Claims C1–C5, with computed verdicts", ["ood_all_metrics_by_seed.csv"],
           ["pedestrians_mae.png"]),
    "C4": ("04_ood_noise_evaluation", "Claims C1–C5, with computed verdicts", ["ood_all_metrics.csv"],
           ["pedestrians_mae.png"]),
    "C5": ("04_ood_noise_evaluation", "The paper's figures, redrawn", ["ood_all_metrics.csv", "ood_picp_mpiw.csv"],
           ["pendulum_picp_mpiw.png", "pedestrians_picp_mpiw.png"]),
    "C6": ("05_timing", "Claim C6 and the targets", ["timing.csv"], ["timing_ms_per_frame.png"]),
    # the judged gates are tuned at the training noise (gating_summary_train_noise.csv); gating_summary.csv
    # holds the gates tuned out of distribution, a labelled second row
    "C7a": ("06_competency_gating", "Claim C7, with computed verdicts",
            ["gating_summary_train_noise.csv", "gating_summary.csv"], ["gating_sweep.png"]),
    "C7b": ("06_competency_gating", "Claim C7, with computed verdicts",
            ["gating_summary_train_noise.csv", "gating_summary.csv"], ["gating_sweep.png"]),
    "F1": ("02_pendulum_dynamics", "Does the filter filter?", ["pendulum_mechanism.csv", "pendulum_protocols.csv"], []),
    "F2": ("02_pendulum_dynamics", "Blackout: does the state coast?",
           ["pendulum_blackout.csv", "pendulum_physics_bound_protocols.csv"], ["pendulum_blackout_protocols.png"]),
}
# Claims whose evidence is the simulated pedestrian source by default (pedestrians.source: simulated)
PEDESTRIAN_CLAIMS = ("C3", "C4", "C7b")


def evidence_links(cid: str, prefix: str = "") -> str:
    """'notebook §section; tables …; figures …' of a claim, as markdown links relative to ``prefix``
    (the folder of results/<profile>/ as seen from the page)."""
    notebook, section, tables, figures = CLAIM_EVIDENCE[cid]
    parts = [f"[{notebook} §{section}]({prefix}executed/{notebook}.ipynb)"]
    parts += [f"[{t}]({prefix}tables/{t})" for t in tables] + [f"[{f}]({prefix}figures/{f})" for f in figures]
    return "; ".join(parts)


def _cell(summary: pd.DataFrame, model: str, metric: str, **where: Any) -> float:
    rows = summary[summary["model"] == model]
    for col, val in where.items():
        rows = rows[np.isclose(rows[col], val)] if isinstance(val, float) else rows[rows[col] == val]
    if len(rows) != 1:
        raise KeyError(f"expected one row for {model} {where}, found {len(rows)}")
    return float(rows[metric].iloc[0])


def _fmt(summary: pd.DataFrame, model: str, metric: str, digits: int = 4, scale: float = 1.0, **where) -> str:
    mean = _cell(summary, model, metric, **where) * scale
    ci = summary.get(f"{metric}_ci")
    half = _cell(summary, model, f"{metric}_ci", **where) * scale if ci is not None else math.nan
    return f"{mean:.{digits}g}" + ("" if math.isnan(half) else f" ± {half:.{digits - 1}g}")


# ------------------------------------------------------------------------------ C1
def paired_difference(by_seed: pd.DataFrame, a: str, b: str, noise: float, metric: str = "mae"
                      ) -> tuple[float, float, float]:
    """Mean over seeds of ``metric``(a) - ``metric``(b) at ``noise``, paired by seed (same data, each
    model its own initialisation), and its 95 % t-interval (NaN bounds with one seed).
    by_seed: one row per (model, seed, noise)."""
    from drfkit.core.metrics import t975

    rows = by_seed[np.isclose(by_seed["noise"].astype(float), noise)]
    table = rows.pivot_table(index="seed", columns="model", values=metric)
    diff = (table[a] - table[b]).dropna()
    mean = float(diff.mean())
    if len(diff) < 2:
        return mean, math.nan, math.nan
    half = t975(len(diff) - 1) * float(diff.std(ddof=1)) / math.sqrt(len(diff))
    return mean, mean - half, mean + half


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
        m = {k: _cell(mae, k, "mae", noise=lv) for k in ("drf", "lstm", "no_dynamics")}
        full.append(m["drf"] < m["lstm"] < m["no_dynamics"])
        drf_best.append(m["drf"] < min(m["lstm"], m["no_dynamics"]))
        if by_seed is not None:
            steps = [paired_difference(by_seed, a, b, lv) for a, b in (("drf", "lstm"), ("lstm", "no_dynamics"))]
            beyond.append(all(hi < 0 for _, _, hi in steps))  # NaN (one seed) compares False
        else:
            beyond.append(False)
        ours.append(f"@{lv}: DRF {_fmt(mae, 'drf', 'mae', 3, noise=lv)}, LSTM {_fmt(mae, 'lstm', 'mae', 3, noise=lv)}, "
                    f"no_dyn {_fmt(mae, 'no_dynamics', 'mae', 3, noise=lv)}")
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


# ------------------------------------------------------------------------------ C2
def dominance(curve: pd.DataFrame, model: str, baseline: str, x: str = "mpiw", y: str = "picp") -> float:
    """Fraction of ``model``'s curve points (within the baseline's x-range) lying above the
    baseline's curve interpolated linearly in x. NaN if the ranges do not overlap."""
    a = curve[curve["model"] == model].sort_values(x)
    b = curve[curve["model"] == baseline].sort_values(x)
    inside = a[(a[x] >= b[x].min()) & (a[x] <= b[x].max())]
    if len(inside) == 0 or len(b) < 2:
        # Outside the baseline's range: above-and-left of its narrowest point also dominates.
        left = a[(a[x] <= b[x].min()) & (a[y] >= b.loc[b[x].idxmin(), y])]
        return float(len(left) > 0) if len(a) else math.nan
    return float(np.mean(inside[y].to_numpy() > np.interp(inside[x], b[x], b[y])))


def c2_pendulum_picp_mpiw(curve: pd.DataFrame, levels=(0.5, 0.75)) -> dict[str, Any]:
    """DRF's PICP–MPIW curve lies above each baseline's (higher PICP at equal MPIW)."""
    fractions, saturated = {}, []
    for lv in levels:
        sub = curve[np.isclose(curve["noise"], lv)]
        for base in ("lstm", "no_dynamics"):
            pair = sub[sub["model"].isin(["drf", base])]
            if len(pair) and bool((pair["picp"] >= SATURATED_PICP).all()):
                saturated.append(f"vs {base}@{lv}")  # every interval covers: coverage cannot rank them
                continue
            fractions[(lv, base)] = dominance(sub, "drf", base)
    vals = [v for v in fractions.values() if not math.isnan(v)]
    verdict = (NOT_TESTABLE if not vals else REPRODUCED if min(vals) == 1.0 else PARTLY if np.mean(vals) >= 0.5
               else NOT)
    ours = ", ".join(f"vs {b}@{lv}: {100 * f:.0f}%" for (lv, b), f in fractions.items())
    if saturated:
        ours += ("; " if ours else "") + "not informative (every PICP >= " + f"{100 * SATURATED_PICP:g}%): " \
            + ", ".join(saturated)
    return {"id": "C2", "claim": "Pendulum: DRF's PICP–MPIW curve dominates no_dynamics and LSTM",
            "paper": "DRF " + " ".join(f"({m:.2f}, {p:g}%)" for m, p in paper.PENDULUM_PICP_MPIW["drf"])
                     + " above both baselines",
            "ours": "share of DRF points above the baseline curve: " + ours,
            "rule": "reproduced: every DRF point (dropout rates) lies above every baseline curve at equal MPIW at "
                    "every level; partly: on average at least half do; else not reproduced; a comparison where "
                    f"every PICP is >= {100 * SATURATED_PICP:g}% is left out as not informative (intervals that "
                    "cover everything cannot be ranked by coverage); not testable if none is left",
            "verdict": verdict}


# ------------------------------------------------------------------------------ C3
def improvement(by_seed: pd.DataFrame, base: str, levels) -> tuple[float, float, float]:
    """Relative MAE improvement of DRF over ``base``: per seed, 1 - MAE_drf / MAE_base averaged
    over ``levels`` (models paired by seed: same data, their own initialisation), then the
    mean over seeds and its 95 % t-interval (NaN bounds with one seed).

    by_seed: one row per (model, seed, noise) with a ``mae`` column.
    """
    from drfkit.core.metrics import t975

    rows = by_seed[by_seed["noise"].apply(lambda v: any(math.isclose(v, lv) for lv in levels))]
    table = rows.pivot_table(index=["seed", "noise"], columns="model", values="mae")
    per_seed = (1 - table["drf"] / table[base]).groupby(level="seed").mean().dropna()
    mean = float(per_seed.mean())
    if len(per_seed) < 2:
        return mean, math.nan, math.nan
    half = t975(len(per_seed) - 1) * float(per_seed.std(ddof=1)) / math.sqrt(len(per_seed))
    return mean, mean - half, mean + half


def c3_pedestrian_ood_gain(by_seed: pd.DataFrame, ood_levels=(0.025, 0.05)) -> dict[str, Any]:
    gains = {b: improvement(by_seed, b, ood_levels) for b in ("no_dynamics", "lstm", "monoloco")}
    positive = [g[0] > 0 for g in gains.values()]
    significant = [g[1] > 0 for g in gains.values()]
    verdict = REPRODUCED if all(significant) else PARTLY if any(positive) else NOT
    ours = ", ".join(f"vs {b}: {100 * g[0]:+.1f}%" + ("" if math.isnan(g[1]) else f" [{100 * g[1]:+.1f}, {100 * g[2]:+.1f}]")
                     for b, g in gains.items())
    return {"id": "C3", "claim": "Pedestrians, out of distribution (p 0.025, 0.05): DRF's MAE improves on "
                                 "no_dynamics, LSTM and Monoloco",
            "paper": ", ".join(f"{100 * v:.0f} %" for v in paper.PEDESTRIAN_OOD_IMPROVEMENT.values()) + " lower MAE",
            "ours": ours,
            "rule": "improvement = 1 - MAE_DRF/MAE_base per seed (paired by seed), averaged over the OOD levels; "
                    "mean over seeds with a 95 % t-interval; reproduced: the interval is above 0 against all "
                    "three; partly: the mean is above 0 against at least one; else not reproduced",
            "verdict": verdict}


# ------------------------------------------------------------------------------ C4
PARITY_BAND = 0.10


def c4_in_distribution_parity(mae: pd.DataFrame, noise: float = 0.01) -> dict[str, Any]:
    d, m = _cell(mae, "drf", "mae", noise=noise), _cell(mae, "monoloco", "mae", noise=noise)
    rel = (d - m) / m
    verdict = (REPRODUCED if _at_most(abs(rel), PARITY_BAND) else BETTER if rel < 0
               else PARTLY if _at_most(rel, 0.25) else NOT)
    return {"id": "C4", "claim": "Pedestrians in distribution (p 0.01): DRF comparable to Monoloco",
            "paper": f"{paper.PEDESTRIAN_MAE[0.01]['drf']:.2f} m vs {paper.PEDESTRIAN_MAE[0.01]['monoloco']:.2f} m",
            "ours": f"DRF {_fmt(mae, 'drf', 'mae', 3, noise=noise)} m vs Monoloco "
                    f"{_fmt(mae, 'monoloco', 'mae', 3, noise=noise)} m ({100 * (d - m) / m:+.1f}%)",
            "rule": "comparable = within 10 % either way (the paper reports equal MAE; 10 % is the book's band: "
                    "half the 18 % the paper calls an improvement in C3); reproduced: |MAE_DRF / MAE_Monoloco - 1| "
                    "<= 10 %; better than the paper's parity: DRF more than 10 % lower (a different finding, not "
                    "parity); partly: DRF 10-25 % higher; else not reproduced",
            "verdict": verdict}


# ------------------------------------------------------------------------------ C5
def c5_intervals_under_shift(curves: pd.DataFrame, conditions: list[tuple[str, float]],
                             baselines: dict[str, list[str]]) -> dict[str, Any]:
    """Under shift, DRF keeps a higher PICP with a narrower MPIW: judged over the PICP–MPIW curves
    (one point per inference dropout rate), as C2 is.

    curves: rows with columns study, model, noise, picp, mpiw (one per dropout rate; a single rate
    per model reduces to comparing points); conditions: (study, noise) pairs out of distribution;
    baselines: study -> models. Per comparison, the share of DRF points above the baseline's curve at
    equal MPIW (``dominance``: left of the baseline's narrowest point counts when its PICP is at least
    as high). A comparison where every PICP of both is saturated is not informative and left out.
    """
    fractions, parts = {}, []
    for study, lv in conditions:
        sub = curves[(curves["study"] == study) & np.isclose(curves["noise"].astype(float), lv)]
        for base in baselines[study]:
            pair = sub[sub["model"].isin(["drf", base])]
            if len(pair) and bool((pair["picp"] >= SATURATED_PICP).all()):
                parts.append(f"{study}@{lv} vs {base}: not informative (every PICP >= {100 * SATURATED_PICP:g}%)")
                continue
            f = dominance(sub, "drf", base)
            fractions[(study, lv, base)] = f
            parts.append(f"{study}@{lv} vs {base}: {'n/a' if math.isnan(f) else f'{100 * f:.0f}%'}")
    vals = [v for v in fractions.values() if not math.isnan(v)]
    verdict = (NOT_TESTABLE if not vals else REPRODUCED if min(vals) == 1.0 else PARTLY if np.mean(vals) >= 0.5
               else NOT)
    return {"id": "C5", "claim": "Under shift, DRF keeps a higher PICP with a narrower MPIW than the baselines",
            "paper": "pedestrians p 0.025/0.05: DRF's curve above all; pendulum at 0.75 likewise",
            "ours": "share of DRF curve points above the baseline's curve at equal MPIW: " + "; ".join(parts),
            "rule": "over the PICP–MPIW curves (inference dropout rates), at each out-of-distribution level; "
                    "reproduced: every DRF point lies above every baseline's curve (higher PICP at equal or "
                    "narrower MPIW); partly: on average at least half do; else not reproduced; a comparison "
                    f"where every PICP is >= {100 * SATURATED_PICP:g}% is not informative and left out; not "
                    "testable if none is left",
            "verdict": verdict}


# ------------------------------------------------------------------------------ C6
def c6_speedup(speedup: float, target: float = paper.TIMING_SPEEDUP) -> dict[str, Any]:
    verdict = REPRODUCED if _at_most(2.5, speedup) else PARTLY if _at_most(1.5, speedup) else NOT
    return {"id": "C6", "claim": "DRF computes aleatoric + epistemic uncertainty ~3x faster than Monoloco "
                                 "(25 passes, after keypoint extraction)",
            "paper": f"{paper.TIMING_MS['monoloco']} ms vs {paper.TIMING_MS['drf']} ms, {target}x (GTX 1080)",
            "ours": f"{speedup:.2f}x at batch 1",
            "rule": "speed-up = Monoloco as published (25 sequential passes) / DRF (25 batched decoder samples), "
                    "per frame at batch 1, measured in one run; reproduced: >= 2.5x (within 15 % of the paper's "
                    f"{paper.TIMING_SPEEDUP}x, about the spread of such timings across machines); partly: >= 1.5x "
                    "(still clearly faster); else not reproduced",
            "verdict": verdict}


# ------------------------------------------------------------------------------ C7
def _gating_ours(table: pd.DataFrame, study: str) -> tuple[pd.Series, pd.Series, pd.Series, str]:
    row = lambda s: table[(table["study"] == study) & (table["setting"] == s)].iloc[0]  # noqa: E731
    kg, rnd, always = row("kalman_gain"), row("random"), row("always")
    ours = (f"KG {100 * kg['picp']:.1f}% at {kg['time_ms']:.3g} ms vs always {100 * always['picp']:.1f}% at "
            f"{always['time_ms']:.3g} ms, random {100 * rnd['picp']:.1f}%")
    if "fraction" in table.columns:
        ours += f"; KG gates {100 * float(kg['fraction']):.0f}% of frames"
    return kg, rnd, always, ours


def _paper_gating(study: str) -> str:
    """The paper's gating row of ``study`` as the claims table quotes it (``paper.GATING``)."""
    g = paper.GATING[study]  # setting -> (PICP %, MPIW, time ms)
    if study == "pendulum":
        return (f"{g['kalman_gain'][0]:.1f} % vs {g['always'][0]:.1f} % (always) at {g['kalman_gain'][2]:.1f} vs "
                f"{g['always'][2]:.1f} ms; random {g['random'][0]:.1f} %")
    return f"{g['kalman_gain'][0]:.1f} % (KG) vs {g['random'][0]:.1f} % (random)"


def c7_gating(table: pd.DataFrame, study: str, ood_tuned: pd.DataFrame | None = None) -> dict[str, Any]:
    """table: rows setting in {no_dropout, random, kalman_gain, always} with picp (fraction), time_ms
    (and fraction), for gates tuned on validation at the TRAINING noise: a gate is tuned where its
    user has data, not at the shift it will meet. ``ood_tuned``: the same for gates tuned at the
    out-of-distribution test level, reported in the row as a labelled reference, not judged."""
    kg, rnd, always, ours = _gating_ours(table, study)
    ours = "gate tuned at the training noise: " + ours
    if ood_tuned is not None:
        ours += "; for reference, gate tuned at the test noise: " + _gating_ours(ood_tuned, study)[3]
    close = _at_most(always["picp"] - kg["picp"], 0.015)
    cheaper = _at_most(kg["time_ms"], 0.75 * always["time_ms"])
    beats_random = kg["picp"] > rnd["picp"]
    lo, hi = GATE_FRACTION_RANGE
    degenerate = "fraction" in table.columns and not (_at_most(lo, float(kg["fraction"]))
                                                      and _at_most(float(kg["fraction"]), hi))
    tuned = "gates tuned on validation at the training noise (the tuned-at-test-noise gate is a reference only); "
    if study == "pendulum":
        score = int(close) + int(cheaper) + int(beats_random)
        verdict = NOT_TESTABLE if degenerate else REPRODUCED if score == 3 else PARTLY if score == 2 else NOT
        return {"id": "C7a", "claim": "Pendulum: Kalman-gain gating keeps PICP near always-dropout at much less time",
                "paper": _paper_gating("pendulum"), "ours": ours,
                "rule": tuned + "three tests: PICP within 1.5 points of always-dropout (about twice the paper's own "
                        "0.8-point gap); time <= 0.75 x always (a saving of at least a quarter; the paper's is 40 %); "
                        "PICP above random gating at equal fraction; reproduced: all three; partly: two; else not "
                        "reproduced; not testable when the gate selects under 10 % or over 90 % of the frames (then "
                        "its PICP follows from the fraction, not from the gain)",
                "verdict": verdict}
    gain = kg["picp"] - rnd["picp"]
    verdict = (NOT_TESTABLE if degenerate else REPRODUCED if _at_most(abs(gain), 0.01)
               else PARTLY if _at_most(abs(gain), 0.03) else NOT)
    return {"id": "C7b", "claim": "Pedestrians: Kalman-gain gating brings no clear gain over random gating",
            "paper": _paper_gating("pedestrians"), "ours": ours + f"; KG - random = {100 * gain:+.1f} pt",
            "rule": tuned + "reproduced: |PICP_KG - PICP_random| <= 1 point (no gain, as the paper found: its gap "
                    "is 0.3 points); partly: <= 3 points; else not reproduced; not testable when the gate selects "
                    "under 10 % or over 90 % of the frames",
            "verdict": verdict}


# --------------------------------------------------------- a diagnostic beside C4 (notebook 03)
# Monoloco fed the DRF family's inputs closes this share of its in-distribution gap to no_dynamics or
# more: the gap is mostly its published inputs (else mostly its network, loss or schedule). Half,
# because it splits the gap into the larger and the smaller part.
INPUTS_SHARE = 0.5


def monoloco_inputs_reading(summary: pd.DataFrame, level: float) -> dict[str, Any]:
    """summary: ``drfkit.study.evaluate.summarise`` by model, noise with rows monoloco,
    monoloco_detected_inputs and no_dynamics. Returns the share of the gap closed and a sentence."""
    mae = summary[(summary["noise"] - level).abs() < _EPS].set_index("model")["mae"]
    mono, fed, nd = (float(mae[m]) for m in ("monoloco", "monoloco_detected_inputs", "no_dynamics"))
    if mono <= nd:
        return {"share": float("nan"), "text": f"Monoloco ({mono:.3g} m) is no worse than no_dynamics ({nd:.3g} m) at "
                                               f"p = {level:g}: there is no handicap to explain."}
    share = (mono - fed) / (mono - nd)
    cause = "its published inputs" if share >= INPUTS_SHARE else "its network, loss or schedule, not its inputs"
    return {"share": share, "text": f"At p = {level:g} Monoloco is at {mono:.3g} m, no_dynamics at {nd:.3g} m; the "
                                    f"same network fed the DRF family's inputs reaches {fed:.3g} m, closing "
                                    f"{100 * share:.0f} % of the gap: the gap is mostly {cause}."}


# ------------------------------------------------------------------------- F1, F2
# Not claims the paper states but the premise of its method: a recursive filter inside the network
# is only "a filter" if its gain follows observation quality, its transition predicts and its state
# coasts through missing observations. The book checks them before reading the claims above.
# F1 and F2: what "the filter filters" and "the state coasts" mean in numbers (reasons in the rules below);
# the ablation's second round chose the book's DRF by the same thresholds (``ablation.mechanism_targets``)
F1_RANK_CORRELATION = 0.8
F1_GAIN_RATIO = 0.25
F1_PREDICTION_RATIO = 1.0
F2_BLACKOUT_MAE = 0.10


def f1_filter_mechanism(mechanism: pd.DataFrame, noise: float) -> dict[str, Any]:
    """mechanism: ``drfkit.study.dynamics.mechanism_table`` rows of the DRF (one per seed)."""
    drf = mechanism[mechanism["model"] == "drf"]
    rho, ratio, prior = (float(drf[c].mean()) for c in ("r_noise_spearman", "gain_ratio_blackout", "prior_ratio"))
    checks = [_at_most(F1_RANK_CORRELATION, rho), _at_most(ratio, F1_GAIN_RATIO), prior < F1_PREDICTION_RATIO]
    verdict = REPRODUCED if all(checks) else PARTLY if any(checks) else NOT
    return {"id": "F1", "claim": "The DRF's filter filters: r follows frame quality, the gain drops on pure noise, "
                                 "F predicts the next observation",
            "paper": "implied by the method (Kalman update on a learned latent state)",
            "ours": f"rank corr(r, noise) {rho:.2f} at max noise {noise:g}; gain pure/clean {ratio:.2f} on the blackout; "
                    f"‖Fz − w‖/‖z − w‖ {prior:.2f} (seed means)",
            "rule": "reproduced: rank correlation >= 0.8 (r orders frames by quality almost perfectly), gain ratio "
                    "<= 0.25 (on pure noise the update keeps at most a quarter of the clean-frame correction, "
                    "so the prior carries the state) and prediction ratio < 1 (F z beats 'no change'); partly: at "
                    "least one of the three; else not reproduced",
            "verdict": verdict}


def f2_blackout_coasting(blackout: pd.DataFrame, bound_mae: float, target: float = F2_BLACKOUT_MAE) -> dict[str, Any]:
    """blackout: ``drfkit.study.dynamics.blackout_table`` rows (model, seed, mae_blackout)."""
    means = blackout.groupby("model")["mae_blackout"].mean()
    drf = float(means["drf"])
    others = {k: float(v) for k, v in means.items() if k not in ("drf", "physics_bound")}
    verdict = REPRODUCED if drf <= target else PARTLY if drf < min(others.values(), default=math.inf) else NOT
    return {"id": "F2", "claim": "The DRF's state coasts through 15 pure-noise frames",
            "paper": "implied by the method (the prior carries the state when the gain falls)",
            "ours": f"MAE on the blackout frames: DRF {drf:.3f}, " + ", ".join(f"{k} {v:.3f}" for k, v in others.items())
                    + f"; true-physics bound {bound_mae:.3f}",
            "rule": f"reproduced: DRF MAE <= {target:g} on the 15 blackout frames (an error of ~6 degrees after "
                    "2/3 of a swing without a usable frame); partly: lower than every baseline's; else not "
                    "reproduced; the bound is averaged over the same frames",
            "verdict": verdict}


def reading(table: pd.DataFrame, ids) -> str:
    """A short reading of the verdicts of ``ids`` in a claims table, written from its rows: per claim
    and protocol, the verdict and the numbers that decided it, then what the verdicts say together."""
    rows = table[table["id"].isin(list(ids))]
    lines = [f"{r['id']} ({r['protocol']} protocol) {r['verdict']}: {r['ours']}." for _, r in rows.iterrows()]
    counts = rows["verdict"].value_counts()
    summary = ", ".join(f"{n} {v}" for v, n in counts.items())
    held = rows.loc[rows["verdict"].eq(REPRODUCED), "id"].tolist()
    lines.append(f"Together: {summary}." + (f" Reproduced beyond seed noise or by its rule: {', '.join(held)}."
                                            if held else " None of these claims is reproduced by its rule."))
    return "\n".join(lines)


# ----------------------------------------------------------------------------- table
def read_claims(path) -> pd.DataFrame:
    """A claims.csv with its protocol column (tables written before protocols existed judged the paper's)."""
    table = pd.read_csv(path)
    if "protocol" not in table:
        table.insert(1, "protocol", "paper")
    return table


def upsert(profile: str, rows: list[dict[str, Any]], protocol: str = "paper") -> pd.DataFrame:
    """Replace rows with the same (id, protocol) in ``results/<profile>/claims.csv``; rewrite claims.md.
    ``protocol``: the training protocol of the models the rows judge (``drfkit.methods.protocols``)."""
    path = results_dir(profile) / "claims.csv"
    table = read_claims(path) if path.exists() else pd.DataFrame(columns=COLUMNS)
    new = pd.DataFrame([{**row, "protocol": protocol} for row in rows], columns=COLUMNS)
    replaced = table.set_index(["id", "protocol"]).index.isin(new.set_index(["id", "protocol"]).index)
    table = pd.concat([table[~replaced], new], ignore_index=True)
    order = table["id"].map(lambda v: ({"C": 0, "F": 1}.get(v[0], 2), int(v[1:].rstrip("ab")), v))
    table = (table.assign(_order=order, _book=table["protocol"].ne("paper"))
             .sort_values(["_order", "_book", "protocol"]).drop(columns=["_order", "_book"]))
    atomic_write_csv(path, table)
    atomic_write_text(results_dir(profile) / "claims.md", to_markdown(table, profile))
    return table


def to_markdown(table: pd.DataFrame, profile: str) -> str:
    lines = [f"# Claims of the paper, checked on profile `{profile}`", "",
             "Generated by `drfkit.study.claims` from the results of this profile; verdicts are computed by the "
             "rule in each row; `protocol` names how the judged models were trained (`drfkit.methods.protocols`).", "",
             "Pedestrian claims (" + ", ".join(PEDESTRIAN_CLAIMS) + ") are judged on the **simulated** pedestrian "
             "source unless the profile says `pedestrians.source: nuscenes` (docs/nuscenes.md).", "",
             "| id | protocol | claim | paper | ours | verdict | rule | evidence |", "|---|---|---|---|---|---|---|---|"]
    for _, r in table.iterrows():
        cells = [str(r[c]).replace("|", "/") for c in ("id", "protocol", "claim", "paper", "ours", "verdict", "rule")]
        cid = str(r["id"])
        if cid in PEDESTRIAN_CLAIMS:
            cells[5] += " (simulated source)"
        cells.append(evidence_links(cid) if cid in CLAIM_EVIDENCE else "")
        lines.append("| " + " | ".join(cells) + " |")
    missing = [f"{cid} ({src})" for cid, src in CLAIM_SOURCES.items() if cid not in set(table["id"])]  # any protocol
    if missing:
        lines += ["", "Not evaluated yet in this profile: " + "; ".join(missing) + "."]
    return "\n".join(lines) + "\n"
