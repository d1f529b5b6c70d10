"""What the Kalman-gain gating claims (C7a on the pendulum, C7b on the pedestrians: the paper's claims on
what the uncertainty costs and whether the gain tells which frames need it) share: the threshold sweep's
numbers, the time test, ``GatingClaim`` (a gating claim's words and verdict, each in its own module) and
``c7_gating``, which judges one on a study's sweep (notebook 06). C6, the other efficiency claim, is
``c6_uncertainty_speedup``."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

import pandas as pd

from drfkit.study import paper
from drfkit.study.claims.verdicts import NOT_TESTABLE, at_most, fmt_interval, rows_of, seed_interval
from drfkit.util.registry import Registry

# ------------------------------------------------------------------------------ C7
# The sweep's fractions averaged: the validation-quantile targets strictly between never and always
# (at 0 and 1 Kalman-gain and random gating select the same frames by construction).
C7_FRACTIONS = (0.05, 0.95)
# C7b: Kalman-gain and random gating "about equal" = their paired PICP difference within 1 point
# either way, beyond seed noise (the paper's gap is 0.3 points).
C7_NO_GAIN_BAND = 0.01
# C7a's time test: the Kalman-gain curve reaches PICP within 1.5 points of always-dropout (about twice
# the paper's 0.8-point gap) at <= 0.75x its time (a saving of at least a quarter; the paper's is 40 %) ...
C7_NEAR_ALWAYS, C7_TIME_RATIO = 0.015, 0.75
# ... and applies only where MC dropout is at least half of the per-frame cost (the paper's: 91 %,
# 2.48 of 28.23 ms): below that, gating no frame at all cannot save a quarter of always-dropout's time.
C7_MIN_SAMPLING_SHARE = 0.5


def sweep_gain(sweep: pd.DataFrame, study: str, method: str = "kalman_gain", versus: str = "random",
               fractions: tuple[float, float] = C7_FRACTIONS) -> tuple[float, float, float]:
    """PICP(method) - PICP(versus) at equal fraction, paired by seed and swept fraction, averaged
    over the informative fractions in ``fractions`` per seed (``sweep_differences``); mean over seeds and 95 %
    t-interval (all NaN when the sweep has no such rows). sweep: ``gating_study`` sweep rows (method, seed,
    val_fraction, fraction, picp)."""
    return seed_interval(sweep_differences(sweep, study, method, versus, fractions))


def sweep_differences(sweep: pd.DataFrame, study: str, method: str = "kalman_gain", versus: str = "random",
                      fractions: tuple[float, float] = C7_FRACTIONS) -> pd.Series:
    """Per seed: PICP(method) - PICP(versus) averaged over the swept fractions in ``fractions`` at which some
    but not every test frame is selected (where none or all is, every gate selects the same frames and the
    difference is 0 by construction, which would only dilute the mean). Empty when the sweep lacks them."""
    rows = sweep[(sweep["study"] == study) & sweep["val_fraction"].between(fractions[0] - 1e-9, fractions[1] + 1e-9)]
    if "fraction" in rows:
        selected = rows[rows["method"] == method].set_index(["seed", "val_fraction"])["fraction"]
        informative = selected[(selected > 0) & (selected < 1)].index
        rows = rows[rows.set_index(["seed", "val_fraction"]).index.isin(informative)]
    table = rows.pivot_table(index=["seed", "val_fraction"], columns="method", values="picp")
    if method not in table or versus not in table:
        return pd.Series(dtype=float)
    return (table[method] - table[versus]).groupby(level="seed").mean().dropna()


def sampling_share(settings: pd.DataFrame, study: str) -> float:
    """1 - time(no dropout) / time(always dropout): MC dropout's share of the per-frame cost
    (settings: ``gating_study`` settings summary with setting, time_ms)."""
    t = settings[settings["study"] == study].set_index("setting")["time_ms"]
    return float(1 - t["no_dropout"] / t["always"])


# the paper's MC-dropout share of the per-frame cost (1 - 2.48 / 28.23 ms): the pass-count time test's cost model
C7_PAPER_SAMPLING_SHARE = 0.91


def pass_count_test(sweep: pd.DataFrame, study: str, always_picp: float,
                    share: float = C7_PAPER_SAMPLING_SHARE) -> tuple[bool, str]:
    """The time test without a clock: a frame costs (1 - share) without MC dropout and 1 with it (the paper's
    share), so gating a fraction f of the frames costs (1 - share) + share f of always-dropout. Passes when the
    Kalman-gain sweep (seed means) comes within C7_NEAR_ALWAYS of always-dropout's PICP at <= C7_TIME_RATIO of
    that cost. Machine-independent: the fraction of frames is counted, not timed."""
    kg = (sweep[(sweep["study"] == study) & (sweep["method"] == "kalman_gain")]
          .groupby("val_fraction")[["fraction", "picp"]].mean().sort_index())
    near = kg[kg["picp"] >= always_picp - C7_NEAR_ALWAYS - 1e-9]
    if near.empty:
        return False, f"the Kalman-gain curve never comes within {100 * C7_NEAR_ALWAYS:g} points of always-dropout"
    f = float(near["fraction"].min())
    cost = (1 - share) + share * f
    return at_most(cost, C7_TIME_RATIO), (f"within {100 * C7_NEAR_ALWAYS:g} points of always-dropout from {100 * f:.0f}% "
                                         f"of frames: {cost:.2f}x its cost counted in MC passes at the paper's "
                                         f"{100 * share:.0f} % dropout share")


def time_test(sweep: pd.DataFrame, settings: pd.DataFrame, study: str) -> tuple[bool, str]:
    """The Kalman-gain sweep's first fraction (seed means) within C7_NEAR_ALWAYS of always-dropout's
    PICP, and whether its time is <= C7_TIME_RATIO x always's."""
    always = settings[(settings["study"] == study) & (settings["setting"] == "always")].iloc[0]
    kg = (sweep[(sweep["study"] == study) & (sweep["method"] == "kalman_gain")]
          .groupby("val_fraction")[["fraction", "picp", "time_ms"]].mean().sort_index())
    near = kg[kg["picp"] >= always["picp"] - C7_NEAR_ALWAYS - 1e-9]
    if near.empty:
        return False, f"the Kalman-gain curve never comes within {100 * C7_NEAR_ALWAYS:g} points of always-dropout"
    first = near.iloc[0]
    ratio = float(first["time_ms"] / always["time_ms"])
    return at_most(ratio, C7_TIME_RATIO), (f"within {100 * C7_NEAR_ALWAYS:g} points of always-dropout from "
                                           f"{100 * first['fraction']:.0f}% of frames at {ratio:.2f}x its time")


def tuned_reference(tuned: dict[str, pd.DataFrame] | None, study: str) -> str:
    parts = []
    for name, table in (tuned or {}).items():
        t = table[table["study"] == study].set_index("setting")
        if {"kalman_gain", "random"} <= set(t.index):
            parts.append(f"{name}: KG {100 * t.loc['kalman_gain', 'picp']:.1f}% vs random "
                         f"{100 * t.loc['random', 'picp']:.1f}% on {100 * t.loc['kalman_gain', 'fraction']:.0f}% of frames")
    return ("; gates tuned on validation (a reference, not judged): " + "; ".join(parts)) if parts else ""


def paper_share(g: dict) -> float:
    """MC dropout's share of the per-frame cost in a paper gating row (setting -> (PICP %, MPIW, time ms)), in %."""
    return 100 * (1 - g["no_dropout"][2] / g["always"][2])


SWEEP_WORDS = (f"KG - random = PICP of Kalman-gain minus random gating at equal fraction, paired by seed, averaged "
               f"over the sweep's fractions {C7_FRACTIONS[0]:g}-{C7_FRACTIONS[1]:g} (validation-score quantiles: "
               "no threshold is tuned), mean over seeds with a 95 % t-interval")

Interval = tuple[float, float, float]


@dataclass(frozen=True)
class GatingClaim:
    """One of the paper's claims on Kalman-gain gating; a study's registry entry names the one it is judged by
    (``Study.gating_claim``)."""
    id: str
    paper_study: str  # the study of the paper the claim is about (its row of ``paper.GATING``)
    claim: str
    quote: Callable[[dict], str]  # the paper's row of ``paper_study`` in ``paper.GATING`` -> the claims table's words
    rule: str
    # (sweep, study, settings, KG - random, oracle - random, 'ours' so far, tuned reference) -> (verdict, ours)
    judge: Callable[..., tuple[str, str]]

    def row(self, verdict: str, ours: str) -> dict[str, Any]:
        return {"id": self.id, "claim": self.claim, "paper": self.quote(paper.GATING[self.paper_study]), "ours": ours,
                "rule": self.rule, "verdict": verdict}


# claim id -> GatingClaim: the claims a study's registry entry may name (``Study.gating_claim``)
GATING_CLAIMS = Registry("gating claim")

# where every gating claim is judged: notebook 06's section, tables and figures (``table.Claim``'s fields)
GATING_EVIDENCE = dict(notebook="06_competency_gating", section="Claim C7, with computed verdicts",
                       tables=("gating_sweep.csv", "gating_summary.csv", "gating_summary_train_noise.csv"),
                       figures=("gating_picp_fraction.png", "gating_sweep.png"), reads="gating")


def gating_claim(study: str, claim: str | None = None) -> GatingClaim:
    """``GATING_CLAIMS[claim]``; without ``claim``, the paper's claim on the study named ``study`` (for a study
    of the registry, ``drfkit.study.claims.judge`` passes its entry's ``Study.gating_claim``)."""
    if claim is None:
        found = [c for c in GATING_CLAIMS.values() if c.paper_study == study]
        if not found:
            raise ValueError(f"the paper makes no gating claim on {study!r} (it makes "
                             f"{ {c.id: c.paper_study for c in GATING_CLAIMS.values()} }): name one of "
                             f"{sorted(GATING_CLAIMS)}")
        return found[0]
    if claim not in GATING_CLAIMS:
        raise ValueError(f"unknown gating claim {claim!r}; known: {sorted(GATING_CLAIMS)}")
    return GATING_CLAIMS[claim]


def c7_gating(sweep: pd.DataFrame, study: str, settings: pd.DataFrame | None = None,
              tuned: dict[str, pd.DataFrame] | None = None, claim: str | None = None) -> dict[str, Any]:
    """The gating claim ``claim`` (``gating_claim``; default: the paper's on ``study``) on ``study``'s rows:
    C7a, the pendulum's, the gain beats random gating and, where MC dropout dominates the cost, keeps PICP
    near always-dropout at much less time; C7b, the pedestrians', no clear gain over random. Judged on the
    threshold sweep of one training protocol (``gating_study``'s sweep: method in {kalman_gain, random,
    oracle}, seed, val_fraction, fraction, picp, time_ms).

    settings: the four settings' summary (no_dropout, always, ... with time_ms, picp) for the time
    test; tuned: name -> settings summary of a gate tuned on validation, reported as a reference."""
    rule = gating_claim(study, claim)
    gain = sweep_gain(sweep, study)
    room = sweep_gain(sweep, study, method="oracle")
    ours = f"KG - random {fmt_interval(gain, 100, 2, True, ' pt')}"
    ours += ("; oracle (frames of largest true error) - random " + fmt_interval(room, 100, 2, True, " pt")
             if not math.isnan(room[0]) else "; oracle curve not in this sweep (notebook 06 adds it)")
    reference = tuned_reference(tuned, study)
    if math.isnan(gain[0]):
        return rule.row(NOT_TESTABLE, "no sweep rows between never and always" + reference)
    return rule.row(*rule.judge(sweep, study, settings, gain, room, ours, reference))


def judge_gating_claim(gating, claim: str) -> list[tuple[str, dict]]:
    """The rows of the gating claim ``claim`` per protocol, one per study whose registry entry names it
    (``judge.GatingTables``: notebook 06's sweep, its settings summary for the time test, and the gates
    tuned on validation at the test and at the training noise, reported as references)."""
    rows = []  # (protocol, row): ``table.Rows``, not imported here to keep the import chains short
    for study, named, protocols in gating.studies:
        if named != claim:
            continue
        for protocol in protocols:
            part = rows_of(gating.sweep, study, protocol)
            if part.empty:
                continue
            pick = lambda t: None if t is None else rows_of(t, study, protocol)  # noqa: E731
            tuned = {k: v for k, v in (("tuned at the test noise", pick(gating.settings)),
                                       ("tuned at the training noise", pick(gating.trained))) if v is not None}
            rows.append((protocol, c7_gating(part, study, pick(gating.settings), tuned, claim=claim)))
    return rows


__all__ = ["C7_FRACTIONS", "C7_NO_GAIN_BAND", "C7_NEAR_ALWAYS", "C7_TIME_RATIO", "C7_MIN_SAMPLING_SHARE",
           "C7_PAPER_SAMPLING_SHARE", "pass_count_test", "sweep_differences", "sweep_gain", "sampling_share", "GatingClaim", "GATING_CLAIMS", "GATING_EVIDENCE", "gating_claim",
           "c7_gating", "judge_gating_claim"]
