"""F1, the method's premise: the DRF's filter filters. Its observation noise r follows frame quality,
its gain drops on pure-noise frames, and its transition F predicts the next observation."""
from __future__ import annotations

from typing import Any

import pandas as pd

from drfkit.study.claims.dynamics_table import MECHANISM_EVIDENCE, drf_protocols
from drfkit.study.claims.standins import tag, variants
from drfkit.study.claims.table import CLAIMS, Claim, Rows
from drfkit.study.claims.verdicts import NOT, PARTLY, REPRODUCED, at_most, correlation_interval, fmt_interval, seed_interval

F1_RANK_CORRELATION = 0.8
F1_GAIN_RATIO = 0.25
F1_PREDICTION_RATIO = 1.0
# a gain on pure noise at least this share of the clean one is a pass-through: the update does not respond to
# frame quality, and the gain is the mechanism, so such a filter is not "partly" filtering
F1_PASS_THROUGH = 0.9


def f1_filter_mechanism(mechanism: pd.DataFrame, noise: float) -> dict[str, Any]:
    """mechanism: rows of the DRF (model 'drf', one per seed) with r_noise_spearman,
    gain_ratio_blackout, prior_ratio (``drfkit.study.dynamics.mechanism_table`` or ``protocol_table``)."""
    drf = mechanism[mechanism["model"] == "drf"]
    rho = correlation_interval(drf["r_noise_spearman"])
    ratio, prior = (seed_interval(drf[c]) for c in ("gain_ratio_blackout", "prior_ratio"))
    checks = [at_most(F1_RANK_CORRELATION, rho[0]), at_most(ratio[0], F1_GAIN_RATIO), prior[0] < F1_PREDICTION_RATIO]
    reversed_ = at_most(rho[0], 0.0)  # r falls (or does not rise) as frames get noisier
    pass_through = at_most(F1_PASS_THROUGH, ratio[0])  # the gain does not respond to frame quality
    verdict = REPRODUCED if all(checks) else NOT if reversed_ or pass_through or not any(checks) else PARTLY
    direction = ("r falls as frames get noisier: the opposite of following their quality" if rho[0] < 0 else
                 "r does not rise with the noise" if reversed_ else
                 # a positive mean whose interval reaches 0: the seeds do not agree that r rises at all
                 "r rises with the noise in the seed mean only: its interval reaches 0" if rho[1] <= 0 else
                 "r rises with the noise" + ("" if checks[0] else ", too loosely to order frames by quality"))
    return {"id": "F1", "claim": "The DRF's filter filters: r follows frame quality, the gain drops on pure noise, "
                                 "F predicts the next observation",
            "paper": "implied by the method (Kalman update on a learned latent state)",
            "ours": f"rank corr(r, noise) {fmt_interval(rho, digits=2, sign=True)} at max noise {noise:g} ({direction}); "
                    f"gain pure/clean {fmt_interval(ratio)} on the blackout; ‖Fz − w‖/‖z − w‖ "
                    f"{fmt_interval(prior)} (seed means; 95 % intervals over {len(drf)} seeds: Fisher's z for ρ, "
                    "t for the ratios)"
                    + ("; the gain does not respond to frame quality (a pass-through)" if pass_through else ""),
            "rule": f"seed means: reproduced: rank correlation ρ(r, noise) >= {F1_RANK_CORRELATION:g} (r orders frames "
                    f"by quality almost perfectly), gain ratio <= {F1_GAIN_RATIO:g} (on pure noise the update keeps at "
                    "most a quarter of the clean-frame correction, so the prior carries the state) and prediction "
                    f"ratio < {F1_PREDICTION_RATIO:g} (F z beats 'no change'); not reproduced: ρ <= 0 (r does not rise "
                    "with the noise, or falls: the filter cannot trust bad frames less, whatever the other two "
                    f"say), or a gain ratio >= {F1_PASS_THROUGH:g} (a pass-through: the gain is the mechanism), or "
                    "none of the three holds; partly: otherwise",
            "verdict": verdict}


def judge(tables) -> Rows:
    """F1 per protocol at the profile's highest pendulum noise (``judge.Tables``)."""
    return [(cell_, tag(f1_filter_mechanism(rows, max(tables.P.pendulum.eval_max_noise)), kind))
            for protocol, part in drf_protocols(tables)
            for cell_, kind, (rows,) in variants(protocol, tables.judged_drfs("pendulum"), part)]


CLAIM = CLAIMS.register("F1", Claim("F1", tables=("pendulum_protocols.csv",), figures=(), judge=judge,
                                    **MECHANISM_EVIDENCE))

__all__ = ["F1_RANK_CORRELATION", "F1_GAIN_RATIO", "F1_PASS_THROUGH", "F1_PREDICTION_RATIO", "f1_filter_mechanism"]
