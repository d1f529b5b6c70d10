"""The gating study of notebook 06: per DRF seed, a gate fitted on validation data
(``drfkit.methods.gating.fit_gate``) applied to the TEST set, timed and swept over thresholds
(``drfkit.methods.gate_evaluation``) -- ``gating_study``, with the gate a deployed system could tune at the
training noise beside it -- and the paper's
table beside it. The profile is read here and nowhere below; the gate's maths, gated inference and
fitting live in ``drfkit.methods.gating`` (its docstring says why the Kalman gain can measure
competency and how the threshold is chosen).
"""
from __future__ import annotations

from typing import Any

import pandas as pd

from drfkit.methods.gate_evaluation import score_gate, split_sweep, sweep_thresholds, time_gate
from drfkit.methods.gating import fit_gate
from drfkit.models.portable import portable
from drfkit.study import registry
from drfkit.util.progress import steps
from drfkit.util.tasks import map_tasks


# --------------------------------------------------------------------------- the study
def evaluation_level(P, study: str) -> float:
    """The test noise of the gating table: the largest evaluation level (out of distribution;
    the paper's pedestrian always-dropout row, 89.7 % / 12.9 m, is its DRF point at p = 0.05)."""
    return max(registry.study(study).eval_levels(P))


def gated_models(models: dict) -> dict[int, Any]:
    """seed -> model, in seed order: the models of ``models`` ((kind, seed) -> model) that Kalman-gain gating
    runs on, those whose class declares ``competency_gain`` (``drfkit.models.sequence``; of the book's
    models, the DRF). The gating tables hold one row per seed, so these must be of one kind: several are an
    error that names them."""
    gated = {key: m for key, m in models.items() if getattr(m, "competency_gain", False)}
    kinds = sorted({kind for kind, _ in gated})
    if len(kinds) > 1:
        raise ValueError(f"models of several kinds declare competency_gain ({kinds}); the gating tables hold one "
                         f"gated model per seed: pass the models of one of them")
    return {seed: m for (_, seed), m in sorted(gated.items())}


def gating_study(P, study: str, models: dict | None = None, min_run_time: float = 0.3,
                 val_noise: float | None = None, sweep: bool = True, workers: int | str | None = None
                 ) -> dict[str, pd.DataFrame]:
    """Fit two gates per DRF seed on validation data, then evaluate and sweep them on the test set, in one pass of
    the test set per seed (the DRF: the models that declare ``competency_gain``, ``gated_models``).

    Test: the ``test`` split at ``evaluation_level``. The gate: fit on the ``val`` split (other sequences, other
    motions / scenes) at ``val_noise``, by default the test's noise level (held-out sequences of the shifted
    condition: an optimistic reference). The training-noise gate: fit on ``val`` at the study's training noise
    (``Study.train_level``: what a deployed system can tune on), evaluated on the same test pass and timed in the
    same interleaved run. The sweep's thresholds tune nothing, and claim C7 is judged on them; its rows hold
    Kalman-gain, random and oracle gating at each threshold of the first gate (``sweep=False``: an empty 'sweep',
    the settings' metrics unchanged).

    What is not timed -- the gates' fitting and the metric passes (``score_gate``) -- runs as one task per seed
    (``drfkit.util.tasks.map_tasks`` on ``workers``: every core; one torch thread per task, so the metrics are the
    same at any worker count). Then the times, one seed after another in this process at the caller's torch
    threads with no task running beside them (``time_gate``), on about ``P.gating.timing_frames`` frames of evenly
    spaced test sequences (0: all). Returns
    {'table': one row per seed and setting, 'sweep': one row per seed, method and threshold,
    'validation': the candidate table per seed, 'table_train': the four settings with the training-noise gate
    (no_dropout and always are the first table's rows), 'train_gate': per seed, what the training-noise gate
    chose on validation and the fraction of test frames it selects}.
    """
    from drfkit.study import studies

    entry = registry.study(study)  # a clear error for an unknown study, before any work
    models = models if models is not None else studies.trained_models(P, study)
    drf = gated_models(models)
    if not drf:
        raise ValueError(f"no trained 'drf' model for {study} (no model that declares competency_gain): gating "
                         f"needs the filter's gains")
    device = studies.pick_device(P.device)
    level_ = evaluation_level(P, study)
    val_level = level_ if val_noise is None else float(val_noise)
    train_level = float(entry.train_level(P))
    data = {"val": studies.study_data(P, study, "val", val_level), "test": studies.study_data(P, study, "test", level_),
            "val_train": studies.study_data(P, study, "val", train_level), "models": portable(drf)}
    fit = dict(n_samples=P.uncertainty.n_samples, tolerance=P.gating.picp_tolerance, n_points=P.gating.sweep_points,
               level=P.uncertainty.interval_level, device=device)
    scored = map_tasks(_score_task, [(seed, fit, sweep) for seed in sorted(drf)], shared=data, workers=workers,
                       desc=f"{study}: gates fitted and scored per DRF seed (untimed)")
    tables, sweeps, vals, train_tables, train_gates = [], [], [], [], []
    for seed, (gate, gate_train, val_table, score) in steps(list(zip(sorted(drf), scored)),
                                                            f"{study}: gating timed per DRF seed"):
        table = time_gate(drf[seed].to(device), score, data["test"], n_samples=P.uncertainty.n_samples,
                          device=device, min_run_time=min_run_time, timing_frames=P.gating.timing_frames,
                          other_gates={"train": gate_train})
        table, swept = split_sweep(table, gate) if sweep else (table, pd.DataFrame())
        ident = {"study": study, "seed": seed, "noise": level_}
        own = ~table["setting"].str.contains("@train")
        tables.append(table[own].assign(**ident, val_noise=val_level, **_gate_info(gate)))
        shared = table["setting"].isin(["no_dropout", "always"])
        tuned = table[shared | ~own].assign(setting=lambda t: t["setting"].str.replace("@train", "", regex=False))
        train_tables.append(tuned.assign(**ident, val_noise=train_level, **_gate_info(gate_train)))
        chosen = float(tuned.loc[tuned["setting"] == "kalman_gain", "fraction"].iloc[0])
        train_gates.append({"study": study, "seed": seed, "val_noise": train_level, **_gate_info(gate_train),
                            "test_fraction": chosen})
        sweeps.append(swept.assign(**ident, val_noise=val_level))
        vals.append(val_table.assign(study=study, seed=seed, val_noise=val_level))
    lead = ["study", "seed", "noise", "val_noise"]
    cat = lambda fs: pd.concat(fs, ignore_index=True)  # noqa: E731
    ordered = lambda t: t[lead + [c for c in t.columns if c not in lead]]  # noqa: E731
    return {"table": ordered(cat(tables)), "sweep": ordered(cat(sweeps)), "validation": cat(vals),
            "table_train": ordered(cat(train_tables)), "train_gate": pd.DataFrame(train_gates)}


def _score_task(seed: int, fit: dict[str, Any], sweep: bool, shared: dict) -> tuple:
    """One seed's untimed work (a task of ``map_tasks``): both gates fitted on validation, the test set scored.
    Returns (gate, training-noise gate, the validation table, ``ScoredGate``)."""
    model = shared["models"][seed].model.to(fit["device"])
    gate, val_table = fit_gate(model, shared["val"], seed=seed, **fit)
    gate_train, _ = fit_gate(model, shared["val_train"], seed=seed, **fit)
    score = score_gate(model, gate, shared["test"], n_samples=fit["n_samples"], level=fit["level"], seed=seed,
                       device=fit["device"], thresholds=sweep_thresholds(gate) if sweep else None,
                       other_gates={"train": gate_train})
    return gate, gate_train, val_table, score


def _gate_info(gate) -> dict[str, Any]:
    """What a fitted gate chose on validation (the columns the gating tables carry)."""
    return {"direction": gate.direction, "rank_correlation": gate.rank_correlation, "val_fraction": gate.val_fraction,
            "val_picp": gate.val_picp, "val_picp_always": gate.val_picp_always}


def paper_table() -> pd.DataFrame:
    """The paper's gating table (drfkit.study.paper.GATING) with PICP as a fraction."""
    from drfkit.study.paper import GATING

    return pd.DataFrame([{"study": s, "setting": k, "picp": v[0] / 100, "mpiw": v[1], "time_ms": v[2]}
                         for s, rows in GATING.items() for k, v in rows.items()])


__all__ = ["evaluation_level", "gated_models", "gating_study", "paper_table"]
