"""The study book as a website: the pure parts of ``tools/build_book.py`` (no Sphinx, no browser).

Markdown pages are assembled here from what a run produced (README, claims.csv, tables, docs/),
the notebooks are checked against the manifest, and the built HTML's internal links are checked.
Everything takes plain values, so ``tests/test_book.py`` runs with the base environment only.
"""
from __future__ import annotations

import csv
import html.parser
import io
import json
import re
from pathlib import Path
from typing import Any, Iterable
from urllib.parse import unquote, urlsplit

# README sections left out of the landing page (the rest is user-facing); a title's start
DEVELOPER_SECTIONS = ("Library at a glance",)
# docs/*.md as appendices, in this order (any other docs/*.md follows, by name)
APPENDIX_ORDER = ("choices", "troubleshooting", "dynamics", "nuscenes", "grid", "rerun_time", "trust", "training_speed",
                  "results_history", "library")
TABLE_PREVIEW_ROWS = 40


# ----------------------------------------------------------------------------- anchors
def slugify(title: str) -> str:
    """A heading's anchor, GitHub's way (also MyST's ``myst_heading_slug_func`` in book/conf.py):
    lower case, punctuation dropped, spaces to '-'. "Claims C1–C5, with computed verdicts" ->
    "claims-c1c5-with-computed-verdicts"."""
    text = re.sub(r"[^\w\- ]", "", title.strip().lower())
    return text.replace(" ", "-")


def claim_anchor(cid: str) -> str:
    """The HTML id (and Sphinx label) of a claim on the claims page: C7a -> claim-c7a."""
    if not re.fullmatch(r"[A-Za-z]+\d+[a-z]?", cid):
        raise ValueError(f"not a claim id: {cid!r}")
    return f"claim-{cid.lower()}"


def table_anchor(name: str) -> str:
    """The label of a table's section on the tables page: ood_all_metrics.csv -> table-ood-all-metrics."""
    return "table-" + re.sub(r"[^a-z0-9]+", "-", Path(name).stem.lower()).strip("-")


# ----------------------------------------------------------------------------- manifest
def _plain(value: Any) -> Any:
    """JSON's view of a value (tuples as lists, 1 == 1.0), so YAML and manifest values compare."""
    return json.loads(json.dumps(value, default=str))


def params_diff(recorded: dict[str, Any], expected: dict[str, Any]) -> dict[str, tuple[Any, Any]]:
    """{name: (recorded, expected)} for each parameter whose recorded value differs from the
    profile's ('<missing>' where one side lacks it)."""
    out = {}
    for key in sorted(set(recorded) | set(expected)):
        got, want = recorded.get(key, "<missing>"), expected.get(key, "<missing>")
        if _plain(got) != _plain(want):
            out[key] = (got, want)
    return out


def notebook_problems(name: str, entry: dict[str, Any] | None, expected: dict[str, Any] | None,
                      expected_error: str | None = None) -> list[str]:
    """Why a notebook's page must be marked: its manifest entry (``notebooks.<name>``) missing, a
    status other than ``ok``, or recorded parameters that differ from the profile's
    (``expected``: ``drfkit.study.params.notebook_params(name, load_profile(profile))``)."""
    if entry is None:
        return [f"the manifest has no entry for {name}: this page may come from another run"]
    problems = []
    status = entry.get("status")
    if status != "ok":
        problems.append(f"its run's status in the manifest is {status!r}, not 'ok'")
    if expected_error:
        problems.append(f"the profile's parameters for it cannot be read: {expected_error}")
    elif expected is not None:
        diff = params_diff(entry.get("params") or {}, expected)
        if diff:
            shown = "; ".join(f"{k}: ran with {_short(a)}, profile says {_short(b)}" for k, (a, b) in diff.items())
            problems.append(f"it ran with parameters other than the profile's ({shown})")
    return problems


def _short(value: Any, limit: int = 80) -> str:
    text = json.dumps(_plain(value)) if value != "<missing>" else "nothing (the key did not exist)"
    return text if len(text) <= limit else text[:limit - 1] + "…"


def warning_markdown(name: str, profile: str, problems: list[str]) -> str:
    """The admonition put at the top of a notebook page whose outputs may not be this profile's."""
    items = "\n".join(f"* {p}" for p in problems)
    return (f":::{{warning}}\n**These outputs may not be those of profile `{profile}` as it stands now.** "
            f"Notebook `{name}`:\n\n{items}\n\nRerun it with `make reproduce PROFILE={profile}` "
            f"(notebooks that are up to date are skipped) and build the book again.\n:::\n")


# ----------------------------------------------------------------------------- markdown pages
def _sections(text: str) -> list[tuple[str | None, str]]:
    """Split markdown at its '## ' headings outside code fences: [(title or None, text), ...]."""
    out: list[tuple[str | None, list[str]]] = [(None, [])]
    fence = None
    for line in text.splitlines(keepends=True):
        stripped = line.lstrip()
        if stripped.startswith(("```", "~~~")):
            mark = stripped[:3]
            fence = None if fence == mark else (fence or mark)
        if fence is None and line.startswith("## "):
            out.append((line[3:].strip(), []))
        out[-1][1].append(line)
    return [(title, "".join(lines)) for title, lines in out]


def link_claim_ids(text: str, claim_ids: Iterable[str], claims_page: str = "claims.md") -> str:
    """Table rows that start with a claim id get that id linked to its anchor on the claims page."""
    ids = "|".join(sorted(map(re.escape, claim_ids), key=len, reverse=True))
    return re.sub(rf"(?m)^\| ({ids}) \|",
                  lambda m: f"| [{m.group(1)}]({claims_page}#{claim_anchor(m.group(1))}) |", text)


def readme_landing(readme: str, profile: str, claim_ids: Iterable[str],
                   excluded: Iterable[str] = DEVELOPER_SECTIONS, report: bool = True) -> str:
    """The README's user-facing sections as the landing page. Its links stay valid because the
    book's source tree mirrors the repository (docs/, results/<profile>/ with executed/, tables/,
    figures/, report.md). One exception: the README's link to ``results/<profile>/claims.md`` goes
    to the book's claims page (the same rows, with an anchor and the evidence of each claim). The
    generated results block describes the paper profile, so another profile gets a pointer to its
    own pages (``report``: whether the book has its report page)."""
    excluded = tuple(excluded)
    text = "".join(body for title, body in _sections(readme) if not (title and title.startswith(excluded)))
    if profile != "paper":
        text = re.sub(r"<!-- results:start -->.*?<!-- results:end -->",
                      f"This book shows profile `{profile}`: its verdicts are on the [claims page](claims.md)"
                      + (f", every number in [its report](results/{profile}/report.md)." if report else "."),
                      text, flags=re.S)
    text = re.sub(rf"\]\(results/{re.escape(profile)}/claims\.md\)", "](claims.md)", text)
    return link_claim_ids(text, claim_ids)


def rewrite_doc_links(text: str) -> str:
    """docs/*.md link each other from the repository root (``[x](docs/y.md)``); in the book they sit
    side by side."""
    return re.sub(r"\]\(docs/", "](", text)


def _cell(value: str) -> str:
    return str(value).replace("|", "/").replace("\n", " ").strip()


def claims_page(rows: list[dict[str, str]], evidence: dict[str, tuple], profile: str,
                claim_ids: Iterable[str], notebook_dir: str = "notebooks",
                tables: Iterable[str] = (), figures: Iterable[str] = (), figures_dir: str = "figures",
                simulated: Iterable[str] = ()) -> str:
    """The claims page from claims.csv's rows: a table of every (claim, protocol) verdict, then one
    section per claim id, anchored ``claim-<id>``, linking the notebook section that judges it
    (``<notebook_dir>/<nb>.ipynb#<slug>``), its tables (``tables``: those on the tables page) and
    figures (``figures``: those under ``figures_dir``); one not produced is named, not linked."""
    tables, figures, simulated = set(tables), set(figures), set(simulated)
    order = list(claim_ids)
    by_id: dict[str, list[dict[str, str]]] = {}
    for r in rows:
        by_id.setdefault(r["id"], []).append(r)
    ids = [c for c in order if c in by_id] + sorted(set(by_id) - set(order))

    def judged_in(cid: str) -> str:
        if cid not in evidence:
            return ""
        nb, section = evidence[cid][0], evidence[cid][1]
        return f"[{nb[:2]} § {section}]({notebook_dir}/{nb}.ipynb#{slugify(section)})"

    lines = [f"# Claims of the paper, checked on profile `{profile}`", "",
             "Every row comes from `results/" + profile + "/claims.csv` (rendered there as `claims.md`); "
             "verdicts are computed by the rule of each claim (`drfkit.study.claims`). `protocol` names how the "
             "judged models were trained (`drfkit.methods.protocols`).", ""]
    if simulated:
        lines += ["Pedestrian claims (" + ", ".join(sorted(simulated)) + ") are judged on the **simulated** "
                  "pedestrian source unless the profile says `pedestrians.source: nuscenes`.", ""]
    lines += ["| id | protocol | claim | verdict | judged in |", "|---|---|---|---|---|"]
    for cid in ids:
        for r in by_id[cid]:
            lines.append(f"| [{cid}](#{claim_anchor(cid)}) | {_cell(r.get('protocol', 'paper'))} | "
                         f"{_cell(r['claim'])} | **{_cell(r['verdict'])}** | {judged_in(cid)} |")
    missing = [c for c in order if c not in by_id]
    if missing:
        lines += ["", "Not evaluated yet in this profile: " + ", ".join(missing) + "."]
    for cid in ids:
        first = by_id[cid][0]
        lines += ["", f"({claim_anchor(cid)})=", f"## {cid} · {_cell(first['claim'])}", "",
                  f"* **Paper:** {_cell(first['paper'])}"]
        if cid in evidence:
            _, _, tabs, figs = evidence[cid]
            lines.append(f"* **Judged in:** {judged_in(cid)}")
            links = [f"{{ref}}`{t} <{table_anchor(t)}>`" if t in tables else f"`{t}` (not produced)" for t in tabs]
            if links:
                lines.append("* **Tables:** " + ", ".join(links))
            if figs:
                lines.append("* **Figures:** " + ", ".join(f"[{f}]({figures_dir}/{f})" if f in figures
                                                           else f"`{f}` (not produced)" for f in figs))
        lines += ["", "| protocol | ours | verdict |", "|---|---|---|"]
        for r in by_id[cid]:
            verdict = _cell(r["verdict"]) + (" (simulated source)" if cid in simulated else "")
            lines.append(f"| {_cell(r.get('protocol', 'paper'))} | {_cell(r['ours'])} | **{verdict}** |")
        lines += ["", f"Rule: {_cell(first['rule'])}"]
    return "\n".join(lines) + "\n"


def _fmt(value: str) -> str:
    try:
        number = float(value)
    except ValueError:
        return _cell(value)
    return _cell(value) if re.fullmatch(r"-?\d+", value.strip()) else f"{number:.4g}"


def tables_page(tables: dict[str, str], profile: str, link_dir: str,
                max_rows: int = TABLE_PREVIEW_ROWS) -> str:
    """One section per CSV ({name: text}), labelled ``table_anchor(name)``: its first rows and a
    link to the whole file (``link_dir``/name)."""
    lines = [f"# Tables of profile `{profile}`", "",
             f"Every number the book shows, as `results/{profile}/tables/*.csv` (the first {max_rows} rows "
             "here; each heading's link is the whole file). Numbers are shown to 4 significant digits.", ""]
    for name in sorted(tables):
        rows = list(csv.reader(io.StringIO(tables[name])))
        header, body = (rows[0], rows[1:]) if rows else ([], [])
        lines += [f"({table_anchor(name)})=", f"## {name}", "",
                  f"[{name}]({link_dir}/{name}): {len(body)} rows, {len(header)} columns.", ""]
        if header:
            lines += ["| " + " | ".join(_cell(h) for h in header) + " |", "|" + "---|" * len(header)]
            lines += ["| " + " | ".join(_fmt(v) for v in row) + " |" for row in body[:max_rows]]
            lines.append("")
    return "\n".join(lines)


def appendix_order(names: Iterable[str]) -> list[str]:
    """docs/ page stems in the book's order: APPENDIX_ORDER first, the rest by name."""
    names = list(names)
    return [n for n in APPENDIX_ORDER if n in names] + sorted(n for n in names if n not in APPENDIX_ORDER)


# ----------------------------------------------------------------------------- built HTML
class _Collector(html.parser.HTMLParser):
    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.ids: set[str] = set()
        self.links: list[tuple[str, str]] = []  # (attribute, value)

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        for key, value in attrs:
            if value is None:
                continue
            if key == "id" or (key == "name" and tag == "a"):
                self.ids.add(value)
            elif (key == "href" and tag in ("a", "link", "area")) or (key == "src" and tag in ("img", "script", "iframe", "source")):
                self.links.append((key, value))


def _is_internal(url: str) -> bool:
    parts = urlsplit(url)
    return not parts.scheme and not parts.netloc and not url.startswith(("//", "javascript:"))


def check_links(root: Path, skip: Iterable[str] = ("_sources/", "_static/")) -> list[str]:
    """Every internal link of every HTML page under ``root`` (href of a/link, src of img/script):
    the file exists, inside ``root``, and a fragment names an id (or <a name>) of the target page
    (pages under ``skip`` are not read: the theme's template fragments in _static/).
    Returns one line per broken link ('page: link (why)'); empty when all hold."""
    root = Path(root).resolve()
    pages: dict[Path, _Collector] = {}

    def parsed(path: Path) -> _Collector:
        if path not in pages:
            c = _Collector()
            c.feed(path.read_text(encoding="utf-8", errors="replace"))
            pages[path] = c
        return pages[path]

    broken = []
    for page in sorted(root.rglob("*.html")):
        rel_page = page.relative_to(root).as_posix()
        if any(rel_page.startswith(s) for s in skip):
            continue
        for _attr, url in parsed(page).links:
            if not url or not _is_internal(url):
                continue
            parts = urlsplit(url)
            target = page if not parts.path else (page.parent / unquote(parts.path)).resolve()
            if target.is_dir():
                target = target / "index.html"
            if root not in target.parents and target != root:
                broken.append(f"{rel_page}: {url} (outside the book)")
            elif not target.is_file():
                broken.append(f"{rel_page}: {url} (no such file)")
            elif parts.fragment and target.suffix == ".html" and unquote(parts.fragment) not in parsed(target).ids:
                broken.append(f"{rel_page}: {url} (no id {unquote(parts.fragment)!r} on that page)")
    return broken
