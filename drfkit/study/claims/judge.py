"""Every claim judged from a profile's tables: what notebooks 02, 04, 05 and 06 call once they have
written their tables, and what ``python -m drfkit claims --profile <profile>`` runs to judge every
claim again from the committed tables (no model is trained or evaluated).

One function per notebook (``JUDGES``) reads that notebook's tables under ``results/<profile>/tables``
and returns its claims' rows per training protocol; the rules themselves are in ``accuracy``,
``efficiency`` and ``mechanism``, the claims' registry in ``table.CLAIMS``.
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np
import pandas as pd

from drfkit.study import registry
from drfkit.study.claims import accuracy, efficiency, mechanism
from drfkit.study.claims.table import CLAIMS, upsert
from drfkit.util.paths import tables_dir

Rows = list[tuple[str, dict]]  # (protocol, claim row)


def _read(P, name: str) -> pd.DataFrame | None:
    path = tables_dir(P.profile) / f"{name}.csv"
    return pd.read_csv(path) if path.exists() else None


def _part(frame: pd.DataFrame, study: str, protocol: str) -> pd.DataFrame:
    return frame[frame["study"].eq(study) & frame["protocol"].eq(protocol)]


def _at(frame: pd.DataFrame, levels) -> pd.DataFrame:
    return frame[frame["noise"].astype(float).apply(lambda v: any(math.isclose(v, float(lv)) for lv in levels))]


# ------------------------------------------------------------------------------ notebook 04
def _matched_monoloco(P) -> tuple[pd.DataFrame | None, pd.DataFrame | None, str]:
    """Notebook 03's Monoloco fed the DRF family's inputs: (summary rows, per-seed rows, a note). A
    summary row counting more seeds than the profile has (a level evaluated twice) keeps its mean;
    its interval, which the repeated rows make too narrow, is withheld and the note says so."""
    summary, by_seed = _read(P, "pedestrians_monoloco_inputs"), _read(P, "pedestrians_monoloco_inputs_by_seed")
    note = ""
    if summary is not None:
        summary = summary[summary["model"] == accuracy.MATCHED_MONOLOCO].copy()
        repeated = summary["n_seeds"] > len(P.seeds)
        if repeated.any():
            summary.loc[repeated, [c for c in summary if c.endswith(("_ci", "_lo", "_hi"))]] = np.nan
            note = (" (interval withheld: its table counts each seed twice at p = "
                    + ", ".join(f"{v:g}" for v in summary.loc[repeated, "noise"]) + ", a level evaluated twice)")
    if by_seed is not None:
        by_seed = by_seed[by_seed["model"] == accuracy.MATCHED_MONOLOCO].drop_duplicates(["model", "seed", "noise"])
    return summary, by_seed, note


def judge_ood(P) -> Rows:
    """C1-C5 from notebook 04's tables (and notebook 03's input-matched Monoloco for C3, C4). Every
    claim is judged once per protocol, on each study's models of that protocol (a study that does not
    train a protocol is judged in it on its paper-protocol models), as notebook 04 does."""
    summary, evals, curves = (_read(P, n) for n in ("ood_all_metrics", "ood_all_metrics_by_seed", "ood_picp_mpiw"))
    if summary is None or evals is None or curves is None:
        return []
    studies = [s for s in P.evaluation.studies if (summary["study"] == s).any()]
    protocols = {s: registry.study(s).protocols(P) for s in studies}
    paper_noise = {s: registry.study(s).eval_levels(P) for s in studies}
    shifted = {s: registry.study(s).shifted_levels(P) for s in studies}
    baselines = {s: registry.study(s).baselines(P) for s in studies}
    rows: Rows = []
    for protocol in dict.fromkeys(pr for s in studies for pr in protocols[s]):  # the paper's first
        judged = [(s, protocol if protocol in protocols[s] else "paper") for s in studies]
        if ("pendulum", protocol) in judged:
            by_seed = _part(evals, "pendulum", protocol)
            # each model at its own default rate (models differ: a filter read without a decoder has none)
            by_seed = by_seed[by_seed["dropout_p"].eq(by_seed.groupby("model")["dropout_p"].transform("first"))]
            rows += [(protocol, accuracy.c1_pendulum_mae_ordering(_at(_part(summary, "pendulum", protocol),
                                                                      paper_noise["pendulum"]),
                                                                  paper_noise["pendulum"], by_seed=by_seed)),
                     (protocol, accuracy.c2_pendulum_picp_mpiw(_part(curves, "pendulum", protocol),
                                                               paper_noise["pendulum"]))]
        if ("pedestrians", protocol) in judged:
            matched, matched_seeds, note = _matched_monoloco(P)
            by_seed = _part(evals, "pedestrians", protocol)
            if matched_seeds is not None:
                by_seed = pd.concat([by_seed, matched_seeds], ignore_index=True)
            mae = _at(_part(summary, "pedestrians", protocol), paper_noise["pedestrians"])
            if matched is not None:
                mae = pd.concat([mae, matched], ignore_index=True)
            rows += [(protocol, accuracy.c3_pedestrian_ood_gain(by_seed, shifted["pedestrians"], matched)),
                     (protocol, accuracy.c4_in_distribution_parity(mae, P.pedestrians.train_p, by_seed=by_seed,
                                                                   note=note))]
        shift = pd.concat([_part(curves, s, pr) for s, pr in judged], ignore_index=True)
        rows.append((protocol, accuracy.c5_intervals_under_shift(shift, [(s, lv) for s, _ in judged for lv in shifted[s]],
                                                                 baselines)))
    return rows


# ------------------------------------------------------------------------------ notebook 02
def judge_dynamics(P) -> Rows:
    """F1 and F2 per protocol from ``pendulum_protocols.csv`` (both protocols' DRF mechanism checks and
    blackout MAE, per seed) and ``pendulum_physics_bound_protocols.csv`` (each protocol's particle-filter
    reference on its own no_dynamics)."""
    protocols, refs = _read(P, "pendulum_protocols"), _read(P, "pendulum_physics_bound_protocols")
    if protocols is None:
        return []
    level = max(P.pendulum.eval_max_noise)
    rows: Rows = []
    for protocol, part in protocols.groupby("protocol", sort=False):
        if not (part["model"] == "drf").any():
            continue
        ref = (refs[(refs["protocol"] == protocol) & (refs["noise"].astype(str) == "blackout")]["mae"]
               if refs is not None else pd.Series(dtype=float))
        rows += [(protocol, mechanism.f1_filter_mechanism(part, level)),
                 (protocol, mechanism.f2_blackout_coasting(part, ref.to_numpy(dtype=float),
                                                           in_distribution=mechanism.training_label(part)))]
    return rows


# ------------------------------------------------------------------------------ notebook 05
def c6_row(P, table: pd.DataFrame) -> dict:
    """C6 from the inference benchmark (``drfkit.study.bench``): at batch 1 on CPU with the fewest
    threads of the profile, the other thread counts and devices reported beside it."""
    b1, threads = min(P.timing.batch_sizes), min(P.timing.threads)

    def at(model, mode, t=threads, device="cpu", column="median_ms_per_frame"):
        rows = table[(table["study"] == "pedestrians") & (table["model"] == model) & (table["mode"] == mode)
                     & (table["batch"] == b1) & (table["threads"] == t) & (table["device"] == device)]
        return float(rows[column].iloc[0])

    speedup = lambda t=threads, device="cpu": at("monoloco", "published", t, device) / at("drf", "batched", t, device)  # noqa: E731
    spread = efficiency.speedup_spread(at("monoloco", "published"), at("monoloco", "published", column="iqr_ms_per_frame"),
                                       at("drf", "batched"), at("drf", "batched", column="iqr_ms_per_frame"))
    row = efficiency.c6_speedup(speedup(), spread=spread)
    groups = [("cpu", t) for t in P.timing.threads] + [(d, threads) for d in dict.fromkeys(table["device"]) if d != "cpu"]
    others = [f"{d} {t} thr: {speedup(t, d):.2f}x" for d, t in groups if (d, t) != ("cpu", threads)]
    row["ours"] += (f" (CPU, {threads} thread(s), S = {P.uncertainty.n_samples}" + ("; " + ", ".join(others) if others else "")
                    + f"; 1-min load up to {table['load_1min'].max():.1f})")
    return row


def judge_timing(P) -> Rows:
    table = _read(P, "timing")
    return [] if table is None else [("paper", c6_row(P, table))]


# ------------------------------------------------------------------------------ notebook 06
def judge_gating(P) -> Rows:
    """Each study's gating claim (``Study.gating_claim``: C7a for the pendulum, C7b for the pedestrians) per
    protocol, on the threshold sweep (``gating_sweep.csv``); the settings summary (``gating_summary.csv``,
    the same run) gives the time test, and the gates tuned on validation at the test and at the training
    noise are reported as references. A study whose entry names no gating claim gives no row."""
    sweep, settings = _read(P, "gating_sweep"), _read(P, "gating_summary")
    if sweep is None:
        return []
    trained = _read(P, "gating_summary_train_noise")
    rows: Rows = []
    for study in P.evaluation.studies:
        claim = registry.study(study).gating_claim
        if not claim:
            continue
        for protocol in registry.study(study).protocols(P):
            part = _part(sweep, study, protocol)
            if part.empty:
                continue
            pick = lambda t: None if t is None else _part(t, study, protocol)  # noqa: E731
            tuned = {k: v for k, v in (("tuned at the test noise", pick(settings)),
                                       ("tuned at the training noise", pick(trained))) if v is not None}
            rows.append((protocol, efficiency.c7_gating(part, study, pick(settings), tuned, claim=claim)))
    return rows


JUDGES: dict[str, Callable[..., Rows]] = {"02_pendulum_dynamics": judge_dynamics, "04_ood_noise_evaluation": judge_ood,
                                          "05_timing": judge_timing, "06_competency_gating": judge_gating}
assert {c.notebook for c in CLAIMS.values()} <= set(JUDGES)


def judge(P, ids=None) -> Rows:
    """The rows of the claims ``ids`` (default: every claim of ``CLAIMS``) that ``P``'s notebooks judge,
    from the profile's tables; claims whose tables are missing give no row."""
    ids = list(CLAIMS) if ids is None else list(ids)
    rows: Rows = []
    for notebook in dict.fromkeys(CLAIMS[i].notebook for i in ids):
        rows += [(pr, r) for pr, r in JUDGES[notebook](P) if r["id"] in ids]
    return rows


def write(P, ids=None) -> pd.DataFrame:
    """Judge ``ids`` from ``P``'s tables and write them into claims.csv / claims.md (``upsert``, one
    call per protocol); returns the whole claims table."""
    rows, table = judge(P, ids), None
    for protocol in dict.fromkeys(pr for pr, _ in rows):
        table = upsert(P.profile, [r for pr, r in rows if pr == protocol], protocol=protocol)
    if table is None:
        from drfkit.study.claims.table import read_claims
        from drfkit.util.paths import results_dir

        path = results_dir(P.profile) / "claims.csv"
        table = read_claims(path) if path.exists() else pd.DataFrame(columns=["id", "protocol", "verdict"])
    return table


def main(argv: list[str] | None = None) -> int:
    """``python -m drfkit claims --profile paper``: judge every claim again from the profile's tables
    (each claim with its notebook's parameters) and rewrite claims.csv and claims.md."""
    import argparse

    from drfkit.study.params import for_notebook, load_profile

    ap = argparse.ArgumentParser(prog="python -m drfkit claims", description=main.__doc__)
    ap.add_argument("--profile", default="paper", help="a profile name in params/ or a YAML path")
    ap.add_argument("--ids", nargs="+", default=list(CLAIMS), choices=list(CLAIMS), help="the claims to judge")
    args = ap.parse_args(argv)
    values = load_profile(args.profile)
    table = None
    for notebook in dict.fromkeys(CLAIMS[i].notebook for i in args.ids):
        ids = [i for i in args.ids if CLAIMS[i].notebook == notebook]
        table = write(for_notebook(notebook, values), ids)
    for _, r in table[table["id"].isin(args.ids)].iterrows():
        print(f"{r['id']:4s} {r['protocol']:6s} {r['verdict']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
