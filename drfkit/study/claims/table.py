"""The claims table: every claim registered once (``CLAIMS``: its rule's entry point, who judges it,
where its evidence lies), ``results/<profile>/claims.csv`` kept one row per (claim, protocol) by
``upsert``, and its rendering as ``claims.md``.

A claim is one module of this package (or an extension file, ``drfkit.util.registry``) that builds
its ``Claim`` and registers it in ``CLAIMS``; the views below (sources, evidence, claims judged on the
simulated pedestrians) are read from the registry when asked for, so a claim registered later is in
them, and one taken out again is not."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import pandas as pd

from drfkit.study.claims.standins import protocol_words
from drfkit.study.claims.verdicts import REPRODUCED
from drfkit.util.io import atomic_write_csv, atomic_write_text
from drfkit.util.paths import results_dir
from drfkit.util.registry import Registry

COLUMNS = ["id", "protocol", "claim", "paper", "ours", "rule", "verdict"]

Rows = list[tuple[str, dict]]  # (protocol, claims row): what judging a claim gives, one per protocol it is judged in


@dataclass(frozen=True)
class Claim:
    """A claim and where it is judged: the notebook that fills its row (``drfkit.study.claims.judge``
    judges it from that notebook's tables), what claims.md says when it has not, the notebook's section,
    and the tables and figures the verdict reads (under results/<profile>/; a protocol other than the
    paper's has its figures as <study>_<protocol>_...).

    ``judge`` turns the inputs named by ``reads`` (``judge.INPUTS``: "tables", a profile's tables read on
    demand, or what a notebook's claims share, built once for all of them) into rows; it gives none when
    its tables are missing. ``simulated``: judged on the simulated pedestrian source unless the profile
    says ``pedestrians.source: nuscenes``."""

    id: str
    notebook: str
    source: str
    section: str
    tables: tuple[str, ...]
    figures: tuple[str, ...]
    judge: Callable[[Any], Rows]
    reads: str = "tables"
    simulated: bool = False


# claim id -> Claim, in the order of the claims table's rows (registration order: the package's
# __init__ imports the paper's claims in order, an extension's come after)
CLAIMS = Registry("claim")


def claim_sources() -> dict[str, str]:
    """Every claim row and what fills it: claims.md lists the ones a profile has not evaluated yet."""
    return {cid: c.source for cid, c in CLAIMS.items()}


def claim_evidence() -> dict[str, tuple[str, str, list[str], list[str]]]:
    """Where each claim is judged: (notebook, section, tables, figures)."""
    return {cid: (c.notebook, c.section, list(c.tables), list(c.figures)) for cid, c in CLAIMS.items()}


def simulated_claims() -> tuple[str, ...]:
    """Claims whose evidence is the simulated pedestrian source by default (pedestrians.source: simulated)."""
    return tuple(cid for cid, c in CLAIMS.items() if c.simulated)


# the views under the names their readers import (made when read, never stored: see the module's docstring)
VIEWS = {"CLAIM_SOURCES": claim_sources, "CLAIM_EVIDENCE": claim_evidence, "PEDESTRIAN_CLAIMS": simulated_claims}


def __getattr__(name: str):
    if name in VIEWS:
        return VIEWS[name]()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def evidence_links(cid: str, prefix: str = "") -> str:
    """'notebook §section; tables …; figures …' of a claim, as markdown links relative to ``prefix``
    (the folder of results/<profile>/ as seen from the page)."""
    c = CLAIMS[cid]
    notebook, section, tables, figures = c.notebook, c.section, c.tables, c.figures
    parts = [f"[{notebook} §{section}]({prefix}executed/{notebook}.ipynb)"]
    parts += [f"[{t}]({prefix}tables/{t})" for t in tables] + [f"[{f}]({prefix}figures/{f})" for f in figures]
    return "; ".join(parts)


def reading(table: pd.DataFrame, ids) -> str:
    """A short reading of the verdicts of ``ids`` in a claims table, written from its rows: per claim
    and protocol, the verdict and the numbers that decided it, then what the verdicts say together."""
    rows = table[table["id"].isin(list(ids))]
    lines = [f"{r['id']} ({protocol_words(r['protocol'])}) {r['verdict']}: {r['ours']}." for _, r in rows.iterrows()]
    counts = rows["verdict"].value_counts()
    summary = ", ".join(f"{n} {v}" for v, n in counts.items())
    held = rows.loc[rows["verdict"].eq(REPRODUCED), "id"].tolist()
    lines.append(f"Together: {summary}." + (f" Reproduced beyond seed noise or by its rule: {', '.join(held)}."
                                            if held else " None of these claims is reproduced by its rule."))
    return "\n".join(lines)


def read_claims(path) -> pd.DataFrame:
    """A claims.csv with its protocol column (tables written before protocols existed judged the paper's)."""
    table = pd.read_csv(path)
    if "protocol" not in table:
        table.insert(1, "protocol", "paper")
    return table


def upsert(profile: str, rows: list[dict[str, Any]], protocol: str = "paper") -> pd.DataFrame:
    """Replace rows with the same (id, protocol) in ``results/<profile>/claims.csv``; rewrite claims.md.
    ``protocol``: the training protocol of the models the rows judge (``drfkit.methods.protocols``)."""
    path = results_dir(profile) / "claims.csv"
    table = read_claims(path) if path.exists() else pd.DataFrame(columns=COLUMNS)
    new = pd.DataFrame([{**row, "protocol": protocol} for row in rows], columns=COLUMNS)
    replaced = table.set_index(["id", "protocol"]).index.isin(new.set_index(["id", "protocol"]).index)
    table = pd.concat([table[~replaced], new], ignore_index=True)
    position = {cid: i for i, cid in enumerate(CLAIMS)}  # a row of no registered claim comes last
    order = table["id"].map(lambda v: (position.get(v, len(position)), str(v)))
    table = (table.assign(_order=order, _book=table["protocol"].ne("paper"))
             .sort_values(["_order", "_book", "protocol"]).drop(columns=["_order", "_book"]))
    atomic_write_csv(path, table)
    atomic_write_text(results_dir(profile) / "claims.md", to_markdown(table, profile))
    return table


def to_markdown(table: pd.DataFrame, profile: str) -> str:
    lines = [f"# Claims of the paper, checked on profile `{profile}`", "",
             "Generated by `drfkit.study.claims` from the results of this profile; verdicts are computed by the "
             "rule in each row; `protocol` names how the judged models were trained (`drfkit.methods.protocols`). "
             f"`python -m drfkit claims --profile {profile}` judges every claim again from the profile's tables.", "",
             "Pedestrian claims (" + ", ".join(simulated_claims()) + ") are judged on the **simulated** pedestrian "
             "source unless the profile says `pedestrians.source: nuscenes` (docs/nuscenes.md).", "",
             "| id | protocol | claim | paper | ours | verdict | rule | evidence |", "|---|---|---|---|---|---|---|---|"]
    for _, r in table.iterrows():
        cells = [str(r[c]).replace("|", "/") for c in ("id", "protocol", "claim", "paper", "ours", "verdict", "rule")]
        cid = str(r["id"])
        if cid in CLAIMS and CLAIMS[cid].simulated:
            cells[5] += " (simulated source)"
        cells.append(evidence_links(cid) if cid in CLAIMS else "")
        lines.append("| " + " | ".join(cells) + " |")
    missing = [f"{cid} ({c.source})" for cid, c in CLAIMS.items() if cid not in set(table["id"])]  # any protocol
    if missing:
        lines += ["", "Not evaluated yet in this profile: " + "; ".join(missing) + "."]
    return "\n".join(lines) + "\n"


__all__ = ["COLUMNS", "Rows", "Claim", "CLAIMS", "claim_sources", "claim_evidence", "simulated_claims",
           "evidence_links", "reading", "read_claims", "upsert", "to_markdown"]
