"""The gating study of notebook 06: per DRF seed, a gate fitted on validation data
(``drfkit.methods.gating.fit_gate``) applied to the TEST set, timed and swept over thresholds
(``drfkit.methods.gate_evaluation``) -- ``gating_study``, ``train_noise_gates`` -- and the paper's
table beside it. The profile is read here and nowhere below; the gate's maths, gated inference and
fitting live in ``drfkit.methods.gating`` (its docstring says why the Kalman gain can measure
competency and how the threshold is chosen).
"""
from __future__ import annotations

from typing import Any

import pandas as pd

from drfkit.methods.gate_evaluation import evaluate_gate, selected_fraction, sweep_gate
from drfkit.methods.gating import fit_gate
from drfkit.study import registry
from drfkit.util.progress import steps


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
                 val_noise: float | None = None, sweep: bool = True) -> dict[str, pd.DataFrame]:
    """Fit a gate per DRF seed on validation data, then evaluate and sweep it on the test set (the DRF: the
    models that declare ``competency_gain``, ``gated_models``).

    Test: the ``test`` split at ``evaluation_level``. Validation: the ``val`` split (other
    sequences, other motions / scenes) at ``val_noise``, by default the test's noise level (held-out
    sequences of the shifted condition: an optimistic reference; the training noise is what a
    deployed system can tune on). The sweep's thresholds tune nothing, and claim C7 is judged on
    them; its rows hold Kalman-gain, random and oracle gating at each threshold. ``sweep=False`` leaves
    the sweep out (an empty 'sweep' table): the four settings alone, their metrics the same as with it,
    and only them in the interleaved timing rounds, for a study that reads no sweep (the gate tuned at
    the training noise: the thresholds differ with the validation noise, the claim reads the test
    noise's sweep). Times are measured on
    about ``P.gating.timing_frames`` frames of evenly spaced test sequences (0: all), metrics on
    all of them. Returns
    {'table': one row per seed and setting, 'sweep': one row per seed, method and threshold,
    'validation': the candidate table per seed}.
    """
    from drfkit.study import studies

    registry.study(study)  # a clear error for an unknown study, before any work
    models = models if models is not None else studies.trained_models(P, study)
    drf = gated_models(models)
    if not drf:
        raise ValueError(f"no trained 'drf' model for {study} (no model that declares competency_gain): gating "
                         f"needs the filter's gains")
    device = studies.pick_device(P.device)
    level_ = evaluation_level(P, study)
    val_level = level_ if val_noise is None else float(val_noise)
    val, test = studies.study_data(P, study, "val", val_level), studies.study_data(P, study, "test", level_)
    tables, sweeps, vals = [], [], []
    for seed, model in steps(sorted(drf.items()), f"{study}: gating per DRF seed"):
        model = model.to(device)
        gate, val_table = fit_gate(model, val, n_samples=P.uncertainty.n_samples, tolerance=P.gating.picp_tolerance,
                                   n_points=P.gating.sweep_points, level=P.uncertainty.interval_level, seed=seed,
                                   device=device)
        kwargs = dict(n_samples=P.uncertainty.n_samples, level=P.uncertainty.interval_level, seed=seed, device=device,
                      min_run_time=min_run_time, timing_frames=P.gating.timing_frames)
        table, swept = (sweep_gate(model, gate, test, **kwargs) if sweep
                        else (evaluate_gate(model, gate, test, **kwargs), pd.DataFrame()))
        ident = {"study": study, "seed": seed, "noise": level_, "val_noise": val_level}
        gate_info = {"direction": gate.direction, "rank_correlation": gate.rank_correlation,
                     "val_fraction": gate.val_fraction, "val_picp": gate.val_picp,
                     "val_picp_always": gate.val_picp_always}
        tables.append(table.assign(**ident, **gate_info))
        sweeps.append(swept.assign(**ident))
        vals.append(val_table.assign(study=study, seed=seed, val_noise=val_level))
    lead = ["study", "seed", "noise", "val_noise"]
    cat = lambda fs: pd.concat(fs, ignore_index=True)  # noqa: E731
    table, swept = cat(tables), cat(sweeps)
    return {"table": table[lead + [c for c in table.columns if c not in lead]],
            "sweep": swept[lead + [c for c in swept.columns if c not in lead]],
            "validation": cat(vals)}


def train_noise_gates(P, study: str, models: dict) -> pd.DataFrame:
    """The gating rule tuned on validation at the *training* noise (the study's ``Study.train_level``:
    pendulum ``pend_train_max_noise``, pedestrians ``ped_train_p``), one row per DRF seed of ``models``
    (``gated_models``): the fraction it picks on validation and the fraction of the test frames at
    ``evaluation_level`` its threshold then selects."""
    from drfkit.study import studies

    train_noise = registry.study(study).train_level(P)  # a clear error for an unknown study
    val = studies.study_data(P, study, "val", train_noise)
    test = studies.study_data(P, study, "test", evaluation_level(P, study))
    rows = []
    for seed, model in gated_models(models).items():
        gate, _ = fit_gate(model, val, n_samples=P.uncertainty.n_samples, tolerance=P.gating.picp_tolerance,
                           n_points=P.gating.sweep_points, level=P.uncertainty.interval_level, seed=seed)
        rows.append({"study": study, "seed": seed, "val_noise": train_noise, "direction": gate.direction,
                     "rank_correlation": gate.rank_correlation, "val_fraction": gate.val_fraction,
                     "val_picp": gate.val_picp, "val_picp_always": gate.val_picp_always,
                     "test_fraction": selected_fraction(model, gate, test)})
    return pd.DataFrame(rows)


def paper_table() -> pd.DataFrame:
    """The paper's gating table (drfkit.study.paper.GATING) with PICP as a fraction."""
    from drfkit.study.paper import GATING

    return pd.DataFrame([{"study": s, "setting": k, "picp": v[0] / 100, "mpiw": v[1], "time_ms": v[2]}
                         for s, rows in GATING.items() for k, v in rows.items()])


__all__ = ["evaluation_level", "gated_models", "gating_study", "train_noise_gates", "paper_table"]
