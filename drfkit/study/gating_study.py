"""The gating study: a gate fitted on validation data (``drfkit.methods.gating.fit_gate``) applied to
the TEST set, timed, and swept over thresholds; the profile-driven study of notebook 06
(``gating_study``, ``train_noise_gates``) and the paper's table beside it.

The test set enters only here, through ``evaluate_gate`` / ``sweep_gate``, which apply a fitted
``Gate``; the gate's maths, gated inference and fitting live in ``drfkit.methods.gating`` (its docstring
says why the Kalman gain can measure competency and how the threshold is chosen).
"""
from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np
import pandas as pd
import torch

from drfkit.study import registry
from drfkit.core.metrics import prediction_metrics
from drfkit.methods.gating import (ALWAYS, NEVER, RANDOM_SEED_OFFSET, SETTINGS, Gate, GatedPrediction, eval_mode,
                           real_mask, apply_gating, assemble, competency_score, fit_gate, oracle_selection,
                           run_setting, select_frames, uncertainty_stage)
from drfkit.models.parts import check_dropout_p, check_n_samples
from drfkit.util.progress import steps
from drfkit.methods.timing.clock import interleaved_times
from drfkit.methods.uncertainty import as_model_input


# --------------------------------------------------------------------------- timing
def timing_subset(frames_per_sequence: torch.Tensor, max_frames: int) -> torch.Tensor:
    """Indices (k,) of the test sequences timed: k evenly spaced over all N, the same every
    run, with k = ceil(N * max_frames / total frames) so that about ``max_frames`` real frames
    are timed (0, or a set no larger than that: every sequence). Evenly spaced, not the first
    k, so a test set ordered by scene or noise is sampled across its whole range.
    frames_per_sequence: (N,) real frames of each sequence."""
    if isinstance(max_frames, bool) or not isinstance(max_frames, int) or max_frames < 0:
        raise ValueError(f"gating_timing_frames must be an int >= 0 (0 = every test frame), got {max_frames!r}")
    n, total = frames_per_sequence.numel(), int(frames_per_sequence.sum())
    if max_frames == 0 or total <= max_frames:
        return torch.arange(n)
    k = math.ceil(n * max_frames / total)
    return torch.linspace(0, n - 1, k, dtype=torch.float64).round().long()


def measure_interleaved(fns: dict[str, Callable[[], Any]], min_run_time: float, block_s: float = 0.01,
                        min_rounds: int = 5) -> dict[str, float]:
    """Median seconds per call of each fn over interleaved rounds (``timing.interleaved_times``:
    blocks of about ``block_s`` seconds, the order rotated per round, at least ``min_rounds``
    rounds and about ``min_run_time`` seconds per fn), so a slow spell of a shared machine hits
    every setting alike."""
    with torch.no_grad():
        per_round = interleaved_times(fns, min_run_time, block_s=block_s, min_rounds=min_rounds)
    return {n: float(np.median(v)) for n, v in per_round.items()}


# --------------------------------------------------------------------------- apply on test
def _metrics(pred: GatedPrediction, y: torch.Tensor, real: torch.Tensor, level: float) -> dict[str, float]:
    m = prediction_metrics(pred.mean, pred.total, y, real, level)
    return {k: m[k] for k in ("picp", "mpiw", "nll", "mae")}


@torch.no_grad()
def evaluate_gate(model, gate: Gate, test, *, n_samples: int, dropout_p: float | None = None,
                  level: float = 0.95, seed: int = 0, min_run_time: float = 0.3, device=None,
                  thresholds: dict[str, float] | None = None, timing_frames: int = 0) -> pd.DataFrame:
    """The four settings on the TEST set (a SequenceData) with a gate fitted beforehand.

    Metrics: the features run once, then one deterministic and one always-dropout pass (masks
    seeded by ``seed``); each gated setting's prediction is ``assemble``d from the two: its
    selected frames take the always pass's result, the others the deterministic one. The head is
    per frame, so this is gated inference's result with the always pass's masks on the selected
    frames (the timed gated inference draws masks for those frames alone: other random numbers,
    the same distribution), and every setting and threshold is judged on common random numbers.
    Random gating selects as many frames as the Kalman-gain gate does on this test set (drawn
    with seed + RANDOM_SEED_OFFSET). ``thresholds`` (name -> threshold)
    adds Kalman-gain rows, each with its random twin 'random:<name>' and its oracle twin
    'oracle:<name>' (``oracle_selection``: as many frames, those of largest true error of the
    deterministic prediction; metrics only, its times are NaN) (used by ``sweep_gate``).

    Times, per real frame, all measured in this call on the same inputs (interleaved medians),
    on about ``timing_frames`` real frames of evenly spaced test sequences (``timing_subset``;
    0: all of them); the metrics always use every test sequence. Per-frame times of a batch of
    thousands of frames do not depend on its size, and timing ~46 settings x >= 5 rounds on
    every frame of a big test set takes an hour on 2 cores. On the timed subset a random twin
    draws as many frames as its Kalman-gain gate selects there (equal compute where timed):
      features_ms  the features (encoder + filter; with gains for Kalman-gain rows only);
      head_ms      the uncertainty stage alone (scoring, selection, gather, head, scatter);
      time_ms      features_ms + head_ms: the inference of the setting. Settings differ only in
                   the stage, and summing two medians keeps the features' timing noise out of
                   the differences between settings;
      whole_ms     the four settings' whole inference timed in one piece (``run_setting``), a
                   check on time_ms (NaN for the extra thresholds).
    Returns one row per setting: setting, threshold, fraction, n_selected, picp (fraction),
    mpiw, nll, mae, time_ms, head_ms, features_ms, whole_ms, frames (real frames, metrics),
    timed_frames (real frames of the timed subset), batch_ms (time_ms x timed_frames), threads.
    """
    n_samples = check_n_samples(n_samples)
    p = model.default_dropout_p if dropout_p is None else check_dropout_p(dropout_p)
    device = torch.device(device) if device is not None else next(model.parameters()).device
    x = as_model_input(model, test.inputs).to(device)
    real = real_mask(test).to(device)
    y = test.targets.to(device)
    n_real = int(real.sum())
    common = dict(n_samples=n_samples, dropout_p=p)
    kg = dict(direction=gate.direction)
    rnd = dict(random_seed=seed + RANDOM_SEED_OFFSET)

    was = eval_mode(model)
    try:
        h, gains = model.features(x, return_gains=True)
        # Metrics from two full passes (``assemble``): every setting's frames take the same
        # deterministic or always-dropout result, so settings differ only in which frames they select.
        passes = {}
        for setting in ("no_dropout", "always"):
            torch.manual_seed(seed)
            passes[setting] = uncertainty_stage(model, h, gains, real, setting, **common)
        # name -> (setting, stage keyword arguments); random twins take the Kalman-gain count
        variants: dict[str, tuple[str, dict[str, Any]]] = {
            "no_dropout": ("no_dropout", {}), "always": ("always", {})}
        rows = []

        def evaluate(name, setting, extra):
            pred = passes[setting] if setting in passes else assemble(
                passes["no_dropout"], passes["always"],
                select_frames(setting, gains, real, **extra, kind=model.config.get("kind")))
            variants[name] = (setting, extra)
            rows.append({"setting": name, "threshold": extra.get("threshold", NEVER if setting == "no_dropout"
                                                                  else ALWAYS),
                         "n_selected": int(pred.selected[real].sum()), **_metrics(pred, y, real, level)})
            return pred

        evaluate("no_dropout", "no_dropout", {})
        evaluate("always", "always", {})
        twin_of: dict[str, str] = {}  # random twin -> its Kalman-gain row
        # the oracle twins of the sweep: as many frames, those of largest true error (metrics only: never timed)
        abs_error = (passes["no_dropout"].mean - y).abs().mean(dim=-1)
        for name, thr in {"kalman_gain": gate.threshold, **(thresholds or {})}.items():
            n_sel = int(evaluate(name, "kalman_gain", {**kg, "threshold": thr}).selected.sum())
            twin = "random" if name == "kalman_gain" else f"random:{name}"
            pred = evaluate(twin, "random", {**rnd, "n_random": n_sel})
            assert int(pred.selected.sum()) == n_sel
            rows[-1]["threshold"] = thr
            twin_of[twin] = name
            if name != "kalman_gain":
                pred = assemble(passes["no_dropout"], passes["always"], oracle_selection(abs_error, real, n_sel))
                rows.append({"setting": f"oracle:{name}", "threshold": thr, "n_selected": n_sel,
                             **_metrics(pred, y, real, level)})

        # ---- times, on the timed subset only
        idx = timing_subset(real.sum(dim=1), timing_frames).to(device)
        whole_set = idx.numel() == x.shape[0]
        x_t, real_t = (x, real) if whole_set else (x[idx], real[idx])
        h_t, gains_t = (h, gains) if whole_set else model.features(x_t, return_gains=True)
        scores_t = competency_score(gains_t, gate.direction)
        timed = {name: (setting, extra if setting != "random" else
                        {**extra, "n_random": int(apply_gating(scores_t, variants[twin_of[name]][1]["threshold"],
                                                               real_t).sum())})
                 for name, (setting, extra) in variants.items()}
        stage_fns = {name: (lambda s=setting, e=extra: uncertainty_stage(model, h_t, gains_t, real_t, s,
                                                                         **common, **e))
                     for name, (setting, extra) in timed.items()}
        head_s = measure_interleaved(stage_fns, min_run_time / 2)
        whole_fns = {name: (lambda s=timed[name][0], e=timed[name][1]:
                            run_setting(model, x_t, real_t, s, **common, **e)) for name in SETTINGS}
        whole_fns["features"] = lambda: model.features(x_t)
        whole_fns["features_gains"] = lambda: model.features(x_t, return_gains=True)
        whole_s = measure_interleaved(whole_fns, min_run_time, min_rounds=7)
    finally:
        model.train(was)
    n_timed = int(real_t.sum())
    frame = pd.DataFrame(rows)
    frame["fraction"] = frame["n_selected"] / n_real
    gains_used = frame["setting"].isin(["kalman_gain", *(thresholds or {})])
    per_frame = 1e3 / n_timed
    frame["head_ms"] = frame["setting"].map(head_s) * per_frame
    frame["features_ms"] = np.where(gains_used, whole_s["features_gains"], whole_s["features"]) * per_frame
    frame["time_ms"] = frame["features_ms"] + frame["head_ms"]
    frame["whole_ms"] = frame["setting"].map(whole_s) * per_frame
    frame["frames"] = n_real
    frame["timed_frames"] = n_timed
    frame["batch_ms"] = frame["time_ms"] * n_timed
    frame["threads"] = torch.get_num_threads()
    order = ["setting", "threshold", "fraction", "n_selected", "picp", "mpiw", "nll", "mae", "time_ms",
             "head_ms", "features_ms", "whole_ms", "batch_ms", "frames", "timed_frames", "threads"]
    return frame[order]


def split_sweep(table: pd.DataFrame, gate: Gate) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Split ``evaluate_gate(..., thresholds=sweep_thresholds(gate))`` into the four settings and
    the sweep rows (method in {kalman_gain, random, oracle}, val_fraction = the target fraction on validation)."""
    is_sweep = table["setting"].str.contains(r"q\d+$")
    sweep = table[is_sweep].copy()
    sweep.insert(0, "method", np.select([sweep["setting"].str.startswith("random"), sweep["setting"].str.startswith("oracle")],
                                        ["random", "oracle"], "kalman_gain"))
    index = sweep["setting"].str.extract(r"q(\d+)$")[0].astype(int)
    sweep.insert(1, "val_fraction", index.map(lambda i: gate.sweep_fractions[i]))
    return (table[~is_sweep].reset_index(drop=True),
            sweep.drop(columns="setting").reset_index(drop=True))


def sweep_thresholds(gate: Gate) -> dict[str, float]:
    """Names q0 ... q{m-1} -> the gate's validation-quantile thresholds (never ... always)."""
    return {f"q{i}": thr for i, thr in enumerate(gate.sweep_thresholds)}


def sweep_gate(model, gate: Gate, test, **kwargs) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The four settings and Kalman-gain / random gating at every threshold of
    ``gate.sweep_thresholds`` (never ... always), on the TEST set, timed in one interleaved run.
    Returns (settings table, sweep table); see ``evaluate_gate`` and ``split_sweep``."""
    return split_sweep(evaluate_gate(model, gate, test, thresholds=sweep_thresholds(gate), **kwargs), gate)


# --------------------------------------------------------------------------- the study
def evaluation_level(P, study: str) -> float:
    """The test noise of the gating table: the largest evaluation level (out of distribution;
    the paper's pedestrian always-dropout row, 89.7 % / 12.9 m, is its DRF point at p = 0.05)."""
    return max(registry.study(study).eval_levels(P))


@torch.no_grad()
def selected_fraction(model, gate: Gate, data, device=None) -> float:
    """Fraction of the real frames of ``data`` (a SequenceData) that ``gate`` sends to MC dropout."""
    device = torch.device(device) if device is not None else next(model.parameters()).device
    was = eval_mode(model)
    try:
        gains = model.kalman_gains(as_model_input(model, data.inputs).to(device))
    finally:
        model.train(was)
    if gains is None:
        raise ValueError(f"model kind {model.config.get('kind')!r} has no Kalman filter; gating needs a model that "
                         f"declares competency_gain (the DRF, 'drf')")
    real = real_mask(data).to(device)
    return float(gate.select(gains, real).sum()) / int(real.sum())


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
                 val_noise: float | None = None) -> dict[str, pd.DataFrame]:
    """Fit a gate per DRF seed on validation data, then evaluate and sweep it on the test set (the DRF: the
    models that declare ``competency_gain``, ``gated_models``).

    Test: the ``test`` split at ``evaluation_level``. Validation: the ``val`` split (other
    sequences, other motions / scenes) at ``val_noise``, by default the test's noise level (held-out
    sequences of the shifted condition: an optimistic reference; the training noise is what a
    deployed system can tune on). The sweep's thresholds tune nothing, and claim C7 is judged on
    them; its rows hold Kalman-gain, random and oracle gating at each threshold. Times are measured on
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
        table, sweep = sweep_gate(model, gate, test, n_samples=P.uncertainty.n_samples, level=P.uncertainty.interval_level, seed=seed,
                                  device=device, min_run_time=min_run_time,
                                  timing_frames=P.gating.timing_frames)
        ident = {"study": study, "seed": seed, "noise": level_, "val_noise": val_level}
        gate_info = {"direction": gate.direction, "rank_correlation": gate.rank_correlation,
                     "val_fraction": gate.val_fraction, "val_picp": gate.val_picp,
                     "val_picp_always": gate.val_picp_always}
        tables.append(table.assign(**ident, **gate_info))
        sweeps.append(sweep.assign(**ident))
        vals.append(val_table.assign(study=study, seed=seed, val_noise=val_level))
    lead = ["study", "seed", "noise", "val_noise"]
    cat = lambda fs: pd.concat(fs, ignore_index=True)  # noqa: E731
    table, sweep = cat(tables), cat(sweeps)
    return {"table": table[lead + [c for c in table.columns if c not in lead]],
            "sweep": sweep[lead + [c for c in sweep.columns if c not in lead]],
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


__all__ = [
    "timing_subset", "measure_interleaved", "evaluate_gate", "sweep_gate", "split_sweep", "sweep_thresholds",
    "evaluation_level", "selected_fraction", "gated_models", "gating_study", "train_noise_gates", "paper_table",
]
