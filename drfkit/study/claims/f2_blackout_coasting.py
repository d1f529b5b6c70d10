"""F2, the method's premise: the DRF's state coasts through 15 pure-noise frames (the prior carries
the state when the gain falls), against the baselines and a particle filter given the true physics."""
from __future__ import annotations

import math
from typing import Any

import pandas as pd

from drfkit.study.claims.dynamics_table import MECHANISM_EVIDENCE, UNKNOWN_TRAINING, drf_protocols, training_label
from drfkit.study.claims.standins import tag, variants
from drfkit.study.claims.table import CLAIMS, Claim, Rows
from drfkit.study.claims.verdicts import NOT, PARTLY, REPRODUCED, at_most, fmt_interval, seed_interval

F2_BLACKOUT_MAE = 0.10


BASELINES = ("no_dynamics", "lstm")  # the paper's baselines; references (known dynamics, particle filter) are not


def f2_blackout_coasting(blackout: pd.DataFrame, reference, target: float = F2_BLACKOUT_MAE,
                         in_distribution: str | None = None, chance: float = math.nan) -> dict[str, Any]:
    """blackout: rows (model, seed, mae_blackout) of the DRF and its baselines (``blackout_table`` or
    ``protocol_table``; other rows, references among them, are shown but not compared); reference: the
    particle filter on the same protocol's no_dynamics outputs, its MAE over the same frames (per seed, or
    one number); in_distribution: why the protocol's training frames include pure noise
    (``pure_noise_training``), None when they do not; chance: the MAE of always answering (0, 0) on the
    same frames (NaN: unknown, and then no 'partly')."""
    rows = blackout[~blackout["model"].isin(["physics_reference"])]
    stats = {k: seed_interval(g["mae_blackout"]) for k, g in rows.groupby("model", sort=False)}
    drf = stats["drf"]
    others = {k: v for k, v in stats.items() if k in BASELINES}
    shown = {k: v for k, v in stats.items() if k != "drf"}
    ref = seed_interval([reference] if isinstance(reference, (int, float)) else list(reference))
    upper = drf[0] if math.isnan(drf[2]) else drf[2]  # beyond the seeds' interval: its upper end
    beats_chance = not math.isnan(chance) and upper < chance
    verdict = (REPRODUCED if at_most(drf[0], target)
               else PARTLY if beats_chance and drf[0] < min((v[0] for v in others.values()), default=math.inf)
               else NOT)
    where = (UNKNOWN_TRAINING if in_distribution == UNKNOWN_TRAINING else
             f"in distribution ({in_distribution})" if in_distribution else
             "out of distribution (no training frame of this protocol is pure noise)")
    return {"id": "F2", "claim": "The DRF's state coasts through 15 pure-noise frames",
            "paper": "implied by the method (the prior carries the state when the gain falls)",
            "ours": f"{where}; MAE on the blackout frames: DRF {fmt_interval(drf, digits=3)}, "
                    + ", ".join(f"{k} {fmt_interval(v, digits=3)}" for k, v in shown.items())
                    + ("" if math.isnan(chance) else f"; chance (always (0, 0)) {chance:.3f}")
                    + f"; reference (particle filter with the true physics on this protocol's no_dynamics outputs, "
                      f"not a bound) {fmt_interval(ref, digits=3)}",
            "rule": f"seed means: reproduced: DRF MAE <= {target:g} on the 15 blackout frames (an error of ~6 degrees "
                    "after 2/3 of a swing without a usable frame); partly: below chance (always answering (0, 0)) "
                    f"beyond the seeds' 95 % interval and lower than each of the paper's baselines ({', '.join(BASELINES)}; "
                    "references such as the known-dynamics filter are shown, not compared); else not reproduced; "
                    "labelled in distribution when the protocol's training frames include pure noise (then coasting "
                    "is trained, not a robustness to shift); the reference is averaged over the same frames",
            "verdict": verdict}


def judge(tables) -> Rows:
    """F2 per protocol, against each protocol's particle-filter reference on its own no_dynamics
    (``pendulum_physics_reference_protocols.csv``; ``judge.Tables``)."""
    refs = tables.read("pendulum_physics_reference_protocols")
    rows: Rows = []
    for protocol, part in drf_protocols(tables):
        ref = (refs[(refs["protocol"] == protocol) & (refs["noise"].astype(str) == "blackout")]["mae"]
               if refs is not None else pd.Series(dtype=float))
        chance = float(part["mae_blackout_chance"].mean()) if "mae_blackout_chance" in part else math.nan
        for cell_, kind, (own,) in variants(protocol, tables.judged_drfs("pendulum"), part):
            rows.append((cell_, tag(f2_blackout_coasting(own, ref.to_numpy(dtype=float),
                                                         in_distribution=training_label(part), chance=chance), kind)))
    return rows


CLAIM = CLAIMS.register("F2", Claim(
    "F2", tables=("pendulum_protocols.csv", "pendulum_physics_reference_protocols.csv"),
    figures=("pendulum_blackout_protocols.png",), judge=judge, **MECHANISM_EVIDENCE))

__all__ = ["BASELINES", "F2_BLACKOUT_MAE", "f2_blackout_coasting"]
