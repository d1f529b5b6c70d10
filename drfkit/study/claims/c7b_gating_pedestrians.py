"""Claim C7b: on the pedestrians, Kalman-gain gating brings no clear gain over random gating
(``drfkit.study.paper.GATING["pedestrians"]``), judged on notebook 06's threshold sweep."""
from __future__ import annotations

import math

import pandas as pd

from drfkit.study.claims.efficiency import (C7_NO_GAIN_BAND, GATING_CLAIMS, GATING_EVIDENCE, SWEEP_WORDS, GatingClaim,
                                            Interval, judge_gating_claim)
from drfkit.study.claims.table import CLAIMS, Claim, Rows
from drfkit.study.claims.verdicts import NOT, NOT_TESTABLE, PARTLY, REPRODUCED, at_most


def quote(g: dict) -> str:
    """The paper's gating row ``g`` as C7b quotes it: Kalman-gain against random gating."""
    return (f"{g['kalman_gain'][0]:.1f} % (KG) vs {g['random'][0]:.1f} % (random): "
            f"{g['kalman_gain'][0] - g['random'][0]:+.1f} points")


def verdict(sweep: pd.DataFrame, study: str, settings: pd.DataFrame | None, gain: Interval, room: Interval,
            ours: str, reference: str) -> tuple[str, str]:
    """C7b's verdict and 'ours': KG - random within the no-gain band, unless even an oracle could not leave it."""
    band = C7_NO_GAIN_BAND
    if not math.isnan(room[0]) and at_most(room[0], band):
        return NOT_TESTABLE, f"{ours}: even a perfect gate is within {100 * band:g} point of random here{reference}"
    inside = at_most(abs(gain[1]), band) and at_most(abs(gain[2]), band)  # NaN bounds: not inside
    result = REPRODUCED if inside else PARTLY if at_most(abs(gain[0]), band) else NOT
    return result, ours + reference


GATING = GATING_CLAIMS.register("C7b", GatingClaim(
    "C7b", "pedestrians", "Pedestrians: Kalman-gain gating brings no clear gain over random gating", quote,
    f"{SWEEP_WORDS}; reproduced: the interval lies within +/- {100 * C7_NO_GAIN_BAND:g} point "
    "(no gain, beyond seed noise; the paper's gap is 0.3 points); partly: the mean within it, the "
    "interval not; else not reproduced; not testable when an oracle gate (the frames of largest "
    f"true error, same count) beats random by at most {100 * C7_NO_GAIN_BAND:g} point: then no gate "
    "could be told from random", verdict))


def judge(gating) -> Rows:
    return judge_gating_claim(gating, "C7b")


CLAIM = CLAIMS.register("C7b", Claim("C7b", source="notebook 06, pedestrians", judge=judge, simulated=True,
                                     **GATING_EVIDENCE))

__all__: list[str] = []
