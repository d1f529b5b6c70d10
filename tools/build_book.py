"""Build the study book as a static HTML site: ``make book [PROFILE=paper]``.

Nothing is executed: a temporary source tree is assembled from what a run produced and rendered
by Sphinx + MyST-NB (``requirements-book.txt``, configuration in ``book/conf.py``):

* the README's user-facing sections as the landing page,
* the executed notebooks ``results/<profile>/executed/*.ipynb`` in order, with their outputs, at the
  same path in the book (``results/<profile>/executed/<name>.html``); a
  notebook whose manifest status is not ``ok`` or whose recorded parameters differ from the
  profile's gets a warning here and an admonition at the top of its page,
* the claims page (``claims.csv``: one anchor ``claim-<id>`` per claim, linking the notebook section
  that judges it, its tables and figures), the tables, ``report.md``, ``docs/*.md`` as appendices.

The tree mirrors the repository (``docs/``, ``results/<profile>/`` with its ``executed/``, ``tables/``,
``figures/`` and ``report.md``), so the README's, the report's and claims.md's links hold as written
(``booklib.readme_landing`` names the one exception). Sphinx runs with ``-W -n`` (a dangling reference
or a missing figure fails the build), then every internal link of the built HTML is checked
(``booklib.check_links``; ``tests/test_book_build.py`` builds a small tree and checks both).

A profile's report.md is written by ``python -m drfkit report``; where a run left none (``make
quick``), the book renders the same page from the run's files into its own source tree
(``drfkit.report.writers.report_text``), and results/ stays as the run left it.

    python tools/build_book.py --profile paper [--out results/paper/book] [--keep-src DIR]
                               [--results DIR] [--readme README.md]
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import nbformat

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tools"))
import booklib  # noqa: E402


def warn(message: str) -> None:
    print(f"book: warning: {message}", file=sys.stderr)


def expected_params(profile: str) -> tuple[dict, str | None]:
    """{notebook: its parameters under the profile as it stands} and an error, if the profile
    cannot be read (every notebook is then marked)."""
    from drfkit.study.params import NOTEBOOKS, ParameterError, load_profile, notebook_params

    try:
        values = load_profile(profile)
    except ParameterError as exc:
        return {}, str(exc)
    out = {}
    for name in NOTEBOOKS:
        try:
            out[name] = notebook_params(name, values)
        except ParameterError as exc:
            out[name] = exc
    return out, None


def notebook_dir(profile: str) -> str:
    """Where the executed notebooks sit in the book's source tree: where they sit in the repository."""
    return f"results/{profile}/executed"


def add_notebooks(src: Path, results: Path, profile: str) -> list[str]:
    """Copy the executed notebooks into src/results/<profile>/executed/ (where the README and the
    report link them), marking those the manifest does not vouch for; returns their names in order."""
    manifest_path = results / "manifest.json"
    manifest = json.loads(manifest_path.read_text()) if manifest_path.is_file() else {}
    if not manifest:
        warn(f"{manifest_path} is missing: every notebook page is marked")
    expected, profile_error = expected_params(profile)
    names = []
    target = src / notebook_dir(profile)
    target.mkdir(parents=True)
    for path in sorted((results / "executed").glob("[0-9]*.ipynb")):
        name = path.stem
        want = expected.get(name)
        error = profile_error or (str(want) if isinstance(want, Exception) else None)
        if want is None and not error:
            error = "the notebook is not one drfkit.study.params knows"
        problems = booklib.notebook_problems(name, manifest.get("notebooks", {}).get(name),
                                             None if error else want, error)
        nb = nbformat.read(path, as_version=4)
        if problems:
            warn(f"{name}: " + "; ".join(problems) + " (its page is marked)")
            note = booklib.warning_markdown(name, profile, problems)
            first = nb.cells[0] if nb.cells else None
            if first is not None and first.cell_type == "markdown" and first.source.lstrip().startswith("# "):
                title, _, rest = first.source.lstrip().partition("\n")  # right under the page's title
                first.source = f"{title}\n\n{note}\n{rest}"
            else:
                nb.cells.insert(0, nbformat.v4.new_markdown_cell(note))
        nbformat.write(nb, target / path.name)
        names.append(name)
    return names


def assemble(src: Path, profile: str, readme: Path = ROOT / "README.md") -> dict:
    """The whole source tree from results_root()/<profile>/ (``$DRF_RESULTS`` or results/), ``readme``
    and docs/; returns what went in (for the summary)."""
    from drfkit.study.claims import CLAIM_EVIDENCE, CLAIM_SOURCES, PEDESTRIAN_CLAIMS
    from drfkit.util.paths import results_root

    results = results_root() / profile
    if not sorted((results / "executed").glob("[0-9]*.ipynb")):
        raise SystemExit(f"book: no executed notebooks in {results / 'executed'}: run "
                         f"`make reproduce PROFILE={profile}` first")
    notebooks = add_notebooks(src, results, profile)
    mirror = src / "results" / profile
    mirror.mkdir(parents=True, exist_ok=True)
    for folder in ("figures", "tables"):
        if (results / folder).is_dir():
            shutil.copytree(results / folder, mirror / folder)
    tables = sorted(p.name for p in (mirror / "tables").glob("*.csv")) if (mirror / "tables").is_dir() else []
    figures = sorted(p.name for p in (mirror / "figures").glob("*.png")) if (mirror / "figures").is_dir() else []
    report = results / "report.md"
    if report.is_file():
        shutil.copy2(report, mirror / "report.md")
    elif (results / "claims.md").is_file():
        from drfkit.report.writers import report_text

        command = "make reproduce" if profile == "paper" else f"make reproduce PROFILE={profile}"
        (mirror / "report.md").write_text(report_text(profile, command), encoding="utf-8")
        print(f"book: {report} is missing: its page is rendered from the run's files "
              f"(python -m drfkit report --profiles {profile} writes the file)", file=sys.stderr)
    else:
        warn(f"{report} is missing and no claims.md to render it from: the book has no report page")
    has_report = (mirror / "report.md").is_file()

    docs = booklib.appendix_order(p.stem for p in (ROOT / "docs").glob("*.md") if p.stem != "book")
    (src / "docs").mkdir()
    for stem in docs:
        text = (ROOT / "docs" / f"{stem}.md").read_text(encoding="utf-8")
        (src / "docs" / f"{stem}.md").write_text(booklib.rewrite_doc_links(text), encoding="utf-8")

    claims_csv = results / "claims.csv"
    rows = list(csv.DictReader(claims_csv.open(encoding="utf-8"))) if claims_csv.is_file() else []
    if not rows:
        warn(f"{claims_csv} is missing or empty: the claims page lists no verdict")
    (src / "claims.md").write_text(booklib.claims_page(
        rows, CLAIM_EVIDENCE, profile, list(CLAIM_SOURCES), notebook_dir=notebook_dir(profile), tables=tables,
        figures=figures, figures_dir=f"results/{profile}/figures", simulated=PEDESTRIAN_CLAIMS), encoding="utf-8")
    (src / "tables.md").write_text(booklib.tables_page(
        {t: (mirror / "tables" / t).read_text(encoding="utf-8") for t in tables}, profile,
        link_dir=f"results/{profile}/tables"), encoding="utf-8")

    landing = booklib.readme_landing(Path(readme).read_text(encoding="utf-8"), profile, list(CLAIM_SOURCES),
                                     report=has_report)

    def toctree(caption: str, entries: list[str]) -> str:
        return "\n".join(["```{toctree}", f":caption: {caption}", ":maxdepth: 1", "", *entries, "```", ""])

    landing += "\n## This book\n\n" + "\n".join([
        toctree("Notebooks", [f"{notebook_dir(profile)}/{n}" for n in notebooks]),
        toctree("Results", ["claims"] + ([f"results/{profile}/report"] if has_report else [])),
        toctree("Appendices", [f"docs/{d}" for d in docs] + ["tables"]),
    ])
    (src / "index.md").write_text(landing, encoding="utf-8")
    return {"notebooks": notebooks, "docs": docs, "tables": len(tables), "claims": len(rows)}


def sphinx(src: Path, out: Path, doctrees: Path, profile: str) -> int:
    cmd = [sys.executable, "-m", "sphinx", "-b", "html", "-E", "-W", "--keep-going", "-n", "-q",
           "-c", str(ROOT / "book"), "-d", str(doctrees), str(src), str(out)]
    return subprocess.call(cmd, env={**os.environ, "BOOK_PROFILE": profile})


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--profile", default="paper")
    ap.add_argument("--out", type=Path, help="default: results/<profile>/book")
    ap.add_argument("--keep-src", type=Path, help="also keep the assembled source tree here")
    ap.add_argument("--results", type=Path, help="the results root holding <profile>/ (default: $DRF_RESULTS or results/)")
    ap.add_argument("--readme", type=Path, default=ROOT / "README.md", help="the landing page's source")
    args = ap.parse_args(argv)
    if args.results:
        os.environ["DRF_RESULTS"] = str(args.results.resolve())  # drfkit.util.paths.results_root
    from drfkit.util.paths import results_root

    out = (args.out or results_root() / args.profile / "book").resolve()
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="drf-book-") as tmp:
        src = Path(tmp) / "src"
        src.mkdir()
        info = assemble(src, args.profile, args.readme)
        if args.keep_src:
            shutil.rmtree(args.keep_src, ignore_errors=True)
            shutil.copytree(src, args.keep_src)
        # built inside the temporary folder: MyST-NB writes jupyter_execute/ beside the output folder
        html = Path(tmp) / "html"
        if sphinx(src, html, Path(tmp) / "doctrees", args.profile) != 0:
            print("book: the Sphinx build failed (warnings are errors: a dangling reference or a missing "
                  "figure is one); see above", file=sys.stderr)
            return 1
        if out.exists():
            shutil.rmtree(out)
        out.parent.mkdir(parents=True, exist_ok=True)
        shutil.move(str(html), str(out))
    broken = booklib.check_links(out)
    if broken:
        print(f"book: {len(broken)} broken internal link(s) in the built HTML:", file=sys.stderr)
        for line in broken[:50]:
            print("  " + line, file=sys.stderr)
        return 1
    pages = sum(1 for _ in out.rglob("*.html"))
    print(f"book: {out.relative_to(ROOT) if ROOT in out.parents else out}/index.html — {len(info['notebooks'])} "
          f"notebooks, {info['claims']} claim rows, {info['tables']} tables, {len(info['docs'])} appendices, "
          f"{pages} pages, every internal link checked, {time.perf_counter() - started:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
