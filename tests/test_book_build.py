"""The book as built (``make book``): Sphinx renders a small results tree made here -- the quick
profile as ``make quick`` leaves it, no report.md -- with ``-W``, and every internal link and figure of
the built HTML is checked. A broken link in the README fails the build, whether Sphinx sees it (a
Markdown link) or only the HTML check does (raw HTML).

These need the book's tools (requirements-book.txt, installed by ``make book``); without them they
are skipped, except under CI (``CI`` set), where ``.ci/run`` installs them first and a skip would
hide a broken book."""
from __future__ import annotations

import base64
import importlib.util
import json
import os
import sys

import nbformat
import pandas as pd
import pytest

from drfkit.util.paths import REPO_ROOT

sys.path.insert(0, str(REPO_ROOT / "tools"))
import booklib  # noqa: E402

# subprocesses, papermill, Dask or a book build: left out of the edit loop `pytest -m "not slow"`
pytestmark = pytest.mark.slow


BOOK_TOOLS = ("sphinx", "myst_nb", "sphinx_book_theme")
# a 1x1 PNG: what a notebook's figure output and a results figure hold here
PNG = base64.b64decode("iVBORw0KGgoAAAANSUhEUgAAAAEAAAABCAYAAAAfFcSJAAAADUlEQVR42mP8z8DwHwAFBQIAX8jx0gAAAABJRU5ErkJggg==")
CLAIMS = ("C1", "C6", "F2")  # three notebooks' sections, tables and figures


@pytest.fixture(scope="module")
def build_book():
    missing = [m for m in BOOK_TOOLS if importlib.util.find_spec(m) is None]
    if missing:
        message = (f"the book's tools are not installed ({', '.join(missing)}): `make book` installs "
                   f"requirements-book.txt")
        if os.environ.get("CI"):
            pytest.fail(message + "; .ci/run must install them before the tests")
        pytest.skip(message)
    import build_book as module

    return module


def quick_run(root) -> None:
    """results/quick/ as `make quick` leaves it, in small: an executed notebook per notebook (each
    section a claim links to, a figure output), the manifest, claims.csv/.md, the tables and figures
    the claims name; no report.md (only `python -m drfkit report` writes one)."""
    from drfkit.study.claims import CLAIM_EVIDENCE, to_markdown
    from drfkit.study.params import NOTEBOOKS, load_profile, notebook_params

    results = root / "quick"
    for folder in ("executed", "tables", "figures"):
        (results / folder).mkdir(parents=True)
    values = load_profile("quick")
    sections: dict[str, list[str]] = {}
    for cid in CLAIMS:
        notebook, section, tables, figures = CLAIM_EVIDENCE[cid]
        sections.setdefault(notebook, []).append(section)
        for t in tables:
            (results / "tables" / t).write_text("model,mae\ndrf,0.0123\n")
        for f in figures:
            (results / "figures" / f).write_bytes(PNG)
    manifest = {"profile": "quick", "notebooks": {}}
    for name in NOTEBOOKS:
        nb = nbformat.v4.new_notebook(metadata={"kernelspec": {"name": "python3", "display_name": "Python 3",
                                                               "language": "python"}})
        figure = nbformat.v4.new_code_cell("fig", outputs=[nbformat.v4.new_output(
            "display_data", data={"image/png": base64.b64encode(PNG).decode(), "text/plain": "<Figure>"})])
        nb.cells = [nbformat.v4.new_markdown_cell(f"# {name}\n\nWhat it does."), figure]
        for section in sections.get(name, []):
            nb.cells += [nbformat.v4.new_markdown_cell(f"## {section}\n\nThe verdicts."),
                         nbformat.v4.new_code_cell("x = 1", execution_count=1)]
        nbformat.write(nb, results / "executed" / f"{name}.ipynb")
        manifest["notebooks"][name] = {"status": "ok", "params": notebook_params(name, values)}
    (results / "manifest.json").write_text(json.dumps(manifest))
    table = pd.DataFrame([{"id": cid, "protocol": "paper", "claim": f"claim {cid}", "paper": "p", "ours": "o",
                           "rule": "r", "verdict": "partly"} for cid in CLAIMS])
    table.to_csv(results / "claims.csv", index=False)
    (results / "claims.md").write_text(to_markdown(table, "quick"))


def build(module, tmp_path, monkeypatch, readme_text: str, name: str) -> tuple[int, object]:
    root = tmp_path / "results"
    if not root.exists():
        quick_run(root)
    readme = tmp_path / f"{name}.md"
    readme.write_text(readme_text)
    out = tmp_path / name
    monkeypatch.setenv("DRF_RESULTS", str(root))  # build_book's --results sets it too: restored after the test
    code = module.main(["--profile", "quick", "--results", str(root), "--out", str(out), "--readme", str(readme)])
    return code, out


def test_the_quick_profile_book_builds_and_its_built_links_and_figures_hold(build_book, tmp_path, monkeypatch,
                                                                            capfd):
    code, out = build(build_book, tmp_path, monkeypatch, (REPO_ROOT / "README.md").read_text(), "book")
    assert code == 0, capfd.readouterr().err
    page = out / "results" / "quick" / "executed" / "04_ood_noise_evaluation.html"
    assert page.is_file() and (out / "claims.html").is_file()
    # no report.md in the run: the book renders one from the run's files, and the landing links it
    assert (out / "results" / "quick" / "report.html").is_file()
    assert 'href="results/quick/report.html"' in (out / "index.html").read_text()
    claims = (out / "claims.html").read_text()
    assert 'id="claim-c1"' in claims and "results/quick/executed/04_ood_noise_evaluation.html#" in claims
    assert booklib.check_links(out) == []
    # the HTML check sees a figure that did not make it into the site, and a dangling anchor
    images = sorted((out / "_images").glob("*.png"))
    assert images, "the notebooks' figure outputs are images of the site"
    images[0].unlink()
    (out / "claims.html").write_text((out / "claims.html").read_text().replace('id="claim-c6"', 'id="gone"'))
    broken = booklib.check_links(out)
    assert any(f"_images/{images[0].name} (no such file)" in line for line in broken), broken
    assert any("#claim-c6 (no id 'claim-c6'" in line for line in broken), broken


@pytest.mark.parametrize("broken, where", [
    ("See [the missing page](docs/no_such_page.md).", "no_such_page"),        # Sphinx -W stops on it
    ('See <a href="results/quick/executed/99_gone.html">it</a>.', "99_gone"),  # only the HTML check sees it
])
def test_a_broken_link_in_the_readme_fails_the_build(build_book, tmp_path, monkeypatch, capfd, broken, where):
    readme = (REPO_ROOT / "README.md").read_text().replace("## Where results land", f"{broken}\n\n## Where results land")
    assert broken in readme
    code, out = build(build_book, tmp_path, monkeypatch, readme, "broken")
    assert code == 1
    assert where in capfd.readouterr().err
