"""F1 and F2: not claims the paper states but the premise of its method. A recursive filter inside
the network is only "a filter" if its observation noise r follows frame quality (so the gain can
fall on bad frames), its transition predicts, and its state coasts through frames that hold nothing.
The book checks them (notebook 02) before reading the claims; the ablation's second round chose the
book's DRF by the same thresholds (``drfkit.study.ablation.mechanism_targets``)."""
from __future__ import annotations

import math
from typing import Any

import pandas as pd

from drfkit.study.claims.verdicts import NOT, PARTLY, REPRODUCED, at_most, fmt_interval, seed_interval

F1_RANK_CORRELATION = 0.8
F1_GAIN_RATIO = 0.25
F1_PREDICTION_RATIO = 1.0
F2_BLACKOUT_MAE = 0.10


def f1_filter_mechanism(mechanism: pd.DataFrame, noise: float) -> dict[str, Any]:
    """mechanism: rows of the DRF (model 'drf', one per seed) with r_noise_spearman,
    gain_ratio_blackout, prior_ratio (``drfkit.study.dynamics.mechanism_table`` or ``protocol_table``)."""
    drf = mechanism[mechanism["model"] == "drf"]
    rho, ratio, prior = (seed_interval(drf[c]) for c in ("r_noise_spearman", "gain_ratio_blackout", "prior_ratio"))
    checks = [at_most(F1_RANK_CORRELATION, rho[0]), at_most(ratio[0], F1_GAIN_RATIO), prior[0] < F1_PREDICTION_RATIO]
    reversed_ = at_most(rho[0], 0.0)  # r falls (or does not rise) as frames get noisier
    verdict = REPRODUCED if all(checks) else NOT if reversed_ or not any(checks) else PARTLY
    direction = ("r falls as frames get noisier: the opposite of following their quality" if rho[0] < 0 else
                 "r does not rise with the noise" if reversed_ else
                 "r rises with the noise" + ("" if checks[0] else ", too loosely to order frames by quality"))
    return {"id": "F1", "claim": "The DRF's filter filters: r follows frame quality, the gain drops on pure noise, "
                                 "F predicts the next observation",
            "paper": "implied by the method (Kalman update on a learned latent state)",
            "ours": f"rank corr(r, noise) {fmt_interval(rho, digits=2, sign=True)} at max noise {noise:g} ({direction}); "
                    f"gain pure/clean {fmt_interval(ratio)} on the blackout; ‖Fz − w‖/‖z − w‖ "
                    f"{fmt_interval(prior)} (seed means, 95 % t-intervals over {len(drf)} seeds)",
            "rule": f"seed means: reproduced: rank correlation ρ(r, noise) >= {F1_RANK_CORRELATION:g} (r orders frames "
                    f"by quality almost perfectly), gain ratio <= {F1_GAIN_RATIO:g} (on pure noise the update keeps at "
                    "most a quarter of the clean-frame correction, so the prior carries the state) and prediction "
                    f"ratio < {F1_PREDICTION_RATIO:g} (F z beats 'no change'); not reproduced: ρ <= 0 (r does not rise "
                    "with the noise, or falls: the filter cannot trust bad frames less, whatever the other two "
                    "say) or none of the three holds; partly: otherwise",
            "verdict": verdict}


# the label of a table made before it recorded its training frames (``pure_noise_training`` column)
UNKNOWN_TRAINING = ("in or out of distribution unknown (the table predates the record of its training frames; "
                    "rerun notebook 02)")


def training_label(table: pd.DataFrame) -> str | None:
    """What a protocol table says of its models' training frames: its ``pure_noise_training`` column
    (written by notebook 02 from the recipe the checkpoints were trained with; '' = none), or
    ``UNKNOWN_TRAINING`` for a table without the column."""
    if "pure_noise_training" not in table:
        return UNKNOWN_TRAINING
    values = {str(v) for v in table["pure_noise_training"].fillna("")}
    if len(values) != 1:
        raise ValueError(f"a protocol's table holds several training-frame records: {sorted(values)}")
    return values.pop() or None


def pure_noise_training(protocol: str) -> str | None:
    """Why the DRF of ``protocol`` sees pure-noise frames in training (``drfkit.methods.protocols``:
    blackouts, or a max noise of 1.0, where a frame can be all noise), or None when it never does:
    then a pure-noise blackout is out of its training distribution."""
    from drfkit.methods.protocols import PROTOCOLS, protocol_spec

    if "drf" not in PROTOCOLS.get(protocol, {}):
        return None
    spec = protocol_spec(protocol, "drf")
    if spec["blackouts"]:
        lo, hi = spec["blackouts"]["lengths"]
        return (f"this protocol trains with {lo}–{hi}-frame pure-noise blackouts in "
                f"{100 * spec['blackouts']['fraction']:.0f} % of its sequences")
    if spec["train_max_noise"] >= 1.0:
        return f"this protocol trains at max noise {spec['train_max_noise']:g}, where frames can be pure noise"
    return None


def f2_blackout_coasting(blackout: pd.DataFrame, reference, target: float = F2_BLACKOUT_MAE,
                         in_distribution: str | None = None) -> dict[str, Any]:
    """blackout: rows (model, seed, mae_blackout) of the DRF and its baselines (``blackout_table`` or
    ``protocol_table``); reference: the particle filter on the same protocol's no_dynamics outputs,
    its MAE over the same frames (per seed, or one number); in_distribution: why the protocol's
    training frames include pure noise (``pure_noise_training``), None when they do not."""
    rows = blackout[~blackout["model"].isin(["physics_bound", "physics_reference"])]
    stats = {k: seed_interval(g["mae_blackout"]) for k, g in rows.groupby("model", sort=False)}
    drf = stats["drf"]
    others = {k: v for k, v in stats.items() if k != "drf"}
    ref = seed_interval([reference] if isinstance(reference, (int, float)) else list(reference))
    verdict = (REPRODUCED if at_most(drf[0], target)
               else PARTLY if drf[0] < min((v[0] for v in others.values()), default=math.inf) else NOT)
    where = (UNKNOWN_TRAINING if in_distribution == UNKNOWN_TRAINING else
             f"in distribution ({in_distribution})" if in_distribution else
             "out of distribution (no training frame of this protocol is pure noise)")
    return {"id": "F2", "claim": "The DRF's state coasts through 15 pure-noise frames",
            "paper": "implied by the method (the prior carries the state when the gain falls)",
            "ours": f"{where}; MAE on the blackout frames: DRF {fmt_interval(drf, digits=3)}, "
                    + ", ".join(f"{k} {fmt_interval(v, digits=3)}" for k, v in others.items())
                    + f"; reference (particle filter with the true physics on this protocol's no_dynamics outputs, "
                      f"not a bound) {fmt_interval(ref, digits=3)}",
            "rule": f"seed means: reproduced: DRF MAE <= {target:g} on the 15 blackout frames (an error of ~6 degrees "
                    "after 2/3 of a swing without a usable frame); partly: lower than every baseline's; else not "
                    "reproduced; labelled in distribution when the protocol's training frames include pure noise "
                    "(then coasting is trained, not a robustness to shift); the reference is averaged over the same "
                    "frames",
            "verdict": verdict}


__all__ = ["F1_RANK_CORRELATION", "F1_GAIN_RATIO", "F1_PREDICTION_RATIO", "F2_BLACKOUT_MAE",
           "f1_filter_mechanism", "pure_noise_training", "training_label", "UNKNOWN_TRAINING", "f2_blackout_coasting"]
