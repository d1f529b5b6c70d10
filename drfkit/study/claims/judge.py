"""Every registered claim judged from a profile's tables: what notebooks 02, 04, 05 and 06 call once
they have written their tables, and what ``python -m drfkit claims --profile <profile>`` runs to judge
every claim again from the committed tables (no model is trained or evaluated).

Each claim (``table.CLAIMS``) names the inputs its ``judge`` reads (``Claim.reads``, a key of ``INPUTS``):
"tables", the profile's tables read on demand, or what several claims of a notebook share and is built
once for them ("ood": notebook 04's, "gating": notebook 06's), which needs the study registry (each
study's protocols, levels, baselines, gating claim). The rules themselves are in the claims' modules.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from drfkit.study import registry
from drfkit.study.claims.monoloco import MATCHED_MONOLOCO
from drfkit.study.claims.table import CLAIMS, Rows, read_claims, upsert
from drfkit.study.claims.verdicts import rows_of
from drfkit.util.paths import results_dir, tables_dir
from drfkit.util.registry import Registry


def _read(P, name: str) -> pd.DataFrame | None:
    path = tables_dir(P.profile) / f"{name}.csv"
    return pd.read_csv(path) if path.exists() else None


class _JudgedDrfs:
    """What every claim's tables share: the DRF kinds judged in their own rows, asked of the registry."""

    def judged_drfs(self, study: str) -> tuple[str, ...]:
        """The DRF kinds judged in their own rows beside the paper's DRF (``Study.judged_drfs``)."""
        return registry.study(study).judged_drfs


@dataclass
class Tables(_JudgedDrfs):
    """A profile's tables (results/<profile>/tables/<name>.csv), each read once when first asked for;
    ``P``: the parameters of the notebook that wrote them."""

    P: Any
    _cache: dict[str, pd.DataFrame | None] = field(default_factory=dict, repr=False)

    def read(self, name: str) -> pd.DataFrame | None:
        """The table ``name`` (without .csv), or None when the profile has not written it."""
        if name not in self._cache:
            self._cache[name] = _read(self.P, name)
        return self._cache[name]


# ------------------------------------------------------------------------------ notebook 04
def _matched_monoloco(P) -> tuple[pd.DataFrame | None, pd.DataFrame | None, str]:
    """Notebook 03's Monoloco fed the DRF family's inputs: (summary rows, per-seed rows, a note). A
    summary row counting more seeds than the profile has (a level evaluated twice) keeps its mean;
    its interval, which the repeated rows make too narrow, is withheld and the note says so."""
    summary, by_seed = _read(P, "pedestrians_monoloco_inputs"), _read(P, "pedestrians_monoloco_inputs_by_seed")
    note = ""
    if summary is not None:
        summary = summary[summary["model"] == MATCHED_MONOLOCO].copy()
        repeated = summary["n_seeds"] > len(P.seeds)
        if repeated.any():
            summary.loc[repeated, [c for c in summary if c.endswith(("_ci", "_lo", "_hi"))]] = np.nan
            note = (" (interval withheld: its table counts each seed twice at p = "
                    + ", ".join(f"{v:g}" for v in summary.loc[repeated, "noise"]) + ", a level evaluated twice)")
    if by_seed is not None:
        by_seed = by_seed[by_seed["model"] == MATCHED_MONOLOCO].drop_duplicates(["model", "seed", "noise"])
    return summary, by_seed, note


@dataclass
class OodTables(_JudgedDrfs):
    """What C1-C5 read (notebook 04): the summary, per-seed rows and PICP–MPIW curves (intervals recalibrated on
    validation, ``drfkit.study.evaluate.uncertainty_scales``) of every study in
    the profile's evaluation, each study's protocols, paper levels, shifted levels and baselines, and
    notebook 03's input-matched Monoloco (summary, per-seed rows, a note on its interval)."""

    P: Any
    summary: pd.DataFrame
    evals: pd.DataFrame
    curves: pd.DataFrame | None
    studies: list[str]
    protocols: dict[str, list[str]]
    paper_noise: dict[str, list[float]]
    shifted: dict[str, list[float]]
    baselines: dict[str, list[str]]
    matched: pd.DataFrame | None
    matched_seeds: pd.DataFrame | None
    matched_note: str

    def by_protocol(self) -> list[tuple[str, list[tuple[str, str]]]]:
        """Per protocol (the paper's first), the (study, protocol of its models) judged in it: every claim
        is judged once per protocol, on each study's models of that protocol (a study that does not train
        a protocol is judged in it on its paper-protocol models), as notebook 04 does."""
        order = dict.fromkeys(pr for s in self.studies for pr in self.protocols[s])
        return [(protocol, [(s, protocol if protocol in self.protocols[s] else "paper") for s in self.studies])
                for protocol in order]

    def pedestrian_seeds(self) -> list[tuple[str, pd.DataFrame]]:
        """Per protocol whose models include the pedestrians' own: their per-seed rows (one per model,
        seed, noise) with the input-matched Monoloco's when notebook 03 wrote them (what C3 and C4 read)."""
        out = []
        for protocol, judged in self.by_protocol():
            if ("pedestrians", protocol) not in judged:
                continue
            by_seed = rows_of(self.evals, "pedestrians", protocol)
            if self.matched_seeds is not None:
                by_seed = pd.concat([by_seed, self.matched_seeds], ignore_index=True)
            out.append((protocol, by_seed))
        return out


def ood_tables(P) -> OodTables | None:
    """Notebook 04's inputs of C1-C5 for the studies its summary holds; None until it has written all three tables."""
    summary, evals = (_read(P, n) for n in ("ood_all_metrics", "ood_all_metrics_by_seed"))
    if summary is None or evals is None:
        return None
    # C2 and C5 rank intervals recalibrated on validation (one scale per model and seed): as trained, every learned
    # model's intervals are several times too wide in distribution, and coverage would rank their excess width. A
    # results folder written before notebook 04 recalibrated them has no such curves: C2 and C5 say so, unjudged.
    curves = _read(P, "ood_picp_mpiw_recalibrated")
    studies = [s for s in P.evaluation.studies if (summary["study"] == s).any()]
    entry = {s: registry.study(s) for s in studies}
    matched, matched_seeds, note = _matched_monoloco(P)
    return OodTables(P, summary, evals, curves, studies, protocols={s: e.protocols(P) for s, e in entry.items()},
                     paper_noise={s: e.eval_levels(P) for s, e in entry.items()},
                     shifted={s: e.shifted_levels(P) for s, e in entry.items()},
                     baselines={s: e.baselines(P) for s, e in entry.items()}, matched=matched,
                     matched_seeds=matched_seeds, matched_note=note)


# ------------------------------------------------------------------------------ notebook 06
@dataclass
class GatingTables:
    """What the gating claims read (notebook 06): the threshold sweep, the settings summary of the same
    run (None without it), the gates tuned at the training noise (None without them), and per study of
    the evaluation (study, the gating claim its registry entry names, its protocols)."""

    P: Any
    sweep: pd.DataFrame
    settings: pd.DataFrame | None
    trained: pd.DataFrame | None
    studies: list[tuple[str, str, list[str]]]


def gating_tables(P) -> GatingTables | None:
    """Notebook 06's inputs of the gating claims; None until it has written its sweep."""
    sweep = _read(P, "gating_sweep")
    if sweep is None:
        return None
    studies = [(s, registry.study(s).gating_claim, registry.study(s).protocols(P)) for s in P.evaluation.studies]
    return GatingTables(P, sweep, _read(P, "gating_summary"), _read(P, "gating_summary_train_noise"), studies)


# Claim.reads -> P -> the claim's inputs (None: their tables are missing, the claim gives no row)
INPUTS = Registry("claim input", {"tables": Tables, "ood": ood_tables, "gating": gating_tables})


def judge(P, ids=None) -> Rows:
    """The rows of the claims ``ids`` (default: every registered claim) that ``P``'s notebooks judge,
    from the profile's tables; claims whose tables are missing give no row. Inputs shared by several
    claims are built once."""
    ids = list(CLAIMS) if ids is None else list(ids)
    inputs: dict[str, Any] = {}
    rows: Rows = []
    for cid in ids:
        claim = CLAIMS[cid]
        if claim.reads not in inputs:
            inputs[claim.reads] = INPUTS[claim.reads](P)
        if inputs[claim.reads] is not None:
            rows += claim.judge(inputs[claim.reads])
    return rows


def judge_gating(P) -> Rows:
    """Every gating claim's rows (``efficiency.GATING_CLAIMS``): each study's, per protocol."""
    from drfkit.study.claims.efficiency import GATING_CLAIMS

    return judge(P, [cid for cid in GATING_CLAIMS if cid in CLAIMS])


def write(P, ids=None) -> pd.DataFrame:
    """Judge ``ids`` from ``P``'s tables and write them into claims.csv / claims.md (``upsert``, one
    call per protocol); returns the whole claims table."""
    rows, table = judge(P, ids), None
    for protocol in dict.fromkeys(pr for pr, _ in rows):
        table = upsert(P.profile, [r for pr, r in rows if pr == protocol], protocol=protocol)
    if table is None:
        path = results_dir(P.profile) / "claims.csv"
        table = read_claims(path) if path.exists() else pd.DataFrame(columns=["id", "protocol", "verdict"])
    return table
