"""Claim C7b: on the pedestrians, Kalman-gain gating brings no clear gain over random gating
(``drfkit.study.paper.GATING["pedestrians"]``), judged on notebook 06's threshold sweep."""
from __future__ import annotations

import math

import pandas as pd

from drfkit.study.claims.efficiency import (C7_NO_GAIN_BAND, GATING_CLAIMS, GATING_EVIDENCE, SWEEP_WORDS, GatingClaim,
                                            Interval, judge_gating_claim, sweep_differences)
from drfkit.study.claims.table import CLAIMS, Claim, Rows
from drfkit.study.claims.verdicts import NOT, NOT_TESTABLE, PARTLY, REPRODUCED, at_most, fmt_interval, seed_interval


def quote(g: dict) -> str:
    """The paper's gating row ``g`` as C7b quotes it: Kalman-gain against random gating."""
    return (f"{g['kalman_gain'][0]:.1f} % (KG) vs {g['random'][0]:.1f} % (random): "
            f"{g['kalman_gain'][0] - g['random'][0]:+.1f} points")


# "no clear gain": the Kalman-gain gate captures at most this share of what a perfect gate gains over random
C7B_MAX_SHARE = 0.25


def verdict(sweep: pd.DataFrame, study: str, settings: pd.DataFrame | None, gain: Interval, room: Interval,
            ours: str, reference: str) -> tuple[str, str]:
    """C7b's verdict and 'ours': the Kalman-gain gate's share of the oracle's gain over random, per seed; not
    testable unless the oracle beats random beyond the seeds' interval (then no gate could be told from random)."""
    kg, oracle = sweep_differences(sweep, study), sweep_differences(sweep, study, method="oracle")
    if math.isnan(room[0]) or (room[1] <= 0 if not math.isnan(room[1]) else at_most(room[0], C7_NO_GAIN_BAND)):
        return NOT_TESTABLE, (f"{ours}: even a perfect gate cannot be told from random here (its gain's interval "
                              f"reaches 0){reference}")
    both = pd.concat([kg.rename("kg"), oracle.rename("oracle")], axis=1).dropna()
    share = seed_interval(both["kg"] / both["oracle"])
    upper = share[0] if math.isnan(share[2]) else share[2]
    result = REPRODUCED if at_most(upper, C7B_MAX_SHARE) else PARTLY if at_most(share[0], C7B_MAX_SHARE) else NOT
    return result, f"{ours}; KG's share of the oracle's gain {fmt_interval(share, digits=2)}{reference}"


GATING = GATING_CLAIMS.register("C7b", GatingClaim(
    "C7b", "pedestrians", "Pedestrians: Kalman-gain gating brings no clear gain over random gating", quote,
    f"{SWEEP_WORDS} (fractions where no or every test frame is selected left out: there every gate is the same); "
    "share = (KG - random) / (oracle - random) per seed, the oracle selecting as many frames of largest true error; "
    f"reproduced: the share's 95 % interval lies at or below {C7B_MAX_SHARE:g} (the gain captures at most a quarter "
    "of what a perfect gate gains: no clear gain); partly: the mean share does, the interval not; else not "
    "reproduced; not testable when the oracle's gain over random has an interval reaching 0 (with one seed: at "
    f"most {100 * C7_NO_GAIN_BAND:g} point): then no gate could be told from random", verdict))


def judge(gating) -> Rows:
    return judge_gating_claim(gating, "C7b")


CLAIM = CLAIMS.register("C7b", Claim("C7b", source="notebook 06, pedestrians", judge=judge, simulated=True,
                                     **GATING_EVIDENCE))

__all__ = ["C7B_MAX_SHARE"]
