"""The Monoloco the pedestrian claims (C3, C4) are judged against, and notebook 03's reading of why
Monoloco as published trails the DRF family in distribution (a diagnostic beside C4, not a claim).

The same network, loss and schedule as published, fed the DRF family's inputs (notebook 03), is the
comparator. Monoloco as published reads a different input (every keypoint centred on the box around
all 17, placeholders included, no confidences), so a gap to it mixes the network with the input; it
stays in each row as a second, labelled comparison."""
from __future__ import annotations

from typing import Any

import pandas as pd

MATCHED_MONOLOCO = "monoloco_detected_inputs"
PUBLISHED_MONOLOCO = "monoloco"
MONOLOCO_NAMES = {MATCHED_MONOLOCO: "Monoloco on the DRF family's inputs", PUBLISHED_MONOLOCO: "Monoloco as published"}


def monoloco_name(model: str) -> str:
    """How a claims row names ``model`` (either Monoloco by what it is fed; any other model by its kind)."""
    return MONOLOCO_NAMES.get(model, model)


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


# The DRF family at about Monoloco's width (``drfkit.study.pedestrian_runs.WIDE_KEYPOINT_MODELS``): its rows' names
WIDE_SUFFIX = "_monoloco_width"
# the share of the family's gap to the input-matched Monoloco that the width must close to be called the bottleneck
WIDTH_SHARE = 0.5


def encoder_width_reading(summary: pd.DataFrame, level: float) -> dict[str, Any]:
    """summary: ``summarise`` by model, noise with rows no_dynamics, drf, their ``WIDE_SUFFIX`` versions and
    ``MATCHED_MONOLOCO``. In distribution (``level``): the share of no_dynamics' gap to the input-matched Monoloco
    (the family's encoder alone, frame by frame, against a wider per-frame network on the same inputs) that the
    encoder at Monoloco's width closes, and what the recurrence adds at that width. Returns the share and a
    sentence; at least ``WIDTH_SHARE`` calls the width the bottleneck."""
    mae = summary[(summary["noise"] - level).abs() < 1e-9].set_index("model")["mae"]
    fed, nd, nd_wide = (float(mae[m]) for m in (MATCHED_MONOLOCO, "no_dynamics", "no_dynamics" + WIDE_SUFFIX))
    drf_wide = float(mae.get("drf" + WIDE_SUFFIX, float("nan")))
    pct = lambda v: f"{100 * (v / fed - 1):+.0f} %"  # noqa: E731
    recurrence = (f"; the DRF at that width {drf_wide:.3g} m ({100 * (drf_wide / nd_wide - 1):+.0f} % against its "
                  "encoder alone)" if drf_wide == drf_wide else "")
    if nd <= fed:
        return {"share": float("nan"), "text": f"At p = {level:g} the family's encoder alone ({nd:.3g} m) is no worse "
                                               f"than the input-matched Monoloco ({fed:.3g} m): no gap to explain."}
    share = (nd - nd_wide) / (nd - fed)
    cause = ("the encoder's width" if share >= WIDTH_SHARE else
             "not the encoder's width: the family's per-frame network or recipe")
    return {"share": share, "text": f"At p = {level:g} the input-matched Monoloco is at {fed:.3g} m; the DRF family's "
                                    f"encoder alone (no_dynamics) at {nd:.3g} m ({pct(nd)}), at Monoloco's width "
                                    f"{nd_wide:.3g} m ({pct(nd_wide)}){recurrence}. The width closes "
                                    f"{100 * share:.0f} % of the encoder's gap: the bottleneck is {cause}."}


__all__ = ["MATCHED_MONOLOCO", "PUBLISHED_MONOLOCO", "MONOLOCO_NAMES", "monoloco_name", "INPUTS_SHARE",
           "monoloco_inputs_reading", "WIDE_SUFFIX", "WIDTH_SHARE", "encoder_width_reading"]
