"""Numbers typed into the README and docs/ are checked against the committed tables they quote: a
rerun that moves a number and leaves the prose behind fails here. (Everything in the README's
generated results section and in results/paper/report.md is written by `python -m drfkit report`.)"""
import re

import pandas as pd
import pytest

from drfkit.util.paths import REPO_ROOT

TABLES = REPO_ROOT / "results" / "paper" / "tables"


def _table(name):
    return pd.read_csv(TABLES / name)


def _mean(protocol, model, column):
    """Seed mean of a row of the paper-scale protocol table (test data)."""
    t = _table("pendulum_protocols.csv")
    return float(t.loc[(t["protocol"] == protocol) & (t["model"] == model), column].mean())


def _book(model, column):
    return _mean("book", model, column)


def _worst_seed(model, column, protocol="book"):
    t = _table("pendulum_protocols.csv")
    return float(t.loc[(t["protocol"] == protocol) & (t["model"] == model), column].max())


def _ablation(variant, column):
    t = _table("pendulum_ablation.csv")
    return float(t.loc[t["variant"] == variant, column].mean())


# (document, pattern with one group holding the quoted number, the value from the tables, decimals)
QUOTES = [
    ("docs/training_speed.md", r"a whole DRF epoch costs \*\*([0-9.]+)×",
     lambda: float(_table("pendulum_epoch_times.csv").set_index("model").loc["drf", "ratio_to_no_dynamics"]), 2),
    ("docs/dynamics.md", r"coasts better than `book` \(blackout MAE ([0-9.]+) against",
     lambda: _ablation("book_noise1", "mae_blackout"), 3),
    # the fourth round's book protocol at paper scale (docs/dynamics.md, "The book's protocol at paper scale")
    ("docs/dynamics.md", r"within 1.2 × no_dynamics'\*\*: met \(([0-9.]+) against", lambda: _book("drf", "mae_0.5"), 4),
    ("docs/dynamics.md", r"within 1.2 × no_dynamics'\*\*: met \([0-9.]+ against ([0-9.]+)\)",
     lambda: _book("no_dynamics", "mae_0.5"), 4),
    ("docs/dynamics.md", r"paper's recipe left it there too but 3.5 times higher \(([0-9.]+), the paper",
     lambda: _mean("paper", "drf", "mae_0.5"), 4),
    ("docs/dynamics.md", r"not\s+told apart from no_dynamics \(([0-9.]+) against", lambda: _book("drf", "mae_0.75"), 3),
    ("docs/dynamics.md", r"not\s+told apart from no_dynamics \([0-9.]+ against ([0-9.]+)", lambda: _book("no_dynamics", "mae_0.75"), 3),
    ("docs/dynamics.md", r"worse\s+than the LSTM \(([0-9.]+)\)", lambda: _book("lstm", "mae_0.75"), 3),
    # the one no_dynamics seed that makes the differences at 0.75 (its worst)
    ("docs/dynamics.md", r"one no_dynamics seed, ([0-9.]+), makes", lambda: _worst_seed("no_dynamics", "mae_0.75"), 3),
    ("docs/dynamics.md", r"its one seed at ([0-9.]+) makes", lambda: _worst_seed("no_dynamics", "mae_0.75"), 3),
    ("docs/dynamics.md", r"through the blackout it is worse than chance \(([0-9.]+) against", lambda: _book("drf", "mae_blackout"), 2),
    ("docs/dynamics.md", r"worse than chance \([0-9.]+ against ([0-9.]+)\)", lambda: _book("drf", "mae_blackout_chance"), 2),
    ("docs/dynamics.md", r"r does not follow the noise \(ρ ([0-9.]+) over seeds\)", lambda: _book("drf", "r_noise_spearman"), 2),
    ("docs/dynamics.md", r"median spectral radius of ([0-9]+\.[0-9]+)", lambda: _book("drf", "spectral_radius_median"), 1),
    ("docs/dynamics.md", r"clean gain in \[0.3, 0.85\]: met \(([0-9.]+)\)", lambda: _book("drf_calibrated", "gain_clean"), 2),
    ("docs/dynamics.md", r"MAE at 0.5 ≤ no_dynamics': met \(([0-9.]+)", lambda: _book("drf_calibrated", "mae_0.5"), 4),
    ("docs/dynamics.md", r"Gain on pure noise ≤ 0.25 of clean: missed\s+\(([0-9.]+)\)",
     lambda: _book("drf_calibrated", "gain_ratio_blackout"), 2),
    ("docs/dynamics.md", r"Blackout ≤ 0.10: missed \(([0-9.]+), chance", lambda: _book("drf_calibrated", "mae_blackout"), 2),
    ("docs/dynamics.md", r"missed \([0-9.]+, chance ([0-9.]+)\)", lambda: _book("drf_calibrated", "mae_blackout_chance"), 2),
    ("docs/dynamics.md", r"MAE at 0.75 ≤ 0.5 × no_dynamics': missed \(([0-9.]+), below",
     lambda: _book("drf_calibrated", "mae_0.75"), 3),
    ("docs/dynamics.md", r"the seed mean of no_dynamics' ([0-9.]+), a difference", lambda: _book("no_dynamics", "mae_0.75"), 3),
    ("docs/dynamics.md", r"rule keeps all three: ([0-9.]+) at 0.5", lambda: _book("known_dynamics", "mae_0.5"), 4),
    ("docs/dynamics.md", r"at 0.75 ([0-9.]+) as a mean of", lambda: _book("known_dynamics", "mae_0.75"), 3),
    ("docs/dynamics.md", r"\*\*no_dynamics\*\* is ([0-9.]+) at 0.5", lambda: _book("no_dynamics", "mae_0.5"), 4),
    ("docs/dynamics.md", r"coasts better\s+still \(([0-9.]+)\)", lambda: _ablation("book_train1", "mae_blackout"), 3),
    # the fifth round's DRF at paper scale
    ("docs/dynamics.md", r"learned model at 0.75 \(([0-9.]+), below the LSTM's", lambda: _book("drf_calibrated_steep", "mae_0.75"), 3),
    ("docs/dynamics.md", r"below the LSTM's ([0-9.]+)\) and matches", lambda: _book("lstm", "mae_0.75"), 3),
    ("docs/dynamics.md", r"matches no_dynamics in distribution \(([0-9.]+) against", lambda: _book("drf_calibrated_steep", "mae_0.5"), 4),
    ("docs/dynamics.md", r"matches no_dynamics in distribution \([0-9.]+ against\s+([0-9.]+)\)", lambda: _book("no_dynamics", "mae_0.5"), 4),
    ("docs/dynamics.md", r"its blackout MAE of ([0-9.]+) \(chance", lambda: _book("drf_calibrated_steep", "mae_blackout"), 2),
    ("docs/dynamics.md", r"falls to ([0-9.]+) of clean in every seed", lambda: _worst_seed("drf_calibrated_steep", "gain_ratio_blackout"), 2),
    ("docs/dynamics.md", r"\(after-gap MAE ([0-9.]+), three times", lambda: _book("drf_calibrated_steep", "mae_after_blackout"), 3),
    ("docs/dynamics.md", r"it needs ([0-9]+) frames to come back", lambda: _book("drf_calibrated_steep", "frames_to_recover"), 0),
]


@pytest.mark.parametrize("doc,pattern,value,digits", QUOTES, ids=[f"{d}:{p[:30]}" for d, p, _, _ in QUOTES])
def test_quoted_numbers_match_their_tables(doc, pattern, value, digits):
    text = (REPO_ROOT / doc).read_text()
    found = re.findall(pattern, text)
    assert found, f"{doc} no longer quotes this number ({pattern}); update QUOTES with the prose"
    for quoted in found:
        assert float(quoted) == pytest.approx(round(value(), digits), abs=0.5 * 10 ** -digits), \
            f"{doc} quotes {quoted}, the table says {value():.{digits + 2}f}: regenerate the prose"


def _by_seed(cells: str) -> list[float]:
    return [float(v.replace("−", "-")) for v in cells.split(",")] if cells.strip() else []


def test_the_book_protocol_table_in_docs_is_the_committed_rows():
    """docs/dynamics.md's per-seed table of the book protocol at paper scale: every number is its row of
    pendulum_protocols.csv, rounded as printed (MAE at 0.5 to 4 decimals, at 0.75 to 3, the rest to 2); every
    model of the protocol has its row."""
    text = (REPO_ROOT / "docs" / "dynamics.md").read_text()
    block = text.split("<!-- book-protocol:start -->\n", 1)[1].split("\n<!-- book-protocol:end -->", 1)[0]
    t = _table("pendulum_protocols.csv").query("protocol == 'book'").sort_values("seed")
    columns = [("mae_0.5", 4), ("mae_0.75", 3), ("mae_blackout", 2), ("r_noise_spearman", 2), ("gain_clean", 2),
               ("gain_ratio_blackout", 2)]
    rows = [line.strip("|").split("|") for line in block.splitlines()[2:]]
    assert sorted(r[0].strip() for r in rows) == sorted(t["model"].unique())
    for cells in rows:
        mine = t[t["model"] == cells[0].strip()]
        for (column, digits), quoted in zip(columns, cells[1:]):
            values = _by_seed(quoted)
            if not values:   # a model without a filter has no r or gain to quote (its rho is its sigma's)
                assert mine["gain_clean"].isna().all() and column not in ("mae_0.5", "mae_0.75", "mae_blackout")
                continue
            assert values == pytest.approx([round(v, digits) for v in mine[column]], abs=0.51 * 10 ** -digits), \
                (cells[0], column, values)


def dissection_lines(t: pd.DataFrame) -> list[str]:
    """docs/dynamics.md's dissection lines, rendered from tables/pendulum_dissection.csv (per seed)."""
    lines = []
    def num(v, digits):  # a diverging state's error in powers of ten
        return f"{v:.{digits}f}" if abs(v) < 100 else f"{v:.1e}"
    f2, f3 = (lambda col: ", ".join(num(v, 2) for v in col)), (lambda col: ", ".join(num(v, 3) for v in col))
    for (protocol, model), g in t.groupby(["protocol", "model"], sort=False):
        g = g.sort_values("seed")
        lines.append(f"* {protocol} protocol, `{model}`: open-loop horizon H "
                     + ", ".join(str(int(v)) for v in g["open_loop_horizon"])
                     + "; blackout with the gain 0 " + f3(g["mae_blackout_clamped"]) + " (hold " + f3(g["mae_blackout_hold"])
                     + ", as it runs " + f2(g["mae_blackout"]) + ", oracle gain " + f3(g["mae_blackout_oracle_gain"])
                     + "); at 0.75 as it runs " + f3(g["mae_ood"]) + ", oracle gain " + f3(g["mae_ood_oracle_gain"])
                     + ". Verdicts: " + "; ".join(g["verdict_blackout"]) + ".")
    return lines


def _dissection() -> pd.DataFrame:
    """The dissection of every filter of both protocols on the test split (notebook 02's final paper-profile run)."""
    return _table("pendulum_dissection.csv")


def _dissection_horizons() -> pd.DataFrame:
    return _table("pendulum_dissection_horizons.csv")


def test_the_dissection_lines_in_docs_are_the_measured_rows():
    text = (REPO_ROOT / "docs" / "dynamics.md").read_text()
    block = text.split("<!-- dissection:start -->\n", 1)[1].split("\n<!-- dissection:end -->", 1)[0]
    assert block.splitlines() == dissection_lines(_dissection()), \
        "regenerate the block with tests/test_prose_numbers.py's dissection_lines"
    assert (_dissection()["clamped_gain_max"] == 0).all()   # every clamp read back as exactly 0


def both_halves_target_lines(t: pd.DataFrame) -> list[str]:
    """docs/dynamics.md's lines of the fifth round's targets, rendered from tables/pendulum_both_halves_targets.csv."""
    return [f"* `{r['model']}`, {r['target']}: **{'met' if r['met'] else 'missed'}** ({r['value']:.4g} against "
            f"{r['bound']:.4g}; by seed {r['per_seed']})" for _, r in t.iterrows()]


def test_the_fifth_round_targets_in_docs_are_the_table():
    text = (REPO_ROOT / "docs" / "dynamics.md").read_text()
    block = text.split("<!-- both-halves-targets:start -->\n", 1)[1].split("\n<!-- both-halves-targets:end -->", 1)[0]
    assert block.splitlines() == both_halves_target_lines(_table("pendulum_both_halves_targets.csv")), \
        "regenerate the block with tests/test_prose_numbers.py's both_halves_target_lines"


def test_the_reference_calibration_paragraph_is_its_table():
    """docs/dynamics.md: the book protocol's seed 1 reference sits at its scale grid's edge with no outlier term, and
    its out-of-distribution numbers are the table's."""
    text = " ".join((REPO_ROOT / "docs" / "dynamics.md").read_text().split())
    t = _table("pendulum_physics_reference_protocols.csv").query("protocol == 'book'")
    t = t.assign(noise=t["noise"].astype(str)).set_index(["seed", "noise"])
    one = t.loc[(1, "0.5")]
    assert not one["calibration_interior"] and one["outlier"] == 0 and one["sigma_scale"] == 0.125
    assert "(σ scale 0.125, outlier 0) still sits at the scale grid's edge" in text
    assert t.loc[[(s, "0.5") for s in (0, 2)], "calibration_interior"].all()
    quoted = re.search(r"\(([0-9.]+) at 0.75 and ([0-9.]+) on the blackout, against ([0-9.]+) and ([0-9.]+)\s+for seed 0\)",
                       text).groups()
    table = [t.loc[(1, "0.75"), "mae"], t.loc[(1, "blackout"), "mae"], t.loc[(0, "0.75"), "mae"],
             t.loc[(0, "blackout"), "mae"]]
    assert [float(q) for q in quoted] == pytest.approx([round(v, 3) for v in table], abs=5e-4)


def test_the_readme_conclusions_quote_no_hand_typed_ratio():
    """The README's conclusions (outside the generated section) state directions, not ratios: the
    ratios live in the generated table and report.md, so a rerun cannot leave them stale."""
    text = (REPO_ROOT / "README.md").read_text()
    results = text.split("## Results", 1)[1].split("<!-- results:start -->", 1)[0]
    assert not re.findall(r"\d+(?:\.\d+)?\s*(?:–\s*\d+(?:\.\d+)?)?×", results), \
        "a hand-typed ratio in the README's conclusions: quote the generated table instead"


def test_the_round2_table_in_docs_is_the_rows_on_disk():
    """docs/dynamics.md quotes the second and third rounds' summaries; regenerate each with
    `python -m drfkit ablation --profile paper --budget fit --summary --markdown --round N`."""
    from drfkit.study import ablation
    from drfkit.methods.protocols import ROUND2_VARIANTS, ROUND3_VARIANTS, summarise_ablation
    from drfkit.study.params import for_notebook, load_profile

    text = (REPO_ROOT / "docs" / "dynamics.md").read_text()
    rows = ablation.ablation_table(for_notebook("02_pendulum_dynamics", load_profile("paper")), "fit")
    for tag, variants in (("round2", ROUND2_VARIANTS), ("round3", ROUND3_VARIANTS)):
        if f"<!-- {tag}:start -->" not in text:
            assert tag == "round3"   # the third round's table enters docs once its rows are committed
            continue
        quoted = text.split(f"<!-- {tag}:start -->\n", 1)[1].split(f"\n<!-- {tag}:end -->", 1)[0].strip()
        mine = rows[rows["variant"].isin(list(variants))]
        assert quoted == ablation.summary_markdown(summarise_ablation(mine)).strip(), tag


# ------------------------------------------------------------------------------ orderings and verdicts in prose
def _readme():
    return (REPO_ROOT / "README.md").read_text()


def _claim(claim, protocol, column):
    t = pd.read_csv(REPO_ROOT / "results" / "paper" / "claims.csv").set_index(["id", "protocol"])
    return t.loc[(claim, protocol), column]


def _verdict(claim, protocol):
    return _claim(claim, protocol, "verdict")


# (a phrase of the README's conclusions, the claim rows whose verdicts it states; whitespace as one space)
README_VERDICTS = [
    ("its state does not coast (F1, F2 not reproduced)", [("F1", "paper", "not reproduced"),
                                                          ("F2", "paper", "not reproduced")]),
    ("trails the LSTM's at 0.75 (C1 not reproduced)", [("C1", "paper", "not reproduced")]),
    ("the blackout is guessed (C1, F1, F2 not reproduced)", [("C1", "book", "not reproduced"),
                                                             ("F1", "book", "not reproduced"),
                                                             ("F2", "book", "not reproduced")]),
    ("under either protocol (C2, C5 not reproduced)", [
        ("C2", "paper", "not reproduced"), ("C2", "book", "not reproduced"), ("C5", "paper", "not reproduced"),
        ("C5", "book", "not reproduced")]),
    ("at no_dynamics' accuracy in distribution (C1, F1, F2 partly)", [
        ("C1", "book: drf_calibrated_steep", "partly"), ("F1", "book: drf_calibrated_steep", "partly"),
        ("F2", "book: drf_calibrated_steep", "partly")]),
    ("(C4 inconclusive under both protocols", [("C4", "paper", "inconclusive"), ("C4", "book", "inconclusive")]),
    ("(C3 not reproduced)", [("C3", "paper", "not reproduced"), ("C3", "book", "not reproduced")]),
    ("(C7a reproduced, a share)", [("C7a", "paper", "reproduced")]),
    ("its interval reaching zero (C7a partly)", [("C7a", "book", "partly")]),
    ("(C7b reproduced)", [("C7b", "paper", "reproduced"), ("C7b", "book", "reproduced")]),
    ("inside the paper's band (C6 reproduced)", [("C6", "paper", "reproduced")]),
]


def _flat(text: str) -> str:
    return " ".join(text.split())


@pytest.mark.parametrize("phrase,rows", README_VERDICTS)
def test_the_readmes_conclusions_state_the_committed_verdicts(phrase, rows):
    assert phrase in _flat(_readme()), f"the README no longer says {phrase!r}: update README_VERDICTS with the prose"
    for claim, protocol, verdict in rows:
        assert _verdict(claim, protocol) == verdict, (claim, protocol)


def _claim_text(claim, protocol):
    return _claim(claim, protocol, "ours")


def test_the_readmes_orderings_are_the_tables():
    """Each ordering or comparison the README's conclusions state, against the table it comes from."""
    text = _flat(_readme())
    paper, book = (lambda m, c: _mean("paper", m, c)), _book
    # paper protocol: "its accuracy ties no_dynamics' in distribution and trails the LSTM's at 0.75"
    assert "ties no_dynamics' in distribution and trails the LSTM's at 0.75" in text
    assert abs(paper("drf", "mae_0.5") / paper("no_dynamics", "mae_0.5") - 1) < 0.1
    assert paper("lstm", "mae_0.75") < paper("drf", "mae_0.75")
    # book: "Fit well, the paper's DRF is as accurate as no_dynamics in distribution, but its filter is inert:
    # r does not follow the noise, the gain does not move, the blackout is guessed"
    assert "the paper's DRF is as accurate as no_dynamics in distribution, but its filter is inert" in text
    assert abs(book("drf", "mae_0.5") / book("no_dynamics", "mae_0.5") - 1) < 0.1
    rho = re.search(r"rank corr\(r, noise\) [+-][0-9.]+ \[([+-][0-9.]+), ([+-][0-9.]+)\]", _claim_text("F1", "book"))
    assert float(rho.group(1)) < 0 < float(rho.group(2))                 # r does not follow the noise
    assert book("drf", "gain_ratio_blackout") > 0.9                      # the gain does not move
    assert book("drf", "mae_blackout") > 0.9 * book("drf", "mae_blackout_chance")   # the blackout is guessed
    # "Every learned model's MC-dropout intervals are several times too wide in distribution": the book protocol's
    # MPIW at 0.5 against the dropout-off error (a 95 % interval of a calibrated Gaussian is about 3.9 sigma wide)
    ev = _table("ood_all_metrics.csv").query("study == 'pendulum' and protocol == 'book' and noise == 0.5")
    learned = ev[ev["model"].isin(["drf", "drf_calibrated", "drf_calibrated_steep", "no_dynamics", "lstm"])]
    assert learned["model"].nunique() == 5
    assert (learned["mpiw"] / (3.92 * learned["mae"] * 1.25) > 4).all()   # sigma_err ~ 1.25 MAE for Gaussian errors
    # the dissection: "with its gain forced to exactly 0, the paper's DRF's state diverges under either recipe, beyond
    # holding the last estimate from the second frame on"; "its transition beats hold for about 9 frames, but it keeps
    # reading pure noise"; "Only the filter with the true equations predicts through all 15 frames, in every seed"
    d, h = _dissection(), _dissection_horizons()
    assert "with its gain forced to exactly 0, the paper's DRF's state diverges under either recipe" in text
    drf = d[d["model"] == "drf"]
    assert set(drf["protocol"]) == {"paper", "book"} and (drf["open_loop_horizon"] == 0).all()
    assert (drf["mae_blackout_clamped"] > 1).all()
    late = h[(h["model"] == "drf") & (h["h"] >= 2)]
    assert (late["mae_clamped"] > late["mae_hold"]).all()
    cal = h[h["model"] == "drf_calibrated"]
    beats = cal.groupby("seed").apply(lambda g: int((g["mae_clamped"] < g["mae_hold"]).cumprod().sum()),
                                      include_groups=False)
    assert beats.between(8, 10).all() and "The calibrated-gain DRF's transition beats hold for about 9 frames" in text
    assert book("drf_calibrated", "gain_ratio_blackout") > 0.25   # it keeps reading pure noise
    predicts = d[d["open_loop_horizon"] == 15]
    assert set(predicts["model"]) == {"known_dynamics"} and len(predicts) == (d["model"] == "known_dynamics").sum()
    means = _table("pendulum_protocols.csv").groupby(["protocol", "model"])["mae_0.5"].mean()
    # "it fails, in one seed of three, because its r does not rise beyond the training levels"
    kd = _table("pendulum_protocols.csv").query("protocol == 'book' and model == 'known_dynamics'")
    assert (kd["r_noise_spearman"] < 0.5).sum() == 1 and (kd["mae_blackout"] > 0.5).sum() == 1
    # "even in distribution the book protocol's learned models are about twice the per-frame Bayes estimate,
    # the paper protocol's eight to ten times"
    limit = _table("pendulum_pixel_limit.csv").query("estimator == 'per_frame_bayes'").set_index("noise")["mae"]
    bayes = float(limit["0.5"])   # the noise column holds levels and names ('clean', 'blackout'): read as text
    ratios = means / bayes
    assert ratios["book"].between(1.8, 2.6).all() and ratios["paper"].between(7.5, 10.5).all()
    assert "the book protocol's learned models are about twice the per-frame Bayes estimate, the paper " \
           "protocol's eight to ten times" in text
    # "the Kalman gain captures two thirds of what a perfect gate gains over random ..., but that room is 1.6 points
    # where the paper's own gain was 5.8; under the book's a third, its interval reaching zero" (C7a)
    share = {p: [float(v) for v in re.search(r"KG's share of the oracle's gain ([+-]?[0-9.]+) \[([+-]?[0-9.]+), "
                                             r"([+-]?[0-9.]+)\]", _claim_text("C7a", p)).groups()]
             for p in ("paper", "book")}
    room = float(re.search(r"room \(oracle - random\) ([+-][0-9.]+) pt", _claim_text("C7a", "paper")).group(1))
    assert round(share["paper"][0] * 3) == 2 and round(room, 1) == 1.6 and "that room is 1.6 points" in text
    assert round(share["book"][0] * 3) == 1 and share["book"][1] <= 0 and "under the book's a third" in text
    # "Over paired timing rounds, sampling alike, the DRF's uncertainty is about three times cheaper than Monoloco's,
    # inside the paper's band": C6's geometric mean over its rounds and its interval
    c6 = [float(v) for v in re.search(r"([0-9.]+)x at batch 1 \[([0-9.]+), ([0-9.]+)\] over ([0-9]+) paired rounds",
                                      _claim_text("C6", "paper")).groups()]
    assert "the DRF's uncertainty is about three times cheaper than Monoloco's, inside the paper's band" in text
    assert round(c6[0]) == 3 and 2.93 * 0.85 <= c6[1] <= c6[2] <= 2.93 * 1.15 and c6[3] >= 100
    # the fifth round's DRF: "its gain on pure noise falls to a sixteenth of clean, and it is the most accurate model
    # without the true equations at 0.75 and through the blackout, at no_dynamics' accuracy in distribution"
    assert "the most accurate model without the true equations at 0.75 and through the blackout" in text
    assert "falls to a sixteenth of clean" in text and round(1 / book("drf_calibrated_steep", "gain_ratio_blackout")) == 16
    others = ["drf", "drf_calibrated", "no_dynamics", "lstm"]
    for column in ("mae_0.75", "mae_blackout"):
        assert all(book("drf_calibrated_steep", column) < book(m, column) for m in others), column
    assert abs(book("drf_calibrated_steep", "mae_0.5") / book("no_dynamics", "mae_0.5") - 1) < 0.1
    # "Its transition still drifts after 5 or 6 frames, so it does not coast through the gap and needs 7 frames to
    # recover after it"
    steep = d[(d["model"] == "drf_calibrated_steep")]
    assert "still drifts after 5 or 6 frames" in text and set(steep["open_loop_horizon"]) <= {5, 6}
    assert "needs 7 frames to recover" in text and book("drf_calibrated_steep", "frames_to_recover") == 7
    # "on the pedestrians the gain captures almost none of a perfect gate's gain"
    for protocol in ("paper", "book"):
        kg_share = float(re.search(r"KG's share of the oracle's gain ([+-]?[0-9.]+)", _claim_text("C7b", protocol)).group(1))
        assert kg_share < 0.1


def test_the_readmes_width_reading_is_notebook_03s_rule_on_its_table():
    """"Widened to Monoloco's size, the family's encoder alone is no closer to it: the width is not the bottleneck"."""
    from drfkit.study import claims
    from drfkit.study.params import for_notebook, load_profile

    assert "the family's encoder alone is no closer to it: the width is not the bottleneck" in _flat(_readme())
    P = for_notebook("03_nuscenes_training", load_profile("paper"))
    reading = claims.encoder_width_reading(_table("pedestrians_encoder_width.csv"), P.pedestrians.train_p)
    assert "the bottleneck is not the encoder's width" in reading["text"]
    t = _table("pedestrians_encoder_width.csv").query("noise == 0.01").set_index("model")["mae"]
    assert t["no_dynamics_monoloco_width"] >= t["no_dynamics"] > t["monoloco_detected_inputs"]


def test_the_regime_paragraph_states_only_what_its_summary_table_shows():
    """docs/dynamics.md draws no conclusion from the one-seed regime map and describes it as the table is."""
    text = " ".join((REPO_ROOT / "docs" / "dynamics.md").read_text().split())
    assert "two seeds on the `fit` budget, seed means without intervals, so the book draws no conclusion from it" in text
    from drfkit.study.params import load_profile
    assert load_profile("paper")["regime_seeds"] == [0, 1]
    t = _table("pendulum_regime_summary.csv")
    row = t[t["train_noise"] == 0.5].set_index("test")
    graded = row.drop(index=["blackout", "after_blackout"])
    graded = graded.set_axis(graded.index.astype(float))
    # "within 11 % of no_dynamics at every test level (`drf_over_no_dynamics` between 0.96 and 1.11)"
    ratio = graded["drf_over_no_dynamics"]
    lo, hi = re.search(r"`drf_over_no_dynamics` between ([0-9.]+) and\s+([0-9.]+)\)", text).groups()
    assert (round(ratio.min(), 2), round(ratio.max(), 2)) == (float(lo), float(hi))
    assert (ratio - 1).abs().max() < 0.115
    # "through the blackout both stay near chance (0.60 and 0.63), and so does the calibrated-gain DRF (0.65)"
    dark = row.loc["blackout"]
    quoted = re.search(r"near chance \(([0-9.]+) and ([0-9.]+)\), and so does the calibrated-gain DRF \(([0-9.]+)\)",
                       text).groups()
    assert [float(v) for v in quoted] == [round(dark[m], 2) for m in ("drf", "no_dynamics", "drf_calibrated")]
    # "the known-dynamics filter and the particle filter ... are the only models that coast (0.05 and 0.04)"
    coast = {m for m in ("drf", "drf_calibrated", "no_dynamics", "lstm", "known_dynamics", "physics_reference")
             if dark[m] <= 0.10}
    assert coast == {"known_dynamics", "physics_reference"}
    assert "only models that coast (%.2f and %.2f)" % (dark["known_dynamics"], dark["physics_reference"]) in text
    # "Trained at 1.0 ... the DRF's blackout MAE is 0.11 against no_dynamics' 0.54"
    at1 = t[(t["train_noise"] == 1.0) & (t["test"] == "blackout")].iloc[0]
    assert "blackout MAE is %.2f against no_dynamics' %.2f" % (at1["drf"], at1["no_dynamics"]) in text


def test_the_calibrated_gain_screen_in_docs_is_its_committed_table():
    """docs/dynamics.md quotes the screen's MAEs and gain slopes and names its choice: the table must say the same,
    and the book protocol must train the variant the rule chose."""
    from drfkit.methods.protocols import PROTOCOLS

    text = (REPO_ROOT / "docs" / "dynamics.md").read_text().replace("\n", " ")
    t = _table("pendulum_calibrated_screen.csv").set_index("variant")
    chosen = t.index[t["chosen"]].tolist()
    assert chosen == [PROTOCOLS["book"]["drf_calibrated"]] and f"the tie goes to `{chosen[0]}`" in text
    maes = re.search(r"validation MAEs tie within 5 % \(([0-9.]+) and ([0-9.]+)\)", text).groups()
    assert [float(m) for m in maes] == [round(t.loc[v, "mae"], 4) for v in ("fit_calibrated_wide", "fit_calibrated_prior_wide")]
    slopes = re.search(r"slope −([0-9.]+) against −([0-9.]+) per unit", text).groups()
    assert [-float(v) for v in slopes] == [round(t.loc[v, "gain_slope"], 2) for v in ("fit_calibrated_prior_wide", "fit_calibrated_wide")]


def test_the_docs_name_the_test_seed_the_paper_profile_uses():
    from drfkit.study.params import load_profile

    seed = load_profile("paper")["pend_test_seed"]
    assert f"the test split of `pend_test_seed` {seed}" in (REPO_ROOT / "docs" / "dynamics.md").read_text()
    assert seed not in (load_profile("paper")["pend_data_seed"] + k for k in (0, 1, 2))


def test_the_known_dynamics_reliability_in_docs_is_its_table():
    """docs/dynamics.md states how many of the known-dynamics filter's fit-budget seeds fail (validation
    rho(log r, level) < 0.5): the committed per-seed screen must say the same."""
    t = _table("pendulum_known_dynamics_reliability.csv")
    text = " ".join((REPO_ROOT / "docs" / "dynamics.md").read_text().split())
    m = re.search(r"on the `fit` budget (\d+) of (\d+) seeds fail", text)
    assert m and (int(m.group(1)), int(m.group(2))) == (int(t["failed"].sum()), len(t))
    lo = re.search(r"ρ\(log r, level\) between ([0-9.]+) and ([0-9.]+)", text)
    assert lo and (float(lo.group(1)), float(lo.group(2))) == (round(t["r_level_spearman"].min(), 2),
                                                              round(t["r_level_spearman"].max(), 2))


def test_the_known_dynamics_restart_rule_in_docs_is_its_table():
    """docs/dynamics.md says the restart rule fired on none of the paper-scale runs and quotes their validation rho:
    the committed restart table (dissection.restart_check) must say the same, and the profile must replace no seed."""
    from drfkit.study.params import load_profile

    t = _table("pendulum_known_dynamics_restarts.csv")
    used = t[t["used"]].sort_values("slot")
    text = " ".join((REPO_ROOT / "docs" / "dynamics.md").read_text().split())
    m = re.search(r"ρ\(log r, level\) is ([0-9.]+), ([0-9.]+) and ([0-9.]+), so no seed is replaced", text)
    assert m and [float(v) for v in m.groups()] == [round(v, 3) for v in used["r_level_spearman"]]
    assert not used["failed"].any() and (used["training_seed"] == used["slot"]).all()
    assert load_profile("paper")["pend_book_restarts"] == {}
    assert re.search(r"0 of 3 paper-scale seeds fail the in-distribution rule", text)


def test_the_rounding_or_truncation_paragraph_is_its_table():
    """docs/dynamics.md says storing the blend by truncation moves the limit and the models by under 1 % and
    quotes what the mismatched likelihood costs the limit at each level: notebook 02's table must say the same."""
    t = _table("pendulum_quantisation.csv")
    text = " ".join((REPO_ROOT / "docs" / "dynamics.md").read_text().split())
    assert "every model by under 1 % at 0.5 and 0.75" in text
    limit = t[t["estimator"] == "pixel_pf"].set_index(["noise", "frames", "likelihood"])["mae"]
    quoted = re.search(r"costs the limit ([0-9.]+) % at 0.5 and ([0-9.]+) % at 0.75", text)
    assert quoted, "docs/dynamics.md no longer quotes what the mismatched likelihood costs the limit"
    for noise, cost in zip((0.5, 0.75), quoted.groups()):
        matched = limit[(noise, "round", "round")], limit[(noise, "truncate", "truncate")]
        assert abs(matched[1] / matched[0] - 1) < 0.01
        assert float(cost) == round(100 * (limit[(noise, "truncate", "round")] / matched[1] - 1), 1)
    learned = t[t["likelihood"].isna()].groupby(["noise", "estimator", "frames"])["mae"].mean().unstack("frames")
    assert ((learned["truncate"] / learned["round"] - 1).abs() < 0.01).all()


def test_the_readme_says_the_restart_rule_passes_every_known_dynamics_seed():
    """README: the known-dynamics filter's failing seed passes the validation-only restart rule, as its table says."""
    t = _table("pendulum_known_dynamics_restarts.csv")
    text = " ".join((REPO_ROOT / "README.md").read_text().split())
    assert "the validation-only restart rule passes all three seeds" in text
    used = t[t["used"]]
    assert len(used) == 3 and not used["failed"].any()


def test_the_pedestrian_headline_is_the_tables():
    """README: "the single-frame Monoloco fed the DRF family's inputs is the most accurate model at every level; in
    distribution the book protocol's DRF is less accurate than it" (seed means; C4's paired interval for the latter)."""
    text = _flat(_readme())
    assert "the single-frame Monoloco fed the DRF family's inputs is the most accurate model at every level" in text
    matched = _table("pedestrians_monoloco_inputs.csv").query("model == 'monoloco_detected_inputs'").set_index("noise")
    ours = _table("ood_all_metrics.csv").query("study == 'pedestrians'")
    for level, row in matched.iterrows():
        others = ours[(ours["noise"] - level).abs() < 1e-9]
        assert len(others) and (others["mae"] > row["mae"]).all(), level
    assert "the interval excludes 0: Monoloco on the DRF family's inputs is more accurate than DRF" in \
        _claim_text("C4", "book") and "the book protocol's DRF is less accurate than it" in text


def test_the_pedestrian_windows_per_level_quoted_in_choices_are_the_evaluations():
    """docs/choices.md: "745 at p 0.01, 796 at 0.025, 880 at 0.05" (the test windows of each level)."""
    t = _table("ood_all_metrics_by_seed.csv")
    windows = t[t["study"] == "pedestrians"].groupby("noise")["sequences"].agg(["min", "max"])
    assert (windows["min"] == windows["max"]).all()  # one population per level, every model
    quoted = re.search(r"\(([0-9]+) at p 0.01, ([0-9]+) at 0.025, ([0-9]+) at 0.05:", (REPO_ROOT / "docs/choices.md").read_text())
    assert quoted and [int(v) for v in quoted.groups()] == [int(windows.loc[lv, "min"]) for lv in (0.01, 0.025, 0.05)]


def test_the_fifth_round_screen_table_is_the_screens_and_the_rows():
    """docs/dynamics.md's table of the fifth round's screen: ρ, gain slope, MAE, H and the open-loop MAE from
    tables/pendulum_both_halves_screen.csv (what the rule read), the blackout and gain pure/clean per seed from
    the fit-budget rows (what it did not read), and which variant is eligible and chosen."""
    import json

    screen = _table("pendulum_both_halves_screen.csv").set_index("variant")
    text = (REPO_ROOT / "docs/dynamics.md").read_text()
    rows = re.findall(r"^\| `(fit_[a-z_]+)` \| ([−\-0-9.]+) \| ([−\-0-9.]+) \| ([0-9.]+) \| ([0-9.]+) \| ([0-9.]+) \| "
                      r"([^|]+) \| ([0-9.]+), ([0-9.]+) \| ([0-9.]+), ([0-9.]+) \|$", text, flags=re.M)
    assert {r[0] for r in rows} == set(screen.index), "the docs table lists every screened variant once"
    num = lambda v: float(v.replace("−", "-"))  # noqa: E731
    for variant, rho, slope, mae, h, open_loop, verdict, *dark in rows:
        s = screen.loc[variant]
        assert (num(rho), num(slope), float(mae), float(h), float(open_loop)) == pytest.approx(
            (round(s["r_level_spearman"], 2), round(s["gain_slope"], 2), round(s["mae"], 4),
             s["open_loop_horizon"], round(s["mae_open_loop"], 2)), abs=1e-9), variant
        assert verdict.startswith("**yes") == bool(s["eligible"]) and ("chosen" in verdict) == bool(s["chosen"])
        seeds = [json.loads((REPO_ROOT / "results/paper/ablation/fit" / f"{variant}-seed{k}.json").read_text())
                 for k in (0, 1)]
        assert [float(v) for v in dark] == [round(seeds[0]["mae_blackout"], 2), round(seeds[1]["mae_blackout"], 2),
                                            round(seeds[0]["gain_ratio_blackout"], 2),
                                            round(seeds[1]["gain_ratio_blackout"], 2)], variant
