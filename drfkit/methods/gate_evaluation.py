"""A fitted gate applied to a TEST set: metrics of every setting and threshold from two passes, and
the settings' times on the same inputs (``evaluate_gate``, ``sweep_gate``), and the fraction of frames
a gate selects (``selected_fraction``).

The gate itself, its fitting on validation data and gated inference are ``drfkit.methods.gating``'s;
these functions take the test set as an explicit argument and never tune anything on it. The
profile-driven study that calls them per seed is ``drfkit.study.gating_study``.
"""
from __future__ import annotations

import contextlib
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
import torch

from drfkit.core.metrics import prediction_metrics
from drfkit.methods.gating import (ALWAYS, NEVER, RANDOM_SEED_OFFSET, SETTINGS, Gate, GatedPrediction, apply_gating,
                                   assemble, competency_score, eval_mode, oracle_selection, real_mask, run_setting,
                                   select_frames, uncertainty_stage)
from drfkit.methods.timing.clock import measure_interleaved, timing_subset, torch_threads
from drfkit.methods.uncertainty import as_model_input
from drfkit.models.frame_codes import distinct_frames_once
from drfkit.models.parts import check_dropout_p, check_n_samples


def _metrics(pred: GatedPrediction, y: torch.Tensor, real: torch.Tensor, level: float,
             point: torch.Tensor) -> dict[str, float]:
    """Interval metrics of ``pred``, the MAE of ``point`` (the dropout-off pass: a setting changes the intervals only)."""
    m = prediction_metrics(pred.mean, pred.total, y, real, level, point=point)
    return {k: m[k] for k in ("picp", "mpiw", "nll", "mae")}


@dataclass
class ScoredGate:
    """What ``score_gate``'s untimed passes leave for ``time_gate``: the metric rows (setting, threshold,
    n_selected, picp, mpiw, nll, mae), each row's (setting, stage arguments), the random twins' Kalman-gain rows,
    the real frames scored and the sweep's threshold names. Small and picklable: a worker process scores, the
    caller times."""

    rows: list[dict[str, Any]]
    variants: dict[str, tuple[str, dict[str, Any]]]
    twin_of: dict[str, str]
    n_real: int
    thresholds: tuple[str, ...]


@torch.no_grad()
def score_gate(model, gate: Gate, test, *, n_samples: int, dropout_p: float | None = None, level: float = 0.95,
               seed: int = 0, device=None, thresholds: dict[str, float] | None = None,
               other_gates: dict[str, Gate] | None = None, features: tuple | None = None) -> ScoredGate:
    """The metrics of ``evaluate_gate`` (its docstring says what each row is), untimed, at the caller's threads:
    the features once (each distinct frame encoded once), one deterministic and one always-dropout pass (masks
    seeded by ``seed``), every setting ``assemble``d from the two. ``features``: (h, gains) of ``model.features``
    on the whole test set, computed here when None."""
    n_samples = check_n_samples(n_samples)
    p = model.default_dropout_p if dropout_p is None else check_dropout_p(dropout_p)
    device = torch.device(device) if device is not None else next(model.parameters()).device
    real = real_mask(test).to(device)
    y = test.targets.to(device)
    common = dict(n_samples=n_samples, dropout_p=p)
    rnd = dict(random_seed=seed + RANDOM_SEED_OFFSET)
    was = eval_mode(model)
    try:
        if features is None:
            with distinct_frames_once(model):  # untimed: each distinct frame encoded once, the same numbers
                features = model.features(as_model_input(model, test.inputs).to(device), return_gains=True)
        h, gains = features
        # Metrics from two full passes (``assemble``): every setting's frames take the same
        # deterministic or always-dropout result, so settings differ only in which frames they select.
        passes = {}
        for setting in ("no_dropout", "always"):
            torch.manual_seed(seed)
            passes[setting] = uncertainty_stage(model, h, gains, real, setting, **common)
    finally:
        model.train(was)
    # name -> (setting, stage keyword arguments); random twins take the Kalman-gain count
    variants: dict[str, tuple[str, dict[str, Any]]] = {"no_dropout": ("no_dropout", {}), "always": ("always", {})}
    rows = []

    def evaluate(name, setting, extra):
        pred = passes[setting] if setting in passes else assemble(
            passes["no_dropout"], passes["always"],
            select_frames(setting, gains, real, **extra, kind=model.config.get("kind")))
        variants[name] = (setting, extra)
        rows.append({"setting": name, "threshold": extra.get("threshold", NEVER if setting == "no_dropout"
                                                              else ALWAYS),
                     "n_selected": int(pred.selected[real].sum()),
                     **_metrics(pred, y, real, level, passes["no_dropout"].mean)})
        return pred

    evaluate("no_dropout", "no_dropout", {})
    evaluate("always", "always", {})
    twin_of: dict[str, str] = {}  # random twin -> its Kalman-gain row
    # the oracle twins of the sweep: as many frames, those of largest true error (metrics only: never timed)
    abs_error = (passes["no_dropout"].mean - y).abs().mean(dim=-1)
    gated = {"kalman_gain": (gate.direction, gate.threshold),
             **{f"kalman_gain@{k}": (g.direction, g.threshold) for k, g in (other_gates or {}).items()},
             **{k: (gate.direction, thr) for k, thr in (thresholds or {}).items()}}
    for name, (direction, thr) in gated.items():
        n_sel = int(evaluate(name, "kalman_gain", {"direction": direction, "threshold": thr}).selected.sum())
        twin = ("random" if name == "kalman_gain" else name.replace("kalman_gain@", "random@")
                if name.startswith("kalman_gain@") else f"random:{name}")
        pred = evaluate(twin, "random", {**rnd, "n_random": n_sel})
        assert int(pred.selected.sum()) == n_sel
        rows[-1]["threshold"] = thr
        twin_of[twin] = name
        if name in (thresholds or {}):
            pred = assemble(passes["no_dropout"], passes["always"], oracle_selection(abs_error, real, n_sel))
            rows.append({"setting": f"oracle:{name}", "threshold": thr, "n_selected": n_sel,
                         **_metrics(pred, y, real, level, passes["no_dropout"].mean)})
    return ScoredGate(rows, variants, twin_of, int(real.sum()), tuple(thresholds or {}))


@torch.no_grad()
def time_gate(model, scored: ScoredGate, test, *, n_samples: int, dropout_p: float | None = None,
              min_run_time: float = 0.3, device=None, timing_frames: int = 0, other_gates=None,
              features: tuple | None = None) -> pd.DataFrame:
    """``scored``'s table with the times of ``evaluate_gate`` (its docstring says what each column is), measured
    here at the caller's torch threads on about ``timing_frames`` real frames of evenly spaced test sequences
    (0: all). ``other_gates``: their names (the 'kalman_gain@name' rows' whole inference is timed too).
    ``features``: (h, gains) on the whole test set when ``timing_frames`` covers it (computed here otherwise)."""
    n_samples = check_n_samples(n_samples)
    p = model.default_dropout_p if dropout_p is None else check_dropout_p(dropout_p)
    device = torch.device(device) if device is not None else next(model.parameters()).device
    x = as_model_input(model, test.inputs).to(device)
    real = real_mask(test).to(device)
    common = dict(n_samples=n_samples, dropout_p=p)
    variants, twin_of = scored.variants, scored.twin_of
    was = eval_mode(model)
    try:
        idx = timing_subset(real.sum(dim=1), timing_frames).to(device)
        whole_set = idx.numel() == x.shape[0]
        x_t, real_t = (x, real) if whole_set else (x[idx], real[idx])
        h_t, gains_t = (features if whole_set and features is not None else model.features(x_t, return_gains=True))

        def n_timed_selected(kg_name: str) -> int:  # the Kalman-gain row's count on the timed subset
            kg_extra = variants[kg_name][1]
            return int(apply_gating(competency_score(gains_t, kg_extra["direction"]), kg_extra["threshold"],
                                    real_t).sum())

        timed = {name: (setting, extra if setting != "random" else {**extra, "n_random": n_timed_selected(twin_of[name])})
                 for name, (setting, extra) in variants.items()}
        stage_fns = {name: (lambda s=setting, e=extra: uncertainty_stage(model, h_t, gains_t, real_t, s,
                                                                         **common, **e))
                     for name, (setting, extra) in timed.items()}
        head_s = measure_interleaved(stage_fns, min_run_time / 2)
        whole_fns = {name: (lambda s=timed[name][0], e=timed[name][1]:
                            run_setting(model, x_t, real_t, s, **common, **e))
                     for name in (*SETTINGS, *(f"{k}@{g}" for g in (other_gates or {}) for k in ("kalman_gain", "random")))}
        whole_fns["features"] = lambda: model.features(x_t)
        whole_fns["features_gains"] = lambda: model.features(x_t, return_gains=True)
        whole_s = measure_interleaved(whole_fns, min_run_time, min_rounds=7)
    finally:
        model.train(was)
    n_timed = int(real_t.sum())
    frame = pd.DataFrame(scored.rows)
    frame["fraction"] = frame["n_selected"] / scored.n_real
    gains_used = frame["setting"].isin(["kalman_gain", *scored.thresholds]) | frame["setting"].str.startswith("kalman_gain@")
    per_frame = 1e3 / n_timed
    frame["head_ms"] = frame["setting"].map(head_s) * per_frame
    frame["features_ms"] = np.where(gains_used, whole_s["features_gains"], whole_s["features"]) * per_frame
    frame["time_ms"] = frame["features_ms"] + frame["head_ms"]
    frame["whole_ms"] = frame["setting"].map(whole_s) * per_frame
    frame["frames"] = scored.n_real
    frame["timed_frames"] = n_timed
    frame["batch_ms"] = frame["time_ms"] * n_timed
    frame["threads"] = torch.get_num_threads()
    order = ["setting", "threshold", "fraction", "n_selected", "picp", "mpiw", "nll", "mae", "time_ms",
             "head_ms", "features_ms", "whole_ms", "batch_ms", "frames", "timed_frames", "threads"]
    return frame[order]


@torch.no_grad()
def evaluate_gate(model, gate: Gate, test, *, n_samples: int, dropout_p: float | None = None,
                  level: float = 0.95, seed: int = 0, min_run_time: float = 0.3, device=None,
                  thresholds: dict[str, float] | None = None, timing_frames: int = 0,
                  other_gates: dict[str, Gate] | None = None, untimed_threads: int | None = None) -> pd.DataFrame:
    """The four settings on the TEST set (a SequenceData) with a gate fitted beforehand: ``score_gate``'s metrics
    (on ``untimed_threads``; None: the caller's count), then ``time_gate``'s times (at the caller's count).

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
    deterministic prediction; metrics only, its times are NaN) (used by ``sweep_gate``). ``other_gates``
    (name -> a gate fitted elsewhere, e.g. on validation at the training noise) adds its Kalman-gain row
    'kalman_gain@<name>' (its own direction and threshold) and random twin 'random@<name>', from the same
    passes and timed in the same run, whole inference included: one pass of the test set serves every gate.

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
    device = torch.device(device) if device is not None else next(model.parameters()).device
    with torch_threads(untimed_threads) if untimed_threads else contextlib.nullcontext():
        was = eval_mode(model)
        try:
            with distinct_frames_once(model):  # untimed: each distinct frame encoded once, the same numbers
                features = model.features(as_model_input(model, test.inputs).to(device), return_gains=True)
        finally:
            model.train(was)
        scored = score_gate(model, gate, test, n_samples=n_samples, dropout_p=dropout_p, level=level, seed=seed,
                            device=device, thresholds=thresholds, other_gates=other_gates, features=features)
    return time_gate(model, scored, test, n_samples=n_samples, dropout_p=dropout_p, min_run_time=min_run_time,
                     device=device, timing_frames=timing_frames, other_gates=other_gates, features=features)


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


__all__ = ["ScoredGate", "score_gate", "time_gate", "evaluate_gate", "sweep_gate", "split_sweep", "sweep_thresholds", "selected_fraction"]
