"""Claim C7a: on the pendulum, Kalman-gain gating keeps PICP near always-dropout at much less time
(``drfkit.study.paper.GATING["pendulum"]``), judged on notebook 06's threshold sweep (no gate is
tuned; the gates tuned on validation are a labelled reference in the row)."""
from __future__ import annotations

import math

import pandas as pd

from drfkit.study.claims.efficiency import (C7_MIN_SAMPLING_SHARE, C7_NEAR_ALWAYS, C7_NO_GAIN_BAND, C7_TIME_RATIO,
                                            GATING_CLAIMS, GATING_EVIDENCE, SWEEP_WORDS, GatingClaim, Interval,
                                            judge_gating_claim, paper_share, sampling_share, time_test)
from drfkit.study.claims.table import CLAIMS, Claim, Rows
from drfkit.study.claims.verdicts import NOT, NOT_TESTABLE, PARTLY, REPRODUCED, at_most


def quote(g: dict) -> str:
    """The paper's gating row ``g`` (``paper.GATING``: setting -> (PICP %, MPIW, time ms)) as C7a quotes it:
    PICP and time beside always-dropout."""
    return (f"{g['kalman_gain'][0]:.1f} % vs {g['always'][0]:.1f} % (always) at {g['kalman_gain'][2]:.1f} vs "
            f"{g['always'][2]:.1f} ms; random {g['random'][0]:.1f} % (KG - random "
            f"{g['kalman_gain'][0] - g['random'][0]:+.1f} points); MC dropout {paper_share(g):.0f} % of the per-frame "
            "cost")


def verdict(sweep: pd.DataFrame, study: str, settings: pd.DataFrame | None, gain: Interval, room: Interval,
            ours: str, reference: str) -> tuple[str, str]:
    """C7a's verdict and 'ours': KG - random above 0, and the time test where MC dropout dominates the cost;
    not testable when even an oracle gate gains at most ``C7_NO_GAIN_BAND`` over random (a model whose
    dropout does not change its intervals, as one without a dropout head: every gate is then random)."""
    if not math.isnan(room[0]) and at_most(room[0], C7_NO_GAIN_BAND):
        return NOT_TESTABLE, (f"{ours}; even a perfect gate is within {100 * C7_NO_GAIN_BAND:g} point of random "
                              f"here: no gate could be told from random{reference}")
    time_note, time_ok = "time test not measured (no settings table)", None
    if settings is not None:
        share = sampling_share(settings, study)
        if share < C7_MIN_SAMPLING_SHARE:
            time_note = (f"time test not applicable on this machine: MC dropout is {100 * share:.0f}% of the "
                         f"per-frame cost here (the paper's: 91 %), so even gating no frame cannot save a "
                         f"quarter of always-dropout's time")
        else:
            time_ok, words = time_test(sweep, settings, study)
            time_note = f"time test {'passed' if time_ok else 'failed'}: {words} (MC dropout {100 * share:.0f}% of the cost)"
    beats = gain[1] > 0  # NaN (one seed) compares False
    result = (REPRODUCED if beats and time_ok is not False else
              PARTLY if gain[0] > 0 else NOT)
    return result, f"{ours}; {time_note}{reference}"


GATING = GATING_CLAIMS.register("C7a", GatingClaim(
    "C7a", "pendulum", "Pendulum: Kalman-gain gating keeps PICP near always-dropout at much less time", quote,
    f"{SWEEP_WORDS}; time test, applicable where MC dropout is at least "
    f"{100 * C7_MIN_SAMPLING_SHARE:.0f} % of the per-frame cost (1 - time without dropout / time "
    f"always; the paper's: 91 %): the Kalman-gain curve reaches PICP within "
    f"{100 * C7_NEAR_ALWAYS:g} points of always-dropout at <= {C7_TIME_RATIO:g} x its time; "
    "reproduced: the interval of KG - random is above 0 and the time test passes or is not "
    "applicable (then the verdict is on coverage alone, and says so); partly: KG - random above "
    "0 in the seed mean only, or the time test fails; else not reproduced; not testable "
    "without sweep rows, or when an oracle gate (the frames of largest true error, same count) beats "
    f"random by at most {100 * C7_NO_GAIN_BAND:g} point (as for a model whose dropout does not change its "
    "intervals)", verdict))


def judge(gating) -> Rows:
    return judge_gating_claim(gating, "C7a")


CLAIM = CLAIMS.register("C7a", Claim("C7a", source="notebook 06, pendulum", judge=judge, **GATING_EVIDENCE))

__all__: list[str] = []
