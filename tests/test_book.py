"""The book's pure parts (tools/booklib.py): anchors, the manifest check, the pages assembled from a
run, and the internal-link checker on a small HTML tree. No Sphinx, no browser: the base
environment runs these (``make book`` and ``make book-check`` build and check the real thing)."""
from __future__ import annotations

import subprocess
import sys

import pytest

from drfkit.util.paths import REPO_ROOT

sys.path.insert(0, str(REPO_ROOT / "tools"))
import booklib  # noqa: E402


@pytest.mark.slow
def test_booklib_imports_no_sphinx_or_browser():
    """make test runs without requirements-book.txt: the book's pure parts must not need it."""
    code = ("import sys; sys.path.insert(0, 'tools'); import booklib; "
            "print(sorted(m for m in ('sphinx', 'myst_nb', 'myst_parser', 'playwright') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO_ROOT, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_claim_anchors_are_unique_and_cover_every_claim():
    from drfkit.study.claims import CLAIM_EVIDENCE, CLAIM_SOURCES

    anchors = [booklib.claim_anchor(c) for c in CLAIM_SOURCES]
    assert anchors[:2] == ["claim-c1", "claim-c2"] and "claim-c7a" in anchors and "claim-f2" in anchors
    assert len(set(anchors)) == len(anchors) and set(CLAIM_EVIDENCE) == set(CLAIM_SOURCES)
    with pytest.raises(ValueError):
        booklib.claim_anchor("C1 ")


def test_slug_matches_the_notebook_headings_claims_link_to():
    assert booklib.slugify("Claims C1–C5, with computed verdicts") == "claims-c1c5-with-computed-verdicts"
    assert booklib.slugify("Blackout: does the state coast?") == "blackout-does-the-state-coast"
    assert booklib.table_anchor("ood_all_metrics_by_seed.csv") == "table-ood-all-metrics-by-seed"


def test_manifest_problems():
    want = {"pend_epochs": 20, "seeds": [0, 1], "pend_lr": 0.001}
    ok = {"status": "ok", "params": {"pend_epochs": 20, "seeds": (0, 1), "pend_lr": 1e-3}}
    assert booklib.notebook_problems("01", ok, want) == []
    failed = {"status": "failed", "params": dict(ok["params"])}
    assert "'failed'" in booklib.notebook_problems("01", failed, want)[0]
    stale = {"status": "ok", "params": {"pend_epochs": 5, "seeds": [0, 1]}}
    (problem,) = booklib.notebook_problems("01", stale, want)
    assert "pend_epochs: ran with 5, profile says 20" in problem and "pend_lr: ran with nothing" in problem
    assert booklib.params_diff(stale["params"], want) == {"pend_epochs": (5, 20), "pend_lr": ("<missing>", 0.001)}
    assert "no entry" in booklib.notebook_problems("01", None, want)[0]
    assert "cannot be read" in booklib.notebook_problems("01", ok, None, "bad yaml")[0]
    note = booklib.warning_markdown("01", "paper", [problem])
    assert note.startswith(":::{warning}") and "make reproduce PROFILE=paper" in note and note.rstrip().endswith(":::")


def test_manifest_check_against_the_real_params_api():
    """notebook_params of a profile, recorded as is, is no problem; one changed value is."""
    from drfkit.study.params import load_profile, notebook_params

    want = notebook_params("05_timing", load_profile("quick"))
    entry = {"status": "ok", "params": dict(want)}
    assert booklib.notebook_problems("05_timing", entry, want) == []
    entry["params"]["timing_batch_sizes"] = [999]
    assert "timing_batch_sizes" in booklib.notebook_problems("05_timing", entry, want)[0]


README = """# Title

Intro [a doc](docs/x.md).

## Two commands

```bash
## not a heading inside a fence
make reproduce
```

## Library at a glance (`drfkit/`)

secret

### The filter on its own

code

## Results

<!-- results:start -->
| id | claim |
|---|---|
| C1 | one |
| C7a | two |
<!-- results:end -->
"""


def test_readme_landing_keeps_user_sections_and_links_claims():
    page = booklib.readme_landing(README, "paper", ["C1", "C7a", "C7b"])
    assert "## Two commands" in page and "## not a heading inside a fence" in page
    assert "secret" not in page and "The filter on its own" not in page and "## Results" in page
    assert "| [C1](claims.md#claim-c1) | one |" in page and "| [C7a](claims.md#claim-c7a) | two |" in page
    other = booklib.readme_landing(README, "quick", ["C1"])
    assert "| C1 |" not in other and "results/quick/report.md" in other
    assert "(results/quick/report.md)" not in booklib.readme_landing(README, "quick", ["C1"], report=False)
    # the README's link to claims.md opens the book's claims page (the same rows, anchored)
    assert booklib.readme_landing("[c](results/paper/claims.md)\n", "paper", ["C1"]) == "[c](claims.md)\n"
    assert booklib.rewrite_doc_links("see [t](docs/training_speed.md)") == "see [t](training_speed.md)"
    assert booklib.appendix_order(["zeta", "trust", "choices"]) == ["choices", "trust", "zeta"]


def test_claims_page_anchors_each_claim_and_links_its_evidence():
    rows = [{"id": "C1", "protocol": "paper", "claim": "a|b", "paper": "p", "ours": "o", "verdict": "partly",
             "rule": "r"},
            {"id": "C1", "protocol": "book", "claim": "a|b", "paper": "p", "ours": "o2", "verdict": "reproduced",
             "rule": "r"}]
    evidence = {"C1": ("04_ood_noise_evaluation", "Claims C1–C5, with computed verdicts", ["t.csv", "gone.csv"],
                       ["f.png"])}
    page = booklib.claims_page(rows, evidence, "paper", ["C1", "C2"], tables=["t.csv"], figures=["f.png"],
                               figures_dir="results/paper/figures")
    assert page.count("(claim-c1)=") == 1 and "(claim-c2)=" not in page and "Not evaluated yet in this profile: C2" in page
    assert page.count("| [C1](#claim-c1) |") == 2 and "a/b" in page
    assert "(notebooks/04_ood_noise_evaluation.ipynb#claims-c1c5-with-computed-verdicts)" in page
    assert "{ref}`t.csv <table-t>`" in page and "`gone.csv` (not produced)" in page
    assert "[f.png](results/paper/figures/f.png)" in page
    tables = booklib.tables_page({"t.csv": "a,b\n1,0.123456\nx,2\n"}, "paper", "results/paper/tables", max_rows=1)
    assert "(table-t)=" in tables and "| 1 | 0.1235 |" in tables and "| x | 2 |" not in tables and "2 rows" in tables


def test_link_checker_on_a_small_tree(tmp_path):
    (tmp_path / "sub").mkdir()
    (tmp_path / "img.png").write_bytes(b"x")
    (tmp_path / "index.html").write_text(
        '<a href="sub/page.html#here">ok</a><a href="sub/page.html#nowhere">bad id</a>'
        '<a href="missing.html">bad file</a><img src="img.png"><img src="gone.png">'
        '<a href="https://example.org/x">external</a><a href="#top" id="top">self</a>'
        '<a href="../outside.html">out</a><a href="mailto:a@b">mail</a>')
    (tmp_path / "sub" / "page.html").write_text('<h2 id="here">x</h2><a href="../index.html#top">back</a>'
                                                '<a name="old"></a><a href="#old">old</a>')
    broken = booklib.check_links(tmp_path)
    assert sorted(broken) == sorted([
        "index.html: sub/page.html#nowhere (no id 'nowhere' on that page)",
        "index.html: missing.html (no such file)",
        "index.html: gone.png (no such file)",
        "index.html: ../outside.html (outside the book)"])
    (tmp_path / "index.html").write_text('<a href="sub/page.html#here" id="top">ok</a>')
    assert booklib.check_links(tmp_path) == []
