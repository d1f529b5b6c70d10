"""What every rule shares: the verdicts, the saturation and rounding constants, and the numbers a
rule reads from a summary or from per-seed rows, each with its 95 % Student-t interval over seeds."""
from __future__ import annotations

import math
from typing import Any, Iterable

import numpy as np
import pandas as pd

from drfkit.core.metrics import t975

REPRODUCED, PARTLY, NOT = "reproduced", "partly", "not reproduced"
NOT_TESTABLE = "not testable"  # the data cannot decide (e.g. even a perfect gate could not be told from random)
BETTER = "better than the paper's parity"  # a parity claim (C4) where the DRF is far better, not equal
VERDICTS = (REPRODUCED, PARTLY, NOT, NOT_TESTABLE, BETTER)

# A PICP at or above this is saturated: the 95 % intervals cover (almost) everything, so coverage
# cannot rank two models there, and differences in the last decimals are noise, not evidence.
SATURATED_PICP = 0.995
# A value exactly at a threshold is inside it; this absorbs the rounding of e.g. (2.2 - 2.0) / 2.0.
_EPS = 1e-9


def at_most(value: float, limit: float) -> bool:
    return value <= limit + _EPS


def seed_interval(values: Iterable[float]) -> tuple[float, float, float]:
    """Mean of per-seed ``values`` and its 95 % t-interval (NaN bounds with fewer than two seeds)."""
    x = np.asarray([v for v in values if not (isinstance(v, float) and math.isnan(v))], dtype=float)
    if len(x) == 0:
        return math.nan, math.nan, math.nan
    mean = float(x.mean())
    if len(x) < 2:
        return mean, math.nan, math.nan
    half = t975(len(x) - 1) * float(x.std(ddof=1)) / math.sqrt(len(x))
    return mean, mean - half, mean + half


def fmt_interval(interval: tuple[float, float, float], scale: float = 1.0, digits: int = 2, sign: bool = False,
                 unit: str = "") -> str:
    """'mean [lo, hi]' (or 'mean' alone when the interval is undefined), scaled, to ``digits`` decimals."""
    mean, lo, hi = (v * scale for v in interval)
    f = (lambda v: f"{v:+.{digits}f}") if sign else (lambda v: f"{v:.{digits}f}")  # noqa: E731
    text = f"{f(mean)}{unit}"
    return text if math.isnan(lo) else f"{text} [{f(lo)}, {f(hi)}]"


def cell(summary: pd.DataFrame, model: str, metric: str, **where: Any) -> float:
    """The one value of ``metric`` for ``model`` in a summary (``drfkit.study.evaluate.summarise``) where
    the columns equal ``where``; KeyError unless exactly one row matches."""
    rows = summary[summary["model"] == model]
    for col, val in where.items():
        rows = rows[np.isclose(rows[col], val)] if isinstance(val, float) else rows[rows[col] == val]
    if len(rows) != 1:
        raise KeyError(f"expected one row for {model} {where}, found {len(rows)}")
    return float(rows[metric].iloc[0])


def fmt(summary: pd.DataFrame, model: str, metric: str, digits: int = 4, scale: float = 1.0, **where) -> str:
    """'mean ± half-width' of a summary cell (the half-width of its 95 % t-interval over seeds)."""
    mean = cell(summary, model, metric, **where) * scale
    ci = summary.get(f"{metric}_ci")
    half = cell(summary, model, f"{metric}_ci", **where) * scale if ci is not None else math.nan
    return f"{mean:.{digits}g}" + ("" if math.isnan(half) else f" ± {half:.{digits - 1}g}")


def paired_difference(by_seed: pd.DataFrame, a: str, b: str, noise: float, metric: str = "mae"
                      ) -> tuple[float, float, float]:
    """Mean over seeds of ``metric``(a) - ``metric``(b) at ``noise``, paired by seed (same data, each
    model its own initialisation), and its 95 % t-interval (NaN bounds with one seed).
    by_seed: one row per (model, seed, noise)."""
    rows = by_seed[np.isclose(by_seed["noise"].astype(float), noise)]
    table = rows.pivot_table(index="seed", columns="model", values=metric)
    return seed_interval((table[a] - table[b]).dropna())


__all__ = ["REPRODUCED", "PARTLY", "NOT", "NOT_TESTABLE", "BETTER", "VERDICTS", "SATURATED_PICP", "at_most",
           "seed_interval", "fmt_interval", "cell", "fmt", "paired_difference"]
