"""What every rule shares: the verdicts, the saturation and rounding constants, the numbers a rule
reads from a summary or from per-seed rows (each with its 95 % Student-t interval over seeds), the
slices of a profile's tables a rule is fed, and the PICP–MPIW curve comparison of C2 and C5."""
from __future__ import annotations

import math
from typing import Any, Iterable

import numpy as np
import pandas as pd

from drfkit.core.metrics import t975

REPRODUCED, PARTLY, NOT = "reproduced", "partly", "not reproduced"
NOT_TESTABLE = "not testable"  # the data cannot decide (e.g. even a perfect gate could not be told from random)
BETTER = "better than the paper's parity"  # a parity claim (C4) where the DRF is far better, not equal
INCONCLUSIVE = "inconclusive"  # an equivalence claim whose interval is too wide to say equal or not (C4)
DIFFERENT_FACTOR = "a different factor"  # a factor claim (C6) whose interval lies wholly outside the paper's band
AT_EDGE = "at the band's edge"  # a factor claim whose interval straddles an end of the paper's band
VERDICTS = (REPRODUCED, PARTLY, NOT, NOT_TESTABLE, BETTER, INCONCLUSIVE, DIFFERENT_FACTOR, AT_EDGE)

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


def correlation_interval(values: Iterable[float]) -> tuple[float, float, float]:
    """Mean of per-seed correlations and a 95 % interval computed on Fisher's z = atanh(rho) (a t-interval
    of the z's, mapped back by tanh): it stays inside [-1, 1], as a t-interval of the rhos need not."""
    x = np.asarray([v for v in values if not (isinstance(v, float) and math.isnan(v))], dtype=float)
    if len(x) == 0:
        return math.nan, math.nan, math.nan
    z = np.arctanh(np.clip(x, -0.999999, 0.999999))
    mean = float(np.tanh(z.mean()))
    if len(x) < 2:
        return mean, math.nan, math.nan
    half = t975(len(x) - 1) * float(z.std(ddof=1)) / math.sqrt(len(x))
    return mean, float(np.tanh(z.mean() - half)), float(np.tanh(z.mean() + half))


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


# what pairing by seed means across model kinds: seed s of every kind sees the same data in the same order and draws
# the same dropout masks, but two architectures share no initialisation, so the pairing removes only the data's share
# of the seed-to-seed spread; a paired interval is then about as wide as an unpaired one would be
NOMINAL_PAIRING = ("paired by seed number: the same data, order and dropout draws, but no shared initialisation "
                   "across model kinds, so the pairing is nominal")


def paired_difference(by_seed: pd.DataFrame, a: str, b: str, noise: float, metric: str = "mae"
                      ) -> tuple[float, float, float]:
    """Mean over seeds of ``metric``(a) - ``metric``(b) at ``noise``, paired by seed (same data, each
    model its own initialisation), and its 95 % t-interval (NaN bounds with one seed).
    by_seed: one row per (model, seed, noise)."""
    rows = by_seed[np.isclose(by_seed["noise"].astype(float), noise)]
    table = rows.pivot_table(index="seed", columns="model", values=metric)
    return seed_interval((table[a] - table[b]).dropna())


def rows_of(frame: pd.DataFrame, study: str, protocol: str) -> pd.DataFrame:
    """The rows of one study's models trained under one protocol (a table with study, protocol columns)."""
    return frame[frame["study"].eq(study) & frame["protocol"].eq(protocol)]


def at_levels(frame: pd.DataFrame, levels) -> pd.DataFrame:
    """The rows at any of the noise ``levels`` (compared as floats, so 0.75 finds '0.75' and 0.750000001)."""
    return frame[frame["noise"].astype(float).apply(lambda v: any(math.isclose(v, float(lv)) for lv in levels))]


# ------------------------------------------------------------------------------ PICP–MPIW curves (C2, C5)
def dominance(curve: pd.DataFrame, model: str, baseline: str, x: str = "mpiw", y: str = "picp",
              y_model: str | None = None, y_base: str | None = None) -> float:
    """Fraction of ``model``'s curve points (within the baseline's x-range) lying above the
    baseline's curve interpolated linearly in x. NaN if the ranges do not overlap or a column is
    missing. ``y_model`` / ``y_base`` compare other columns than ``y`` (e.g. the model's lower
    interval bound against the baseline's upper one: above beyond the seeds' intervals)."""
    ya, yb = y_model or y, y_base or y
    a = curve[curve["model"] == model].sort_values(x)
    b = curve[curve["model"] == baseline].sort_values(x)
    if ya not in a.columns or yb not in b.columns or not len(b):
        return math.nan
    inside = a[(a[x] >= b[x].min()) & (a[x] <= b[x].max())]
    if len(inside) == 0 or len(b) < 2:
        # Outside the baseline's range: above-and-left of its narrowest point also dominates.
        left = a[(a[x] <= b[x].min()) & (a[ya] >= b.loc[b[x].idxmin(), yb])]
        return float(len(left) > 0) if len(a) else math.nan
    return float(np.mean(inside[ya].to_numpy() > np.interp(inside[x], b[x], b[yb])))


def curve_shares(sub: pd.DataFrame, base: str) -> tuple[float, float]:
    """(share of DRF points above the baseline's curve in seed means, share above it beyond the seeds'
    95 % intervals: DRF's lower PICP bound above the baseline's upper one)."""
    return dominance(sub, "drf", base), dominance(sub, "drf", base, y_model="picp_lo", y_base="picp_hi")


def share_text(share: float, beyond: float) -> str:
    if math.isnan(share):
        return "n/a"
    return f"{100 * share:.0f}%" + ("" if math.isnan(beyond) else f" ({100 * beyond:.0f}% beyond the seeds' intervals)")


def collapsed_curve(sub: pd.DataFrame, model: str = "drf") -> bool:
    """True when ``model``'s PICP–MPIW curve in ``sub`` is one point repeated over several dropout rates: its
    intervals do not move with the rate (no dropout head, as the output-units DRF's), so a curve comparison
    tests nothing about its MC dropout."""
    rows = sub[sub["model"] == model]
    return len(rows) > 1 and float(rows["mpiw"].max() - rows["mpiw"].min()) == 0.0


def collapsed_text(sub: pd.DataFrame, base: str, model: str = "drf") -> str:
    """What a collapsed curve's comparison reports instead: NLL and calibration error beside the baseline's
    (seed means, at the model's own rate: its first row; the baseline's at its default rate)."""
    def first(m):
        rows = sub[sub["model"] == m]
        return rows.iloc[0] if len(rows) else None
    a, b = first(model), first(base)
    if a is None or b is None or "nll" not in sub:
        return "its intervals do not move with the dropout rate (no dropout head)"
    return (f"no dropout head (one point for every rate): NLL {a['nll']:.3g} vs {b['nll']:.3g}, calibration error "
            f"{a['cal_error']:.3f} vs {b['cal_error']:.3f}, PICP {100 * a['picp']:.0f}% vs {100 * b['picp']:.0f}%")


# what C2 and C5 say where notebook 04 has not written the recalibrated curves (a results folder made before it did)
NOT_RECALIBRATED = ("not judged: the intervals are not recalibrated in this results folder (notebook 04 writes "
                    "ood_picp_mpiw_recalibrated.csv); as trained, every learned model's intervals are several times too "
                    "wide in distribution, and coverage would rank their excess width")


def not_recalibrated(row: dict) -> dict:
    """A curve claim's row where no recalibrated curves exist: its rule and the paper's numbers, 'not testable'."""
    return {**row, "ours": NOT_RECALIBRATED, "verdict": NOT_TESTABLE}


def curve_verdict(shares: dict) -> str:
    """The verdict of ``CURVE_RULE`` on (share, share beyond the intervals) per comparison: partly needs at least half
    of the points above in every comparison."""
    vals = [s for s, _ in shares.values() if not math.isnan(s)]
    if not vals:
        return NOT_TESTABLE
    beyond = [b for s, b in shares.values() if not math.isnan(s)]
    return (REPRODUCED if all(at_most(1.0, b) for b in beyond) else PARTLY if min(vals) >= 0.5 else NOT)


CURVE_RULE = ("a DRF whose curve is one point for every dropout rate (no dropout head) tests nothing about MC dropout: "
              "its comparisons are left out and reported with NLL and calibration error; "
              "reproduced: every DRF point lies above every baseline's curve at equal MPIW beyond the seeds' 95 % "
              "intervals (DRF's lower PICP bound above the baseline's upper bound, interpolated); partly: at least "
              "half of the DRF points lie above EACH baseline's curve in seed means (a total loss to one baseline is "
              "not averaged away); else not reproduced; every model's sigma recalibrated on validation by one "
              "scalar per model and seed (drfkit.methods.calibration) before the curves are drawn; a comparison "
              f"where every PICP is >= {100 * SATURATED_PICP:g}% is left out as not informative (intervals that "
              "cover everything cannot be ranked by coverage); not testable if none is left")


__all__ = ["NOMINAL_PAIRING", "NOT_RECALIBRATED", "not_recalibrated", "REPRODUCED", "PARTLY", "NOT", "NOT_TESTABLE", "BETTER", "INCONCLUSIVE", "DIFFERENT_FACTOR", "AT_EDGE", "VERDICTS", "SATURATED_PICP", "at_most",
           "seed_interval", "correlation_interval", "fmt_interval", "cell", "fmt", "paired_difference", "rows_of", "at_levels", "dominance",
           "curve_shares", "share_text", "curve_verdict", "CURVE_RULE", "collapsed_curve", "collapsed_text"]
