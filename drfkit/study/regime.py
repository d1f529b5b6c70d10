"""The noise-regime map: where along the noise axis does a learned filter help, and by how much
against the true-physics reference?

The book's protocol of each model kind (``drfkit.methods.protocols.regime_variant``) is trained at
several max noise levels on the second ablation round's budget (``drfkit.study.ablation.train_variant``: the same
data seeds, schedule and validation judgement as the ablation), then evaluated on a TEST split
of its own (the budget's, seed ``pend_data_seed + 2``, never read by training or selection) along the whole sweep
of max noise and on a blackout set (the test split at max noise 0.5 with ``blackout_frames``
pure noise). MAE is the dropout-off estimate's, as everywhere in the book. Beside every trained
noise, the true-physics particle filter (``drfkit.methods.references.reference_on``) on that noise's
no_dynamics estimates, calibrated on the validation split at its training noise.

One JSON row file per (variant, seed) and per reference, under ``<out>/<budget>/regime/``, keyed
by the run and every evaluation setting: a clean clone reads them without the models, and a
changed setting retrains (or reloads) only what it needs.

Shapes: the splits are ``load_pendulum`` arrays (images (N, T, 24, 24) uint8, targets (N, T, 2)).
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Iterable

import numpy as np
import pandas as pd

from drfkit.study import ablation
from drfkit.data.noise import Noise
from drfkit.data.pendulum import blackout_frames, with_blackout
from drfkit.methods.diagnostics import abs_error_per_frame, blackout_summary
from drfkit.data.pendulum import BLACKOUT_SEED_OFFSET
from drfkit.methods.references import reference_on
from drfkit.util.io import atomic_write_json, param_hash
from drfkit.methods.predictions import point_and_sigma
from drfkit.util.progress import steps
from drfkit.methods.protocols import REGIME_BASES, regime_variant
from drfkit.methods.train import load_checkpoint
from drfkit.study.pendulum_runs import load_split

BLACKOUT_NOISE = 0.5  # the blackout set's frames outside the blackout, for every training noise


def _test_sets(P, budget_name: str, levels: Iterable[float], n_test: int) -> dict[Any, dict[str, np.ndarray]]:
    """The regime's test splits (``ablation.budget_splits``' test split): one per max noise level, and 'blackout'."""
    D = ablation.budget_splits(P, budget_name, test_sequences=n_test)
    split = lambda level: load_split(D, "test", Noise("rkn_uniform", level))  # noqa: E731
    sets: dict[Any, dict[str, np.ndarray]] = {float(level): split(level) for level in levels}
    sets["blackout"] = with_blackout(split(BLACKOUT_NOISE), *blackout_frames(D.seq_len),
                                     seed=D.test_seed + BLACKOUT_SEED_OFFSET)
    return sets


def _settings(P, levels, n_test: int, n_samples: int, extra: dict | None = None) -> dict[str, Any]:
    # "point": the rows score the dropout-off pass (rows made from the MC mean carry no such field, so they are stale)
    return {"levels": [float(v) for v in levels], "n_test": int(n_test), "n_samples": int(n_samples),
            "blackout_noise": BLACKOUT_NOISE, "test_seed": ablation.regime_test_seed(P), "point": "dropout_off", **(extra or {})}


def _cached(path: Path, key: str) -> dict | None:
    if path.exists():
        row = json.loads(path.read_text())
        if row.get("key") == key:
            return row
    return None


def _model(P, name: str, seed: int, budget_name: str, out, progress: bool):
    """(model, ``ablation.VariantRun``) of a variant's trained run (trained if missing)."""
    res, run = ablation.train_variant(P, name, seed, budget_name, out, progress)
    return load_checkpoint(res.best_path), run


def _point_and_sigma(model, arrays, n_samples: int, seed: int, cache: Path | None) -> tuple[np.ndarray, np.ndarray]:
    """``predictions.point_and_sigma`` of ``model`` on arrays['images'] (the studies' evaluation, the same cache entry)."""
    return point_and_sigma(model, arrays["images"], cache=cache, n_samples=n_samples, seed=seed)


def model_key(P, kind: str, train_noise: float, seed: int, budget_name: str, out, levels, n_test: int,
              n_samples: int) -> tuple[str, Path]:
    """(key, row file) of a model's regime row: its run's ``run_key`` and every evaluation setting."""
    run = ablation.variant_run(P, regime_variant(kind, train_noise), seed, budget_name, out)
    key = param_hash({"run": run.key, **_settings(P, levels, n_test, n_samples)}, 8)
    return key, run.folder / "regime" / f"{run.name}-seed{seed}.json"


def reference_key(P, train_noise: float, seed: int, budget_name: str, out, levels, n_test: int, n_samples: int,
                  n_particles: int) -> tuple[str, Path]:
    """(key, row file) of the true-physics reference's regime row: the no_dynamics run it filters, the particles
    and every evaluation setting."""
    run = ablation.variant_run(P, regime_variant("no_dynamics", train_noise), seed, budget_name, out)
    key = param_hash({"run": run.key, "n_particles": int(n_particles), **_settings(P, levels, n_test, n_samples)}, 8)
    return key, run.folder / "regime" / f"physics_reference-train{train_noise:g}-seed{seed}.json"


def model_row(P, kind: str, train_noise: float, seed: int, budget_name: str, out, levels, n_test: int, n_samples: int,
              cache: Path | None = None, progress: bool = False) -> dict[str, Any]:
    """MAE of one (kind, training noise, seed) at every test level and on and through the blackout."""
    name = regime_variant(kind, train_noise)
    key, path = model_key(P, kind, train_noise, seed, budget_name, out, levels, n_test, n_samples)
    if (row := _cached(path, key)) is not None:
        return row
    model, _ = _model(P, name, seed, budget_name, out, progress)
    row: dict[str, Any] = {"model": kind, "variant": name, "train_noise": float(train_noise), "seed": seed,
                           "budget": budget_name, "key": key, "mae": {}}
    for level, arrays in _test_sets(P, budget_name, levels, n_test).items():
        mean, _ = _point_and_sigma(model, arrays, n_samples, seed, cache)
        per_frame = abs_error_per_frame(mean, arrays["targets"])
        if level == "blackout":
            row.update(blackout_summary(per_frame, blackout_frames(per_frame.size)))
            row["mae_per_frame_blackout"] = [round(float(v), 5) for v in per_frame]
        else:
            row["mae"][f"{level:g}"] = float(per_frame.mean())
    atomic_write_json(path, row)
    return row


def reference_row(P, train_noise: float, seed: int, budget_name: str, out, levels, n_test: int, n_samples: int,
                  n_particles: int, cache: Path | None = None, progress: bool = False) -> dict[str, Any]:
    """The true-physics reference (a particle filter) on the no_dynamics of ``train_noise`` (σ scale and outlier weight
    chosen on the validation split at that noise), at every test level and on the blackout."""
    name = regime_variant("no_dynamics", train_noise)
    key, path = reference_key(P, train_noise, seed, budget_name, out, levels, n_test, n_samples, n_particles)
    if (row := _cached(path, key)) is not None:
        return row
    model, run = _model(P, name, seed, budget_name, out, progress)
    val = load_split(run.splits, "val", run.noise(train_noise))
    table, curves = reference_on(lambda arrays: _point_and_sigma(model, arrays, n_samples, seed, cache), val,
                                 _test_sets(P, budget_name, levels, n_test), n_particles, seed)
    sweep = table[table["noise"] != "blackout"]
    per_frame = curves.sort_values("frame")["mae"].to_numpy()
    row = {"model": "physics_reference", "variant": name, "train_noise": float(train_noise), "seed": seed,
           "budget": budget_name, "key": key, "n_particles": int(n_particles),
           "sigma_scale": float(table["sigma_scale"].iloc[0]), "outlier": float(table["outlier"].iloc[0]),
           "mae": {f"{float(n):g}": float(m) for n, m in zip(sweep["noise"], sweep["mae"])},
           **blackout_summary(per_frame, blackout_frames(per_frame.size)),
           "mae_per_frame_blackout": [round(float(v), 5) for v in per_frame]}
    atomic_write_json(path, row)
    return row


def regime_map(P, train_noises: Iterable[float], seeds: Iterable[int], budget_name: str, out, levels, n_test: int,
               n_samples: int, n_particles: int, cache: Path | None = None, progress: bool = False) -> pd.DataFrame:
    """Long table: one row per (train_noise, model, seed, test) with ``mae``; ``test`` is a max
    noise level (as a string) or 'blackout' / 'after_blackout'; ``test_noise`` is its number
    (NaN for the blackout rows). Models: every kind of ``REGIME_BASES`` and 'physics_reference'."""
    rows = []
    todo = [(tn, seed) for tn in train_noises for seed in seeds]
    for train_noise, seed in steps(todo, "noise-regime map (training noise, seed)"):
        found = [model_row(P, kind, train_noise, seed, budget_name, out, levels, n_test, n_samples, cache, progress)
                 for kind in REGIME_BASES]
        found.append(reference_row(P, train_noise, seed, budget_name, out, levels, n_test, n_samples, n_particles,
                                   cache, progress))
        for row in found:
            base = {"train_noise": float(train_noise), "model": row["model"], "seed": seed}
            rows += [base | {"test": lv, "test_noise": float(lv), "mae": m} for lv, m in row["mae"].items()]
            rows += [base | {"test": "blackout", "test_noise": np.nan, "mae": row["mae_blackout"]},
                     base | {"test": "after_blackout", "test_noise": np.nan, "mae": row["mae_after_blackout"]}]
    return pd.DataFrame(rows)


def regime_summary(table: pd.DataFrame) -> pd.DataFrame:
    """Seed-mean MAE per (train_noise, test) with a column per model, and two ratios: the DRF
    over no_dynamics (< 1: the filter helps) and over the particle-filter reference (< 1: the DRF does
    better than filtering no_dynamics' outputs with the true physics)."""
    wide = table.pivot_table(index=["train_noise", "test"], columns="model", values="mae", aggfunc="mean",
                             sort=False)
    wide["drf_over_no_dynamics"] = wide["drf"] / wide["no_dynamics"]
    wide["drf_over_reference"] = wide["drf"] / wide["physics_reference"]
    return wide.reset_index().rename_axis(columns=None)


def profile_map(P, progress: bool = False) -> pd.DataFrame:
    """``regime_map`` with a profile's settings (``regime_*``, the budget of the ablation round that chose
    the book's protocol, ``ablation_round2_budget``, the sweep,
    ``n_samples``, ``reference_particles``); rows under ``results/<profile>/ablation``."""
    from drfkit.util.paths import predictions_dir, results_dir

    return regime_map(P, P.dynamics.regime.train_noise, P.dynamics.regime.seeds, P.dynamics.ablation.round2.budget,
                      results_dir(P.profile, "ablation"), P.pendulum.sweep_max_noise, P.dynamics.regime.test_sequences,
                      P.uncertainty.n_samples, P.dynamics.reference_particles,
                      cache=predictions_dir(P.profile), progress=progress)
