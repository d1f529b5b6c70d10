"""Claim C6: the DRF computes its aleatoric and epistemic uncertainty about 3x faster than Monoloco
(``drfkit.study.paper.TIMING_MS``, ``TIMING_SPEEDUP``), judged on notebook 05's inference benchmark."""
from __future__ import annotations

from typing import Any

import pandas as pd

from drfkit.study import paper
from drfkit.study.claims.table import CLAIMS, Claim, Rows
from drfkit.study.claims.verdicts import NOT, PARTLY, REPRODUCED, at_most

# Reproduced: within 15 % of the paper's 2.93x either way, about the spread of such timings across
# machines; a ratio far above it is a different finding (as in C4), not the paper's.
C6_TOLERANCE = 0.15
C6_CLEARLY_FASTER = 1.5
# Notebook 05's two targets of the book (not claims of the paper; C6 judges the paper's 2.93x):
# DRF's S-sample prediction at least 3x faster per frame than Monoloco as published at batch 1,
# because the paper's claim is "~3x faster" and the book's DRF should meet that round figure itself.
TIMING_SPEEDUP_TARGET = 3.0
# ... and at most 1.25x DRF's own deterministic pass, because only the decoder is sampled, in one
# batched call, so the S samples should add at most a quarter to the features' cost.
SAMPLING_OVERHEAD_TARGET = 1.25


def c6_speedup(speedup: float, target: float = paper.TIMING_SPEEDUP,
               spread: tuple[float, float] | None = None) -> dict[str, Any]:
    """``speedup``: Monoloco / DRF, both drawing their 25 samples the same way (sequential passes: the
    architecture's difference, not the batching's), per frame at batch 1; ``spread``: its range over the
    rounds' interquartile ranges (``speedup_spread``)."""
    lo, hi = target * (1 - C6_TOLERANCE), target * (1 + C6_TOLERANCE)
    verdict = (REPRODUCED if at_most(lo, speedup) and at_most(speedup, hi)
               else PARTLY if at_most(C6_CLEARLY_FASTER, speedup) else NOT)
    ours = f"{speedup:.2f}x at batch 1" + (f" [{spread[0]:.2f}, {spread[1]:.2f}] over the rounds' interquartile "
                                           "ranges" if spread is not None else "")
    if verdict == PARTLY and speedup > hi:
        ours += f"; {speedup / target:.1f}x the paper's factor"
    return {"id": "C6", "claim": "DRF computes aleatoric + epistemic uncertainty ~3x faster than Monoloco "
                                 "(25 passes, after keypoint extraction)",
            "paper": f"{paper.TIMING_MS['monoloco']} ms vs {paper.TIMING_MS['drf']} ms, {target}x (GTX 1080)",
            "ours": ours,
            "rule": "speed-up = Monoloco as published (25 sequential passes) / DRF with 25 sequential decoder passes "
                    "(like for like: the architecture's difference; drawing the samples in one batched call is a "
                    "finding of its own, reported beside it), per frame at batch 1, measured in one run (medians "
                    "over interleaved rounds); reproduced: "
                    f"within {100 * C6_TOLERANCE:.0f} % of the paper's {target}x either way ({lo:.2f}-{hi:.2f}x, "
                    "about the spread of such timings across machines); partly: outside that band but at least "
                    f"{C6_CLEARLY_FASTER:g}x (faster, by a different factor than the paper's: a ratio far above "
                    "it is another finding, as in C4); else not reproduced",
            "verdict": verdict}


def speedup_spread(mono_median: float, mono_iqr: float, drf_median: float, drf_iqr: float) -> tuple[float, float]:
    """The speed-up's range when each median moves by half its interquartile range against the other."""
    return ((mono_median - mono_iqr / 2) / (drf_median + drf_iqr / 2),
            (mono_median + mono_iqr / 2) / max(drf_median - drf_iqr / 2, 1e-12))


def c6_row(P, table: pd.DataFrame) -> dict:
    """C6 from the inference benchmark (``drfkit.study.bench``): at batch 1 on CPU with the fewest
    threads of the profile, the other thread counts and devices reported beside it."""
    b1, threads = min(P.timing.batch_sizes), min(P.timing.threads)

    def at(model, mode, t=threads, device="cpu", column="median_ms_per_frame"):
        rows = table[(table["study"] == "pedestrians") & (table["model"] == model) & (table["mode"] == mode)
                     & (table["batch"] == b1) & (table["threads"] == t) & (table["device"] == device)]
        return float(rows[column].iloc[0])

    def speedup(t=threads, device="cpu", mono="published", drf="sequential"):
        return at("monoloco", mono, t, device) / at("drf", drf, t, device)

    spread = speedup_spread(at("monoloco", "published"), at("monoloco", "published", column="iqr_ms_per_frame"),
                            at("drf", "sequential"), at("drf", "sequential", column="iqr_ms_per_frame"))
    row = c6_speedup(speedup(), spread=spread)
    groups = [("cpu", t) for t in P.timing.threads] + [(d, threads) for d in dict.fromkeys(table["device"]) if d != "cpu"]
    others = [f"{d} {t} thr: {speedup(t, d):.2f}x" for d, t in groups if (d, t) != ("cpu", threads)]
    row["ours"] += (" sequential vs sequential" + f" (CPU, {threads} thread(s), S = {P.uncertainty.n_samples}"
                    + ("; " + ", ".join(others) if others else "") + f"; 1-min load up to {table['load_1min'].max():.1f})"
                    + "; batched vs batched (both draw their samples in one call) "
                    + ", ".join(f"{speedup(t, d, 'batched', 'batched'):.2f}x" for d, t in groups)
                    + "; the DRF batched vs Monoloco as published " + f"{speedup(drf='batched'):.2f}x: batching, not the "
                    "architecture")
    return row


def judge(tables) -> Rows:
    """C6 from notebook 05's ``timing.csv`` (``judge.Tables``); the benchmark times the paper's protocol only."""
    table = tables.read("timing")
    return [] if table is None else [("paper", c6_row(tables.P, table))]


CLAIM = CLAIMS.register("C6", Claim(
    "C6", "05_timing", "notebook 05", "Claim C6 and the targets", ("timing.csv",), ("timing_ms_per_frame.png",), judge))

__all__ = ["C6_TOLERANCE", "TIMING_SPEEDUP_TARGET", "SAMPLING_OVERHEAD_TARGET", "c6_speedup", "speedup_spread",
           "c6_row"]
