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


def _book(model, column):
    """Seed mean of a book-protocol row of the paper-scale protocol table (test data)."""
    t = _table("pendulum_protocols.csv")
    return float(t.loc[(t["protocol"] == "book") & (t["model"] == model), column].mean())


def _ablation(variant, column):
    t = _table("pendulum_ablation.csv")
    return float(t.loc[t["variant"] == variant, column].mean())


# (document, pattern with one group holding the quoted number, the value from the tables, decimals)
QUOTES = [
    ("docs/training_speed.md", r"a whole DRF epoch costs \*\*([0-9.]+)×",
     lambda: float(_table("pendulum_epoch_times.csv").set_index("model").loc["drf", "ratio_to_no_dynamics"]), 2),
    ("docs/dynamics.md", r"coasts better than `book` \(blackout MAE ([0-9.]+) against",
     lambda: _ablation("book_noise1", "mae_blackout"), 3),
    ("docs/dynamics.md", r"the DRF's MAE at 0.5 is ([0-9.]+),", lambda: _book("drf", "mae_0.5"), 4),
    ("docs/dynamics.md", r"the DRF's MAE at 0.5 is [0-9.]+, at 0.75 is ([0-9.]+);", lambda: _book("drf", "mae_0.75"), 3),
    ("docs/dynamics.md", r"the known-dynamics filter's\s+([0-9.]+) and", lambda: _book("known_dynamics", "mae_0.5"), 4),
    ("docs/dynamics.md", r"the known-dynamics filter's\s+[0-9.]+ and ([0-9.]+)\)", lambda: _book("known_dynamics", "mae_0.75"), 3),
    ("docs/dynamics.md", r"\*\*Gain on\s+blackout frames ≤ 0.25 of clean\*\*: missed \(([0-9.]+)\)",
     lambda: _book("drf", "gain_ratio_blackout"), 2),
    ("docs/dynamics.md", r"coasts better\s+still \(([0-9.]+)\)", lambda: _ablation("book_train1", "mae_blackout"), 3),
]


@pytest.mark.parametrize("doc,pattern,value,digits", QUOTES, ids=[f"{d}:{p[:30]}" for d, p, _, _ in QUOTES])
def test_quoted_numbers_match_their_tables(doc, pattern, value, digits):
    text = (REPO_ROOT / doc).read_text()
    found = re.findall(pattern, text)
    assert found, f"{doc} no longer quotes this number ({pattern}); update QUOTES with the prose"
    for quoted in found:
        assert float(quoted) == pytest.approx(round(value(), digits), abs=0.5 * 10 ** -digits), \
            f"{doc} quotes {quoted}, the table says {value():.{digits + 2}f}: regenerate the prose"


def test_the_readme_conclusions_quote_no_hand_typed_ratio():
    """The README's conclusions (outside the generated section) state directions, not ratios: the
    ratios live in the generated table and report.md, so a rerun cannot leave them stale."""
    text = (REPO_ROOT / "README.md").read_text()
    results = text.split("## Results", 1)[1].split("<!-- results:start -->", 1)[0]
    assert not re.findall(r"\d+(?:\.\d+)?\s*(?:–\s*\d+(?:\.\d+)?)?×", results), \
        "a hand-typed ratio in the README's conclusions: quote the generated table instead"


def test_the_round2_table_in_docs_is_the_rows_on_disk():
    """docs/dynamics.md quotes the second and third rounds' summaries; regenerate each with
    `python -m drfkit ablation --budget fit --out results/paper/ablation --summary --markdown --round N`."""
    from drfkit.study import ablation
    from drfkit.methods.protocols import ROUND2_VARIANTS, ROUND3_VARIANTS, summarise_ablation

    text = (REPO_ROOT / "docs" / "dynamics.md").read_text()
    rows = ablation.ablation_table("fit", REPO_ROOT / "results" / "paper" / "ablation")
    for tag, variants in (("round2", ROUND2_VARIANTS), ("round3", ROUND3_VARIANTS)):
        if f"<!-- {tag}:start -->" not in text:
            assert tag == "round3"   # the third round's table enters docs once its rows are committed
            continue
        quoted = text.split(f"<!-- {tag}:start -->\n", 1)[1].split(f"\n<!-- {tag}:end -->", 1)[0].strip()
        mine = rows[rows["variant"].isin(list(variants))]
        assert quoted == ablation.summary_markdown(summarise_ablation(mine)).strip(), tag
