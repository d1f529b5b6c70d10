"""Evaluation: metrics of one model on one data set, and summaries over seeds.

Every number in the book's tables comes through ``evaluate_model`` (predict once with
MC dropout, then all metrics on the same predictions) and ``summarise`` (mean and a
95 % Student-t interval over seeds: mean ± t_{0.975, n-1} · sd / sqrt(n); with a single
seed the interval is undefined and left empty).
"""
from __future__ import annotations

import math
from typing import Any, Iterable

import numpy as np
import pandas as pd
import torch

from drfkit.core import metrics
from drfkit.core.metrics import prediction_metrics, t975  # noqa: F401 (defined with the metrics)
from drfkit.util.paths import predictions_dir
from drfkit.methods.predictions import EVAL_BATCH_SIZE, cached_predict_rates
from drfkit.util.progress import steps
from drfkit.util.tasks import forget, map_tasks, memo
from drfkit.models.portable import portable
from drfkit.methods.train import SequenceData

METRICS = ("mae", "picp", "mpiw", "nll", "crps", "cal_error")

# The values each metric can take (PICP is a fraction): interval ends are clipped to them.
METRIC_RANGES = {"mae": (0.0, math.inf), "picp": (0.0, 1.0), "mpiw": (0.0, math.inf), "crps": (0.0, math.inf),
                 "cal_error": (0.0, 1.0)}

def evaluate_model(model, data: SequenceData, *, n_samples: int, dropout_p: float | None = None,
                   level: float = 0.95, batch_size: int = 256, device=None) -> dict[str, float]:
    """Predict ``data`` with MC dropout and return every metric (PICP as a fraction): the MAE of the
    dropout-off pass, the interval metrics of the MC-dropout predictive Gaussian."""
    return evaluate_model_rates(model, data, n_samples=n_samples, dropout_rates=[dropout_p], level=level,
                                batch_size=batch_size, device=device)[0]


def evaluate_model_rates(model, data: SequenceData, *, n_samples: int, dropout_rates, level: float = 0.95,
                         batch_size: int = EVAL_BATCH_SIZE, device=None, seed: int | None = None, cache=None,
                         sigma_scale: float = 1.0) -> list[dict[str, float]]:
    """``evaluate_model`` at several dropout rates; the encoder and filter run once. With a
    ``seed`` the dropout masks are seeded here and the prediction may come from ``cache``
    (``drfkit.methods.predictions``); without one the caller's random state is used. ``sigma_scale``: every
    predictive sigma times this number (a recalibration, ``drfkit.methods.calibration``; 1 = as trained)."""
    from drfkit.methods.uncertainty import predict_rates

    if seed is None:
        preds = predict_rates(model, data.inputs, n_samples=n_samples, dropout_rates=dropout_rates,
                              batch_size=batch_size, device=device)
    else:
        preds = cached_predict_rates(model, data.inputs, cache=cache, n_samples=n_samples,
                                     dropout_rates=dropout_rates, seed=seed, batch_size=batch_size, device=device)
    out = []
    for pred in preds:
        m = prediction_metrics(pred.mean, pred.total * sigma_scale, data.targets, data.mask, level, point=pred.point)
        m["aleatoric"] = float(pred.aleatoric.mean())
        m["epistemic"] = float(pred.epistemic.mean())
        out.append(m)
    return out


def compare_prediction_modes(models: dict[str, Any], data: SequenceData, *, n_samples: int, level: float = 0.95,
                             seed: int = 0, batch_size: int = 256) -> pd.DataFrame:
    """Each model's metrics on ``data`` predicted two ways: one deterministic pass (dropout
    off, what the validation loss of training uses) and MC dropout with ``n_samples`` passes
    (what every reported number uses). One row per (name, mode)."""
    from drfkit.methods.uncertainty import predict

    rows = []
    for name, model in models.items():
        for mode, s in (("deterministic", 0), ("mc_dropout", n_samples)):
            torch.manual_seed(seed)
            pred = predict(model, data.inputs, n_samples=s, batch_size=batch_size)
            rows.append({"checkpoint": name, "epoch": model.checkpoint_meta.get("epoch"), "mode": mode,
                         **prediction_metrics(pred.mean, pred.total, data.targets, data.mask, level, point=pred.point)})
    return pd.DataFrame(rows)


def summarise(frame: pd.DataFrame, by: Iterable[str], values: Iterable[str] = METRICS) -> pd.DataFrame:
    """Mean, 95 % t-interval half-width and seed count of ``values`` grouped ``by``.

    Output columns: ``by...``, ``n_seeds``, and for each value ``<v>``, ``<v>_ci`` (half-width),
    ``<v>_lo``, ``<v>_hi``. A group that holds a seed twice (with a ``seed`` column) is refused: its
    rows are not independent, and counting them would narrow the interval (pseudo-replication).
    """
    by, values = list(by), [v for v in values if v in frame.columns]
    rows = []
    for key, group in frame.groupby(by, sort=False):
        key = key if isinstance(key, tuple) else (key,)
        if "seed" in group and group["seed"].duplicated().any():
            raise ValueError(f"summarise: the group {dict(zip(by, key))} holds seed(s) "
                             f"{sorted(group.loc[group['seed'].duplicated(), 'seed'].unique())} more than once; "
                             "each seed must be counted once (a level or model evaluated twice?)")
        row: dict[str, Any] = dict(zip(by, key))
        row["n_seeds"] = len(group)
        for v in values:
            x = group[v].to_numpy(dtype=float)
            mean = float(x.mean())
            half = t975(len(x) - 1) * float(x.std(ddof=1)) / math.sqrt(len(x)) if len(x) > 1 else math.nan
            lo, hi = METRIC_RANGES.get(v, (-math.inf, math.inf))
            # with 2 or 3 seeds the t-interval is wide; its ends are clipped to what the metric can take
            row.update({v: mean, f"{v}_ci": half, f"{v}_lo": max(mean - half, lo), f"{v}_hi": min(mean + half, hi)})
        rows.append(row)
    return pd.DataFrame(rows)


def evaluate_study(P, study: str, noise_levels: Iterable[float], dropout_rates: Iterable[float | None] = (None,),
                   models: dict | None = None, sequences: dict[float, int] | None = None,
                   sigma_scales: dict[tuple[str, int], float] | None = None) -> pd.DataFrame:
    """Every trained (model, seed) of ``study`` at every test noise level and dropout rate.

    Returns one row per (model, seed, noise, dropout_p) with all ``METRICS`` (PICP as a
    fraction) and 'sequences', the test sequences evaluated. ``dropout_p = None`` means each model's own training
    rate. ``sequences`` (level -> N): evaluate that level on the first N test sequences only (a sweep's levels that no
    claim reads); every other level on all. A level named twice is refused (its rows would count every seed
    twice). ``sigma_scales`` ((kind, seed) -> s): every sigma of that model times s (``uncertainty_scales``: the
    intervals recalibrated on validation; the rows then carry 'sigma_scale'). Test sets are built by ``drfkit.study.studies`` with the same motions / pedestrians at every noise level.
    """
    from drfkit.study import studies

    noise_levels = [float(v) for v in noise_levels]
    if len(set(noise_levels)) != len(noise_levels):  # each seed would be counted twice there
        raise ValueError(f"evaluate_study: the test levels {noise_levels} name a level twice; pass each level once "
                         f"(e.g. sorted({{train_level, *eval_levels}}))")
    models = models if models is not None else studies.trained_models(P, study)
    scales = {key: 1.0 if sigma_scales is None else sigma_scales[key] for key in models}
    items = [(P, study, noise, (sequences or {}).get(noise), kind, seed, list(dropout_rates), scales[(kind, seed)])
             for noise in noise_levels for kind, seed in models]
    # each level's test set read (made, the first time) here, once: the tasks in this process reuse it, and
    # workers only read files that exist (no two processes make one set)
    forget()
    for noise in noise_levels:
        _test_set(P, study, noise, (sequences or {}).get(noise))
    per_task = map_tasks(_evaluate_task, items, shared=portable(models),
                         desc=f"{study}: {len(models)} models at {len(noise_levels)} test levels")
    rows = [row | ({} if sigma_scales is None else {"sigma_scale": scales[(row["model"], row["seed"])]})
            for task_rows in per_task for row in task_rows]
    return pd.DataFrame(rows)


def _test_set(P, study: str, noise: float, n: int | None) -> SequenceData:
    """A level's test set (its first ``n`` sequences), read once per process (``tasks.memo``)."""
    from drfkit.study import studies

    return memo((P, "test set", study, noise, n),
                lambda: first_sequences(studies.study_data(P, study, "test", noise), n))


def _evaluate_task(P, study: str, noise: float, n: int | None, kind: str, seed: int, dropout_rates: list,
                   sigma_scale: float, shared: dict) -> list[dict[str, Any]]:
    """One (model, seed) at one test level: ``evaluate_study``'s rows of it (a task of ``map_tasks``)."""
    from drfkit.study import studies

    model, data = shared[(kind, seed)].model, _test_set(P, study, noise, n)
    results = evaluate_model_rates(model, data, n_samples=P.uncertainty.n_samples, dropout_rates=dropout_rates,
                                   level=P.uncertainty.interval_level, device=studies.pick_device(P.device), seed=seed,
                                   cache=predictions_dir(P.profile), sigma_scale=sigma_scale)
    return [{"study": study, "model": kind, "seed": seed, "noise": float(noise),
             "dropout_p": model.default_dropout_p if p is None else float(p), **m, "sequences": len(data)}
            for p, m in zip(dropout_rates, results)]


def first_sequences(data: SequenceData, n: int | None) -> SequenceData:
    """The first ``n`` sequences of ``data`` (all of them when ``n`` is None or not smaller)."""
    if n is None or n >= len(data):
        return data
    if n < 1:
        raise ValueError(f"first_sequences: n = {n}; evaluate at least one sequence")
    return SequenceData(data.inputs[:n], data.targets[:n], None if data.mask is None else data.mask[:n])


def calibration_points(P, study: str, noise_levels: Iterable[float], models: dict | None = None) -> pd.DataFrame:
    """Calibration curves (expected vs observed quantile coverage), averaged over seeds.

    Returns columns study, model, noise, expected, observed (mean over seeds), observed_sd.
    """
    from drfkit.study import studies

    models = models if models is not None else studies.trained_models(P, study)
    device = studies.pick_device(P.device)
    rows = []
    noise_levels = list(noise_levels)
    for noise in steps(noise_levels, f"{study}: calibration at {len(noise_levels)} test levels"):
        data = studies.study_data(P, study, "test", noise)
        mask = _value_mask(data)
        for (kind, seed), model in models.items():
            pred = _prediction(P, model, data, seed, device)  # the evaluation's cache entry at this level
            expected, observed = metrics.calibration_curve(data.targets, pred.mean, pred.total, mask=mask)
            rows += [{"study": study, "model": kind, "seed": seed, "noise": float(noise), "expected": e,
                      "observed": o} for e, o in zip(expected, observed)]
    frame = pd.DataFrame(rows)
    return (frame.groupby(["study", "model", "noise", "expected"], as_index=False)["observed"]
            .agg(observed="mean", observed_sd="std"))


def _prediction(P, model, data: SequenceData, seed: int, device):
    """The model's own-rate prediction of ``data``, from the evaluation's cache entry when it exists."""
    return cached_predict_rates(model, data.inputs, cache=predictions_dir(P.profile), n_samples=P.uncertainty.n_samples,
                                dropout_rates=[None], seed=seed, batch_size=EVAL_BATCH_SIZE, device=device)[0]


def _value_mask(data: SequenceData):
    return None if data.mask is None else np.broadcast_to(data.mask.numpy()[..., None], data.targets.shape)


def uncertainty_scales(P, study: str, models: dict, protocol: str = "paper") -> dict[tuple[str, int], float]:
    """(kind, seed) -> s: the one-scalar recalibration of each model's predictive sigma (MC dropout at its own
    rate, ``drfkit.methods.calibration.sigma_scale``), fitted on the VALIDATION split at the training noise only.
    One task per model (``drfkit.util.tasks.map_tasks``)."""
    forget()
    _val_set(P, study, protocol)
    keys = list(models)
    scales = map_tasks(_scale_task, [(P, study, protocol, kind, seed) for kind, seed in keys], shared=portable(models),
                       desc=f"{study}: sigma scales on validation")
    return dict(zip(keys, scales))


def _val_set(P, study: str, protocol: str) -> SequenceData:
    from drfkit.study import studies

    return memo((P, "val set", study, protocol), lambda: studies.study_data(P, study, "val", protocol=protocol))


def _scale_task(P, study: str, protocol: str, kind: str, seed: int, shared: dict) -> float:
    from drfkit.methods.calibration import sigma_scale
    from drfkit.study import studies

    val = _val_set(P, study, protocol)
    pred = _prediction(P, shared[(kind, seed)].model, val, seed, studies.pick_device(P.device))
    return sigma_scale(val.targets.numpy(), pred.mean.numpy(), pred.total.numpy(), _value_mask(val))


def calibration_table(P, study: str, noise_levels: Iterable[float], models: dict, scales: dict[tuple[str, int], float],
                      sequences: dict[float, int] | None = None) -> pd.DataFrame:
    """The primary uncertainty table: per (model, seed, noise, intervals) the coverage at the nominal 68 / 90 / 95 %
    levels, their widths, the NLL and the calibration error (``drfkit.methods.calibration.calibration_summary``) of
    the MC-dropout predictive Gaussian at the model's own rate, 'as trained' and 'recalibrated' (every sigma times
    the model's validation ``scales``); beside them the dropout-off MAE and RMSE and the mean aleatoric and
    epistemic sigma. ``sequences`` as ``evaluate_study``'s (the same cache entries). One task per (model, level)."""
    levels = [float(v) for v in noise_levels]
    forget()
    for noise in levels:
        _test_set(P, study, noise, (sequences or {}).get(noise))
    items = [(P, study, noise, (sequences or {}).get(noise), kind, seed, scales[(kind, seed)])
             for noise in levels for kind, seed in models]
    per_task = map_tasks(_calibration_task, items, shared=portable(models), desc=f"{study}: calibration at {len(levels)} test levels")
    return pd.DataFrame([row for rows in per_task for row in rows])


def _calibration_task(P, study: str, noise: float, n: int | None, kind: str, seed: int, scale: float,
                      shared: dict) -> list[dict[str, Any]]:
    from drfkit.methods.calibration import calibration_summary
    from drfkit.study import studies

    data = _test_set(P, study, noise, n)
    mask, y = _value_mask(data), data.targets.numpy()
    pred = _prediction(P, shared[(kind, seed)].model, data, seed, studies.pick_device(P.device))
    point = pred.point.numpy()
    err = (point - y) if mask is None else (point - y)[mask]
    base = {"study": study, "model": kind, "seed": seed, "noise": noise, "mae": float(np.abs(err).mean()),
            "rmse": float(np.sqrt(np.mean(np.square(err)))),
            "aleatoric": float(pred.aleatoric.mean()), "epistemic": float(pred.epistemic.mean())}
    return [base | {"intervals": name} | calibration_summary(y, pred.mean.numpy(), pred.total.numpy(), mask, scale=s)
            for name, s in (("as trained", 1.0), ("recalibrated", scale))]
