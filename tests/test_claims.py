"""The verdict logic, fed synthetic results with known answers."""
import math

import numpy as np
import pandas as pd
import pytest

from drfkit.study import claims
from drfkit.study.evaluate import summarise, t975


def mae_table(values: dict, ci: float = 0.001) -> pd.DataFrame:
    rows = []
    for (model, noise), m in values.items():
        rows.append({"model": model, "noise": noise, "mae": m, "mae_ci": ci, "mae_lo": m - ci, "mae_hi": m + ci})
    return pd.DataFrame(rows)


def pend(drf, lstm, nod):
    return mae_table({("drf", 0.5): drf[0], ("lstm", 0.5): lstm[0], ("no_dynamics", 0.5): nod[0],
                      ("drf", 0.75): drf[1], ("lstm", 0.75): lstm[1], ("no_dynamics", 0.75): nod[1]})


def pend_by_seed(drf, lstm, nod, spread):
    """Three seeds around the given means: seed s shifts DRF by +(s-1) spread, the others by -(s-1) spread."""
    rows = []
    for seed in range(3):
        for i, lv in enumerate((0.5, 0.75)):
            for model, vals in (("drf", drf), ("lstm", lstm), ("no_dynamics", nod)):
                sign = 1 if model == "drf" else -1
                rows.append({"model": model, "seed": seed, "noise": lv, "mae": vals[i] + sign * (seed - 1) * spread})
    return pd.DataFrame(rows)


def test_c1_verdicts():
    """Reproduced needs the ordering beyond the paired seeds' interval; seed means alone give partly."""
    means = pend((1, 2), (2, 3), (3, 4))
    assert claims.c1_pendulum_mae_ordering(means, by_seed=pend_by_seed((1, 2), (2, 3), (3, 4), 0.01))["verdict"] \
        == claims.REPRODUCED
    # the same means with a seed spread that covers the gaps: the ordering may be seed noise
    assert claims.c1_pendulum_mae_ordering(means, by_seed=pend_by_seed((1, 2), (2, 3), (3, 4), 2.0))["verdict"] \
        == claims.PARTLY
    assert claims.c1_pendulum_mae_ordering(means)["verdict"] == claims.PARTLY  # no seeds: no interval
    # ordering at one level only
    assert claims.c1_pendulum_mae_ordering(pend((1, 2), (2, 4), (3, 3)))["verdict"] == claims.PARTLY
    # DRF best but LSTM worse than no_dynamics everywhere
    assert claims.c1_pendulum_mae_ordering(pend((1, 1), (3, 3), (2, 2)))["verdict"] == claims.PARTLY
    assert claims.c1_pendulum_mae_ordering(pend((3, 3), (2, 2), (1, 1)))["verdict"] == claims.NOT


def curve(points: dict, noise=0.5, ci=0.001) -> pd.DataFrame:
    """Curve points (model, noise, mpiw, picp) with a seed interval of half-width ``ci`` on PICP."""
    return pd.DataFrame([{"model": m, "noise": noise, "mpiw": x, "picp": y, "picp_lo": y - ci, "picp_hi": y + ci}
                         for m, pts in points.items() for x, y in pts])


def test_c2_dominance():
    base = [(1.0, 0.90), (2.0, 0.95), (3.0, 0.98)]
    above = [(1.5, 0.96), (2.5, 0.99)]
    below = [(1.5, 0.90), (2.5, 0.93)]
    mixed = [(1.5, 0.96), (2.5, 0.93)]
    mk = lambda drf: pd.concat([curve({"drf": drf, "lstm": base, "no_dynamics": base}, n) for n in (0.5, 0.75)])
    assert claims.c2_pendulum_picp_mpiw(mk(above))["verdict"] == claims.REPRODUCED
    assert claims.c2_pendulum_picp_mpiw(mk(mixed))["verdict"] == claims.PARTLY
    assert claims.c2_pendulum_picp_mpiw(mk(below))["verdict"] == claims.NOT
    assert claims.dominance(curve({"drf": mixed, "lstm": base}), "drf", "lstm") == 0.5


MATCHED = claims.MATCHED_MONOLOCO  # Monoloco fed the DRF family's inputs: the comparator of C3 and C4


def ped(drf, nod, lstm, mono, ci=0.01, published=None):
    """A summary whose input-matched Monoloco is ``mono``; Monoloco as published is ``published`` (default: mono)."""
    vals = {}
    for i, lv in enumerate((0.01, 0.025, 0.05)):
        vals.update({("drf", lv): drf[i], ("no_dynamics", lv): nod[i], ("lstm", lv): lstm[i],
                     (MATCHED, lv): mono[i], ("monoloco", lv): (published or mono)[i]})
    return mae_table(vals, ci)


def ped_by_seed(drf, nod, lstm, mono, spread=0.01):
    """Per-seed MAE rows: seed s adds s * spread to every model's MAE (both Monolocos at ``mono``)."""
    rows = []
    for seed in range(3):
        for i, lv in enumerate((0.01, 0.025, 0.05)):
            for model, vals in (("drf", drf), ("no_dynamics", nod), ("lstm", lstm), (MATCHED, mono), ("monoloco", mono)):
                rows.append({"model": model, "seed": seed, "noise": lv,
                             "mae": vals[i] + (seed - 1) * spread * (1 if model == "drf" else -1)})
    return pd.DataFrame(rows)


def test_c3_improvement_and_verdicts():
    table = ped_by_seed((2.5, 2.0, 2.5), (3, 2.5, 3.0), (3, 2.2, 2.8), (2.5, 2.1, 2.6), spread=0.0)
    gain, lo, hi = claims.improvement(table, "no_dynamics", (0.025, 0.05))
    assert gain == pytest.approx(((1 - 2.0 / 2.5) + (1 - 2.5 / 3.0)) / 2)
    assert lo == pytest.approx(gain) and hi == pytest.approx(gain)  # identical seeds: no spread
    table = ped_by_seed((2.5, 2.0, 2.5), (3, 2.5, 3.0), (3, 2.2, 2.8), (2.5, 2.1, 2.6))
    gain, lo, hi = claims.improvement(table, "no_dynamics", (0.025, 0.05))
    assert lo < gain < hi
    assert claims.c3_pedestrian_ood_gain(table)["verdict"] == claims.REPRODUCED
    # DRF better than no_dynamics only
    table = ped_by_seed((2.5, 2.3, 2.9), (3, 2.5, 3.0), (3, 2.2, 2.8), (2.5, 2.1, 2.6))
    assert claims.c3_pedestrian_ood_gain(table)["verdict"] == claims.PARTLY
    # a large spread over seeds: improvement positive on average against all three but not significant
    table = ped_by_seed((2.5, 2.0, 2.5), (3, 2.5, 3.0), (3, 2.2, 2.8), (2.5, 2.1, 2.6), spread=0.3)
    assert claims.c3_pedestrian_ood_gain(table)["verdict"] == claims.PARTLY
    table = ped_by_seed((3.5, 3.0, 3.5), (3, 2.5, 3.0), (3, 2.2, 2.8), (2.5, 2.1, 2.6))
    assert claims.c3_pedestrian_ood_gain(table)["verdict"] == claims.NOT


def test_c4_parity():
    mk = lambda d, m: ped((d, 1, 1), (1, 1, 1), (1, 1, 1), (m, 1, 1))
    assert claims.c4_in_distribution_parity(mk(2.6, 2.5))["verdict"] == claims.REPRODUCED
    assert claims.c4_in_distribution_parity(mk(2.0, 2.5))["verdict"] == claims.BETTER  # far better is not parity
    assert claims.c4_in_distribution_parity(mk(3.0, 2.5))["verdict"] == claims.PARTLY
    assert claims.c4_in_distribution_parity(mk(4.0, 2.5))["verdict"] == claims.NOT


def with_ci(frame: pd.DataFrame, ci: float = 0.001) -> pd.DataFrame:
    """Seed intervals of half-width ``ci`` on PICP (what notebook 04's summaries carry)."""
    return frame.assign(picp_lo=frame["picp"] - ci, picp_hi=frame["picp"] + ci)


def test_c5_over_the_curves():
    """DRF's PICP–MPIW curve (dropout rates) above each baseline's at each OOD level: reproduced; half of its
    points above each: partly; above one and below the other: not reproduced (a total loss to one baseline is not
    averaged away); below both: not reproduced."""
    base = [(8.0, 0.86), (10.0, 0.90), (12.0, 0.93)]
    above, below = [(8.5, 0.92), (10.5, 0.95)], [(8.5, 0.80), (10.5, 0.85)]

    def table(drf, other=base):
        rows = [{"study": "pedestrians", "model": "drf", "noise": 0.05, "mpiw": w, "picp": p} for w, p in drf]
        rows += [{"study": "pedestrians", "model": "lstm", "noise": 0.05, "mpiw": w, "picp": p} for w, p in base]
        rows += [{"study": "pedestrians", "model": "monoloco", "noise": 0.05, "mpiw": w, "picp": p} for w, p in other]
        return with_ci(pd.DataFrame(rows))

    conds, bases = [("pedestrians", 0.05)], {"pedestrians": ["lstm", "monoloco"]}
    assert claims.c5_intervals_under_shift(table(above), conds, bases)["verdict"] == claims.REPRODUCED
    higher_monoloco = [(w, p + 0.08) for w, p in base]
    assert claims.c5_intervals_under_shift(table(above, higher_monoloco), conds, bases)["verdict"] == claims.NOT
    half = [(8.5, 0.92), (10.5, 0.85)]                          # one point above both curves, one below both
    assert claims.c5_intervals_under_shift(table(half), conds, bases)["verdict"] == claims.PARTLY
    assert claims.c5_intervals_under_shift(table(below), conds, bases)["verdict"] == claims.NOT
    # one point per model (the default rate only): narrower and higher dominates, wider does not
    point = lambda p, w: with_ci(pd.DataFrame([{"study": "pedestrians", "model": m, "noise": 0.05, "picp": pp, "mpiw": ww}
                                               for m, pp, ww in (("drf", p, w), ("lstm", 0.9, 10.0),
                                                                 ("monoloco", 0.9, 10.0))]))
    assert claims.c5_intervals_under_shift(point(0.95, 9.0), conds, bases)["verdict"] == claims.REPRODUCED
    assert claims.c5_intervals_under_shift(point(0.95, 11.0), conds, bases)["verdict"] == claims.NOT


def paired(geo_mean: float, half: float = 0.01, n: int = 40) -> np.ndarray:
    """n per-round ratios whose geometric mean is ``geo_mean`` and whose 95 % interval (``ratio_interval``) is
    geo_mean * exp(+-half) exactly: half the rounds at geo_mean * exp(a), half at geo_mean * exp(-a)."""
    a = half * math.sqrt(n - 1) / 1.96   # t975(39) is the normal's 1.96; sd = a sqrt(n / (n - 1))
    return geo_mean * np.exp(np.r_[np.full(n // 2, a), np.full(n // 2, -a)])


def test_c6_paired_rounds_decide():
    m, lo, hi = claims.ratio_interval(paired(3.0))
    assert m == pytest.approx(3.0) and lo == pytest.approx(3.0 * math.exp(-0.01)) and hi == pytest.approx(3.0 * math.exp(0.01))
    assert claims.c6_paired(paired(3.0))["verdict"] == claims.REPRODUCED
    row = claims.c6_paired(paired(11.4))
    assert row["verdict"] == claims.DIFFERENT_FACTOR and "faster than claimed: 3.9x the paper's factor" in row["ours"]
    row = claims.c6_paired(paired(2.0))
    assert row["verdict"] == claims.DIFFERENT_FACTOR and "slower than claimed" in row["ours"]
    assert claims.c6_paired(paired(3.37, half=0.05))["verdict"] == claims.AT_EDGE   # the committed runs' case
    assert claims.c6_paired([])["verdict"] == claims.NOT_TESTABLE
    assert "40 paired rounds" in claims.c6_paired(paired(3.0))["ours"]


def test_upsert_replaces_rows_and_renders(tmp_path, monkeypatch):
    monkeypatch.setenv("DRF_RESULTS", str(tmp_path))
    claims.upsert("t", [claims.c6_paired(paired(3.0))])
    claims.upsert("t", [claims.c6_paired(paired(1.0)), claims.c4_in_distribution_parity(
        ped((2.6, 1, 1), (1, 1, 1), (1, 1, 1), (2.5, 1, 1)))])
    table = pd.read_csv(tmp_path / "t" / "claims.csv")
    assert list(table["id"]) == ["C4", "C6"]
    assert table.set_index("id").loc["C6", "verdict"] == claims.DIFFERENT_FACTOR
    text = (tmp_path / "t" / "claims.md").read_text()
    assert "| C6 |" in text
    # the claims no notebook has filled yet are named, with where they come from
    assert "Not evaluated yet in this profile: C1 (notebook 04, pendulum); C2" in text
    assert "C4 (" not in text and "C6 (" not in text and "C7b (notebook 06, pedestrians); F1" in text


def test_claims_carry_their_protocol_and_old_tables_read_as_the_papers(tmp_path, monkeypatch):
    monkeypatch.setenv("DRF_RESULTS", str(tmp_path))
    (tmp_path / "t").mkdir()
    old = pd.DataFrame([claims.c6_paired(paired(3.0))])[["id", "claim", "paper", "ours", "rule", "verdict"]]
    old.to_csv(tmp_path / "t" / "claims.csv", index=False)   # a table from before the protocol column
    claims.upsert("t", [claims.c6_paired(paired(1.0))], protocol="book")
    table = pd.read_csv(tmp_path / "t" / "claims.csv")
    assert list(zip(table["id"], table["protocol"], table["verdict"])) == [
        ("C6", "paper", claims.REPRODUCED), ("C6", "book", claims.DIFFERENT_FACTOR)]
    claims.upsert("t", [claims.c6_paired(paired(3.37, half=0.05))], protocol="paper")
    table = pd.read_csv(tmp_path / "t" / "claims.csv")
    assert list(zip(table["protocol"], table["verdict"])) == [("paper", claims.AT_EDGE),
                                                              ("book", claims.DIFFERENT_FACTOR)]
    assert "| C6 | book |" in (tmp_path / "t" / "claims.md").read_text()


def test_filter_mechanism_and_coasting_verdicts():
    def mech(rho, ratio, prior):
        return pd.DataFrame({"model": ["drf", "drf", "lstm"], "r_noise_spearman": [rho, rho, 0.0],
                             "gain_ratio_blackout": [ratio, ratio, float("nan")], "prior_ratio": [prior, prior, float("nan")]})
    assert claims.f1_filter_mechanism(mech(0.9, 0.2, 0.8), 0.75)["verdict"] == claims.REPRODUCED
    assert claims.f1_filter_mechanism(mech(0.9, 0.5, 8.0), 0.75)["verdict"] == claims.PARTLY
    assert claims.f1_filter_mechanism(mech(0.9, 0.9, 8.0), 0.75)["verdict"] == claims.NOT  # a pass-through gain
    assert claims.f1_filter_mechanism(mech(0.05, 0.92, 7.9), 0.75)["verdict"] == claims.NOT

    def dark(drf):
        return pd.DataFrame({"model": ["drf", "lstm", "no_dynamics", "physics_reference"], "seed": [0] * 4,
                             "mae_blackout": [drf, 0.5, 0.6, 0.03]})
    assert claims.f2_blackout_coasting(dark(0.08), 0.03)["verdict"] == claims.REPRODUCED
    assert claims.f2_blackout_coasting(dark(0.3), 0.03, chance=0.637)["verdict"] == claims.PARTLY
    row = claims.f2_blackout_coasting(dark(0.55), 0.03)
    assert row["verdict"] == claims.NOT and "physics_reference" not in row["ours"] and "reference" in row["ours"]
    assert " bound " not in row["ours"].replace("not a bound", "")  # the particle filter is never called a bound


def test_claims_md_names_no_missing_claim_once_all_are_filled(tmp_path, monkeypatch):
    monkeypatch.setenv("DRF_RESULTS", str(tmp_path))
    rows = [dict(zip(claims.COLUMNS, [cid, "paper", "c", "p", "o", "r", claims.PARTLY])) for cid in claims.CLAIM_SOURCES]
    claims.upsert("t", rows)
    assert "Not evaluated yet" not in (tmp_path / "t" / "claims.md").read_text()


def test_summarise_t_interval():
    frame = pd.DataFrame({"model": ["a"] * 3 + ["b"], "mae": [1.0, 2.0, 3.0, 5.0]})
    s = summarise(frame, ["model"], ["mae"]).set_index("model")
    assert s.loc["a", "mae"] == 2.0 and s.loc["a", "n_seeds"] == 3
    assert s.loc["a", "mae_ci"] == pytest.approx(t975(2) * 1.0 / math.sqrt(3))
    assert math.isnan(s.loc["b", "mae_ci"])


def test_paper_comparison_pairs_ours_with_the_paper():
    from drfkit.study.paper import PENDULUM_MAE
    from drfkit.report.writers import paper_comparison

    summary = pend((0.01, 0.05), (0.03, 0.06), (0.05, 0.1)).assign(mae_ci=0.001)
    table = paper_comparison(summary, PENDULUM_MAE).set_index(["model", "noise"])
    assert len(table) == 6
    row = table.loc[("drf", 0.75)]
    assert row["paper"] == PENDULUM_MAE[0.75]["drf"] and row["ours_over_paper"] == pytest.approx(0.05 / 0.0426968253)
    # levels the paper does not report are left out
    assert paper_comparison(summary.assign(noise=0.3), PENDULUM_MAE).empty


def test_summary_intervals_stay_inside_each_metrics_range():
    from drfkit.study.evaluate import summarise

    frame = pd.DataFrame({"model": ["a", "a"], "mae": [0.001, 0.2], "picp": [0.99, 0.6], "nll": [-3.0, 5.0]})
    row = summarise(frame, ["model"]).iloc[0]
    assert row["mae_lo"] == 0.0 and row["picp_hi"] == 1.0          # 2 seeds: a very wide t-interval, clipped
    assert row["mae_ci"] > row["mae"] and row["nll_lo"] < -3.0       # the half-width itself is kept; NLL unbounded


# ------------------------------------------------------------------ rule boundaries
def test_c4_at_its_band_edges():
    """Exactly 10 % either way is parity; just beyond is 'better' or 'partly'; 25 % is the partly edge.
    A one-sided rule (d < m counts) or a band of another width fails this."""
    mk = lambda d: ped((d, 1, 1), (1, 1, 1), (1, 1, 1), (2.0, 1, 1), ci=0.0)
    verdict = lambda d: claims.c4_in_distribution_parity(mk(d))["verdict"]
    assert verdict(2.2) == claims.REPRODUCED and verdict(1.8) == claims.REPRODUCED
    assert verdict(2.2002) == claims.PARTLY and verdict(1.7998) == claims.BETTER
    assert verdict(2.5) == claims.PARTLY and verdict(2.5002) == claims.NOT


def test_c6_at_its_thresholds():
    """The band is 2.93x +- 15 % (2.4905-3.3695x); an interval inside it reproduces, one wholly outside is a
    different factor, one across an end is at the edge: the verdict flips as one end of the interval
    crosses an end of the band."""
    lo, hi, e = 2.93 * 0.85, 2.93 * 1.15, math.exp(0.01)
    v = lambda m: claims.c6_paired(paired(m))["verdict"]  # noqa: E731 (interval m/e .. m*e)
    assert v(hi / e * 0.9999) == claims.REPRODUCED and v(hi / e * 1.0001) == claims.AT_EDGE
    assert v(hi * e * 0.9999) == claims.AT_EDGE and v(hi * e * 1.0001) == claims.DIFFERENT_FACTOR
    assert v(lo * e * 1.0001) == claims.REPRODUCED and v(lo * e * 0.9999) == claims.AT_EDGE
    assert v(lo / e * 1.0001) == claims.AT_EDGE and v(lo / e * 0.9999) == claims.DIFFERENT_FACTOR


def test_c6_rounds_for_band_follow_the_spread():
    """Rounds for an interval narrower than the band: (2 * 1.96 * sd / log(1.15 / 0.85))^2 of the log ratios."""
    x = paired(3.0, half=0.05, n=40)
    sd = float(np.log(x).std(ddof=1))
    assert claims.rounds_for_band(x) == math.ceil((2 * 1.96 * sd / math.log(1.15 / 0.85)) ** 2)
    assert claims.rounds_for_band(paired(3.0, half=0.2, n=40)) > claims.rounds_for_band(x)


def test_f1_at_its_thresholds():
    def mech(rho, ratio, prior):
        return pd.DataFrame([{"model": "drf", "r_noise_spearman": rho, "gain_ratio_blackout": ratio,
                              "prior_ratio": prior}])
    assert claims.f1_filter_mechanism(mech(0.8, 0.25, 0.999), 0.75)["verdict"] == claims.REPRODUCED
    assert claims.f1_filter_mechanism(mech(0.7999, 0.25, 0.999), 0.75)["verdict"] == claims.PARTLY
    assert claims.f1_filter_mechanism(mech(0.8, 0.2501, 0.999), 0.75)["verdict"] == claims.PARTLY
    assert claims.f1_filter_mechanism(mech(0.8, 0.25, 1.0), 0.75)["verdict"] == claims.PARTLY
    assert claims.f1_filter_mechanism(mech(0.1, 0.9, 1.2), 0.75)["verdict"] == claims.NOT


def test_c2_outside_the_baselines_range_and_saturated_levels():
    """A DRF point left of the baseline's narrowest interval counts as dominating only if its PICP is
    at least the baseline's there; a level where every PICP is saturated is not informative."""
    base = [(2.0, 0.90), (3.0, 0.95)]
    left_above = curve({"drf": [(1.0, 0.92)], "lstm": base})
    left_below = curve({"drf": [(1.0, 0.85)], "lstm": base})
    assert claims.dominance(left_above, "drf", "lstm") == 1.0
    assert claims.dominance(left_below, "drf", "lstm") == 0.0
    saturated = [(2.0, 0.998), (3.0, 0.999)]
    mk = lambda drf, b: pd.concat([curve({"drf": drf, "lstm": b, "no_dynamics": b}, n) for n in (0.5, 0.75)])
    row = claims.c2_pendulum_picp_mpiw(mk([(2.5, 0.9999)], saturated))
    assert row["verdict"] == claims.NOT_TESTABLE and "not informative" in row["ours"]
    mixed = pd.concat([curve({"drf": [(2.5, 0.9999)], "lstm": saturated, "no_dynamics": saturated}, 0.5),
                       curve({"drf": [(2.5, 0.96)], "lstm": base, "no_dynamics": base}, 0.75)])
    assert claims.c2_pendulum_picp_mpiw(mixed)["verdict"] == claims.REPRODUCED  # judged at 0.75 only


def test_c5_saturated_comparisons_are_left_out():
    rows = [{"study": "pendulum", "model": m, "noise": 0.75, "picp": p, "mpiw": w}
            for m, p, w in (("drf", 0.999, 1.0), ("lstm", 0.998, 0.5), ("no_dynamics", 0.9, 2.0))]
    row = claims.c5_intervals_under_shift(with_ci(pd.DataFrame(rows)), [("pendulum", 0.75)],
                                          {"pendulum": ["lstm", "no_dynamics"]})
    assert row["verdict"] == claims.REPRODUCED and "not informative" in row["ours"]  # 1 of 1 informative


def test_monoloco_inputs_reading_splits_the_gap_by_its_share():
    def rows(mono, fed, nd):
        return pd.DataFrame({"model": ["monoloco", "monoloco_detected_inputs", "no_dynamics"] * 2,
                             "noise": [0.01] * 3 + [0.05] * 3, "mae": [mono, fed, nd, 9.0, 9.0, 9.0]})
    inputs = claims.monoloco_inputs_reading(rows(1.4, 0.9, 0.8), 0.01)
    assert inputs["share"] == pytest.approx(5 / 6) and "mostly its published inputs" in inputs["text"]
    network = claims.monoloco_inputs_reading(rows(1.4, 1.3, 0.8), 0.01)
    assert network["share"] == pytest.approx(1 / 6) and "not its inputs" in network["text"]
    assert "no handicap" in claims.monoloco_inputs_reading(rows(0.7, 0.9, 0.8), 0.01)["text"]


def test_encoder_width_reading_flips_at_half_the_gap():
    """no_dynamics 0.90 against the input-matched Monoloco 0.80: a wide encoder at 0.85 closes exactly half the gap
    (the width is the bottleneck); at 0.8501, just under half (it is not)."""
    def rows(nd_wide, drf_wide=0.84):
        models = ["monoloco_detected_inputs", "no_dynamics", "no_dynamics_monoloco_width", "drf_monoloco_width"]
        return pd.DataFrame({"model": models, "noise": 0.01, "mae": [0.80, 0.90, nd_wide, drf_wide]})
    width = claims.encoder_width_reading(rows(0.85), 0.01)
    assert width["share"] == pytest.approx(0.5) and "the bottleneck is the encoder's width" in width["text"]
    assert "+12 %" in width["text"] and "-1 % against its encoder alone" in width["text"]
    assert "not the encoder's width" in claims.encoder_width_reading(rows(0.8501), 0.01)["text"]
    fine = rows(0.85).assign(mae=[0.9, 0.8, 0.8, 0.8])
    assert "no gap" in claims.encoder_width_reading(fine, 0.01)["text"]


def test_a_judged_drf_gets_its_own_rows_and_the_papers_drf_keeps_its_verdict():
    """F1 under the book protocol with a fifth-round DRF beside the paper's: the paper's DRF (a pass-through) is
    not reproduced with or without the other's rows, and the other DRF (a filter) is judged in its own row,
    labelled with its kind, on its own numbers."""
    from types import SimpleNamespace

    import importlib
    f1 = importlib.import_module("drfkit.study.claims.f1_filter_mechanism")
    from drfkit.study.claims.standins import as_drf, label, protocol_words

    def rows(model, rho, ratio, prior):
        return [{"protocol": "book", "model": model, "seed": s, "r_noise_spearman": rho, "gain_ratio_blackout": ratio,
                 "prior_ratio": prior} for s in range(3)]
    table = pd.DataFrame(rows("drf", 0.1, 0.95, 1.5) + rows("drf_calibrated_steep", 0.95, 0.1, 0.5)
                         + rows("no_dynamics", float("nan"), float("nan"), float("nan")))
    tables = SimpleNamespace(read=lambda name: table, P=SimpleNamespace(pendulum=SimpleNamespace(eval_max_noise=[0.75])),
                             judged_drfs=lambda study: ("drf_calibrated_steep", "absent_kind"))
    judged = dict(f1.judge(tables))
    assert set(judged) == {"book", label("book", "drf_calibrated_steep")}   # a kind without rows gets none
    assert judged["book"]["verdict"] == claims.NOT and not judged["book"]["ours"].startswith("drf_calibrated")
    steep = judged["book: drf_calibrated_steep"]
    assert steep["verdict"] == claims.REPRODUCED and steep["ours"].startswith("drf_calibrated_steep as the DRF")
    alone = dict(f1.judge(SimpleNamespace(read=lambda name: table[table["model"] != "drf_calibrated_steep"],
                                          P=tables.P, judged_drfs=tables.judged_drfs)))
    assert alone == {"book": judged["book"]}
    swapped = as_drf(table, "drf_calibrated_steep")
    assert set(swapped["model"]) == {"drf", "no_dynamics"} and (swapped.loc[swapped["model"] == "drf",
                                                                           "r_noise_spearman"] == 0.95).all()
    assert protocol_words("book: drf_calibrated_steep") == "drf_calibrated_steep, book protocol"
    assert protocol_words("paper") == "paper protocol"
