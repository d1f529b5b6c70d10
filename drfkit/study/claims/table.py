"""The claims table: every claim listed once (``CLAIMS``: who judges it, where its evidence lies),
``results/<profile>/claims.csv`` kept one row per (claim, protocol) by ``upsert``, and its rendering
as ``claims.md``."""
from __future__ import annotations

from typing import Any, NamedTuple

import pandas as pd

from drfkit.study.claims.verdicts import REPRODUCED
from drfkit.util.io import atomic_write_csv, atomic_write_text
from drfkit.util.paths import results_dir

COLUMNS = ["id", "protocol", "claim", "paper", "ours", "rule", "verdict"]


class Claim(NamedTuple):
    """Where a claim is judged: the notebook that fills its row (``drfkit.study.claims.judge`` judges
    it from that notebook's tables), what claims.md says when it has not, the notebook's section, and
    the tables and figures the verdict reads (under results/<profile>/; a protocol other than the
    paper's has its figures as <study>_<protocol>_...)."""

    notebook: str
    source: str
    section: str
    tables: tuple[str, ...]
    figures: tuple[str, ...]


_NB04, _NB02, _NB06 = "04_ood_noise_evaluation", "02_pendulum_dynamics", "06_competency_gating"
_VERDICTS04, _FIGURES04 = "Claims C1–C5, with computed verdicts", "The paper's figures, redrawn"
_GATING = Claim(_NB06, "", "Claim C7, with computed verdicts",
                ("gating_sweep.csv", "gating_summary.csv", "gating_summary_train_noise.csv"),
                ("gating_picp_fraction.png", "gating_sweep.png"))
_MONOLOCO = ("pedestrians_monoloco_inputs.csv",)  # and its per-seed rows, when notebook 03 has written them
_BOTH_PROTOCOLS = "Both protocols side by side"
CLAIMS: dict[str, Claim] = {
    "C1": Claim(_NB04, "notebook 04, pendulum", _VERDICTS04, ("ood_all_metrics.csv", "ood_all_metrics_by_seed.csv"),
                ("pendulum_mae.png",)),
    "C2": Claim(_NB04, "notebook 04, pendulum", _FIGURES04, ("ood_picp_mpiw.csv",), ("pendulum_picp_mpiw.png",)),
    "C3": Claim(_NB04, "notebook 04, pedestrians", _VERDICTS04, ("ood_all_metrics_by_seed.csv", *_MONOLOCO),
                ("pedestrians_mae.png",)),
    "C4": Claim(_NB04, "notebook 04, pedestrians", _VERDICTS04, ("ood_all_metrics.csv", *_MONOLOCO),
                ("pedestrians_mae.png",)),
    "C5": Claim(_NB04, "notebook 04, both studies", _FIGURES04, ("ood_all_metrics.csv", "ood_picp_mpiw.csv"),
                ("pendulum_picp_mpiw.png", "pedestrians_picp_mpiw.png")),
    "C6": Claim("05_timing", "notebook 05", "Claim C6 and the targets", ("timing.csv",), ("timing_ms_per_frame.png",)),
    # judged on the threshold sweep (no gate is tuned); the tuned gates are a labelled reference in the row
    "C7a": _GATING._replace(source="notebook 06, pendulum"),
    "C7b": _GATING._replace(source="notebook 06, pedestrians"),
    # both protocols' rows are in these tables (pendulum_mechanism.csv and pendulum_blackout.csv: the paper's only)
    "F1": Claim(_NB02, "notebook 02, pendulum", _BOTH_PROTOCOLS, ("pendulum_protocols.csv",), ()),
    "F2": Claim(_NB02, "notebook 02, pendulum", _BOTH_PROTOCOLS,
                ("pendulum_protocols.csv", "pendulum_physics_bound_protocols.csv"), ("pendulum_blackout_protocols.png",)),
}
# Every claim row and what fills it: claims.md lists the ones a profile has not evaluated yet.
CLAIM_SOURCES = {cid: c.source for cid, c in CLAIMS.items()}
# Where each claim is judged: (notebook, section, tables, figures)
CLAIM_EVIDENCE = {cid: (c.notebook, c.section, list(c.tables), list(c.figures)) for cid, c in CLAIMS.items()}
# Claims whose evidence is the simulated pedestrian source by default (pedestrians.source: simulated)
PEDESTRIAN_CLAIMS = ("C3", "C4", "C7b")


def evidence_links(cid: str, prefix: str = "") -> str:
    """'notebook §section; tables …; figures …' of a claim, as markdown links relative to ``prefix``
    (the folder of results/<profile>/ as seen from the page)."""
    notebook, section, tables, figures = CLAIM_EVIDENCE[cid]
    parts = [f"[{notebook} §{section}]({prefix}executed/{notebook}.ipynb)"]
    parts += [f"[{t}]({prefix}tables/{t})" for t in tables] + [f"[{f}]({prefix}figures/{f})" for f in figures]
    return "; ".join(parts)


def reading(table: pd.DataFrame, ids) -> str:
    """A short reading of the verdicts of ``ids`` in a claims table, written from its rows: per claim
    and protocol, the verdict and the numbers that decided it, then what the verdicts say together."""
    rows = table[table["id"].isin(list(ids))]
    lines = [f"{r['id']} ({r['protocol']} protocol) {r['verdict']}: {r['ours']}." for _, r in rows.iterrows()]
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
    order = table["id"].map(lambda v: ({"C": 0, "F": 1}.get(v[0], 2), int(v[1:].rstrip("ab")), v))
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
             "Pedestrian claims (" + ", ".join(PEDESTRIAN_CLAIMS) + ") are judged on the **simulated** pedestrian "
             "source unless the profile says `pedestrians.source: nuscenes` (docs/nuscenes.md).", "",
             "| id | protocol | claim | paper | ours | verdict | rule | evidence |", "|---|---|---|---|---|---|---|---|"]
    for _, r in table.iterrows():
        cells = [str(r[c]).replace("|", "/") for c in ("id", "protocol", "claim", "paper", "ours", "verdict", "rule")]
        cid = str(r["id"])
        if cid in PEDESTRIAN_CLAIMS:
            cells[5] += " (simulated source)"
        cells.append(evidence_links(cid) if cid in CLAIM_EVIDENCE else "")
        lines.append("| " + " | ".join(cells) + " |")
    missing = [f"{cid} ({src})" for cid, src in CLAIM_SOURCES.items() if cid not in set(table["id"])]  # any protocol
    if missing:
        lines += ["", "Not evaluated yet in this profile: " + "; ".join(missing) + "."]
    return "\n".join(lines) + "\n"


__all__ = ["COLUMNS", "Claim", "CLAIMS", "CLAIM_SOURCES", "CLAIM_EVIDENCE", "PEDESTRIAN_CLAIMS", "evidence_links",
           "reading", "read_claims", "upsert", "to_markdown"]
