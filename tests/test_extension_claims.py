"""Adding a claim is one file: a module that builds its ``Claim`` (its rule, how it is judged from a
profile's tables, where its evidence lies) and registers it in ``CLAIMS`` when imported. Here the file
is written by the test and loaded with ``drfkit.util.registry.extensions``: the judge finds it with the
book's claims, claims.csv and claims.md carry its row, the views of the registry list it, and when the
block ends it is gone again (no registry is patched by hand)."""
from __future__ import annotations

import textwrap
from types import SimpleNamespace

import pandas as pd
import pytest

from drfkit.study import claims
from drfkit.study.claims import judge
from drfkit.util.registry import extensions

CLAIM_FILE = '''
"""A toy claim: the DRF's MAE is below 1 on the toy table."""
from drfkit.study.claims.table import CLAIMS, Claim
from drfkit.study.claims.verdicts import NOT, REPRODUCED, seed_interval


def x1_toy_mae(table):
    mean, lo, hi = seed_interval(table.loc[table["model"] == "drf", "mae"])
    return {"id": "X1", "claim": "Toy: DRF MAE below 1", "paper": "0.5", "ours": f"{mean:.2f}",
            "rule": "reproduced: the seed mean below 1", "verdict": REPRODUCED if mean < 1 else NOT}


def judge(tables):
    table = tables.read("toy_numbers")
    return [] if table is None else [("paper", x1_toy_mae(table))]


CLAIMS.register("X1", Claim("X1", "07_toy", "notebook 07, toy", "A toy section", ("toy_numbers.csv",),
                            ("toy.png",), judge))
'''


@pytest.fixture
def toy_claim(tmp_path, monkeypatch):
    monkeypatch.setenv("DRF_RESULTS", str(tmp_path / "results"))
    path = tmp_path / "x1_toy_claim.py"
    path.write_text(textwrap.dedent(CLAIM_FILE))
    tables = tmp_path / "results" / "t" / "tables"
    tables.mkdir(parents=True)
    pd.DataFrame({"model": ["drf"] * 3 + ["lstm"] * 3, "seed": [0, 1, 2] * 2,
                  "mae": [0.4, 0.5, 0.6, 2.0, 2.1, 2.2]}).to_csv(tables / "toy_numbers.csv", index=False)
    return path, SimpleNamespace(profile="t")


def test_a_claim_written_as_one_file_is_judged_listed_and_gone_after_the_block(toy_claim, tmp_path):
    path, P = toy_claim
    book = list(claims.CLAIMS)
    with extensions(path):
        assert list(claims.CLAIMS) == [*book, "X1"]  # after the book's, in the claims table too
        assert claims.CLAIM_SOURCES["X1"] == "notebook 07, toy" and "X1" not in claims.PEDESTRIAN_CLAIMS
        assert claims.CLAIM_EVIDENCE["X1"] == ("07_toy", "A toy section", ["toy_numbers.csv"], ["toy.png"])
        # the judge finds it without naming it: the book's claims have no tables in this profile, so no rows
        [(protocol, row)] = judge.judge(P)
        assert protocol == "paper" and row["id"] == "X1" and row["verdict"] == claims.REPRODUCED
        claims.upsert("t", [claims.c6_paired([2.9, 3.1] * 20)])
        table = judge.write(P, ["X1"])
        assert list(table["id"]) == ["C6", "X1"]
        text = (tmp_path / "results" / "t" / "claims.md").read_text()
        assert "| X1 | paper | Toy: DRF MAE below 1 | 0.5 | 0.50 | reproduced |" in text
        assert "[toy_numbers.csv](tables/toy_numbers.csv)" in text and "X1 (" not in text
    assert list(claims.CLAIMS) == book and "X1" not in claims.CLAIM_SOURCES and "X1" not in claims.CLAIM_EVIDENCE
    assert judge.judge(P) == []
    # a profile's table may keep the row of a claim no longer registered: it is rendered last, without evidence
    text = claims.to_markdown(pd.read_csv(tmp_path / "results" / "t" / "claims.csv"), "t")
    assert "toy_numbers.csv" not in text and "X1 (" not in text and "C1 (notebook 04, pendulum)" in text


def test_a_claim_file_that_takes_a_books_id_is_refused_and_leaves_nothing(tmp_path):
    path = tmp_path / "c1_again.py"
    path.write_text(textwrap.dedent(CLAIM_FILE).replace('CLAIMS.register("X1"', 'CLAIMS.register("C1"'))
    before = dict(claims.CLAIMS)
    with pytest.raises(ValueError, match="claim 'C1' is registered already"):
        with extensions(path):
            pass
    assert dict(claims.CLAIMS) == before
