"""The protocol ablation of the pendulum study: which levers make the DRF filter?

Every variant (``drfkit.methods.protocols.VARIANTS``: a model kind, its options, a training-time
corruption) is trained on one small budget and judged on VALIDATION data only (the test split is never read here):

    val at the training noise, at 0.75 and at 1.0 (MAE, deterministic pass);
    val with its ``blackout_frames`` replaced by pure noise (MAE on and after the blackout);
    the mechanism diagnostics of ``drfkit.methods.diagnostics`` (r against noise at 0.75, gain on
    clean against pure-noise frames, one-step prediction, spectral radius of F_t).

A run goes the studies' way (``drfkit.study.pendulum_runs``): a budget is a ``PendulumSplits`` of the profile's
data seed and a schedule, a variant is the spec a protocol would name, and the run is named by the one
``run_key`` and trained by ``train_or_load`` (resumable). Its row is written atomically to
``<out>/<budget>/<variant>-seed<k>.json`` and reused while its key holds.

    python -m drfkit ablation --profile paper --budget small --variants paper book --seeds 0 1 --threads 1
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from drfkit.data.noise import Noise
from drfkit.data.pendulum import BLACKOUT_SEED_OFFSET, blackout_frames, with_blackout
from drfkit.methods.diagnostics import blackout_summary, diagnose
from drfkit.methods.protocols import ABLATION_BUDGETS as BUDGETS
from drfkit.methods.protocols import (ROUND2_VARIANTS, ROUND3_VARIANTS, ROUND4_VARIANTS, ROUND5_VARIANTS, VARIANTS,
                                      summarise_ablation, variant_spec)
from drfkit.methods.run_config import TrainConfig, run_key
from drfkit.methods.train import load_checkpoint, train_or_load
from drfkit.models import default_config
from drfkit.study.pendulum_runs import (PENDULUM, PROFILE_SCHEDULE, SPLIT_SEED_OFFSET, PendulumSplits, load_split,
                                        variant_data, variant_data_key, variant_fresh_training, variant_train_config)
from drfkit.util.device import pick_device
from drfkit.util.io import atomic_write_json, param_hash
from drfkit.util.paths import data_dir, results_dir

EVAL_LEVELS = (0.5, 0.75, 1.0)
ROUNDS = {2: ROUND2_VARIANTS, 3: ROUND3_VARIANTS, 4: ROUND4_VARIANTS, 5: ROUND5_VARIANTS}


def budget_splits(P, budget_name: str, train_max_noise: float = 0.5, test_sequences: int = 0) -> PendulumSplits:
    """A budget's data: its sizes on the profile's ``pend_data_seed`` (train = seed, val = seed + 1) and data cache.
    Its test split (the noise-regime map's, ``test_sequences`` long) keeps seed + 2, the split its rows were scored
    on; the study's own test split moved to ``pend_test_seed``, never read here."""
    if budget_name not in BUDGETS:
        raise ValueError(f"unknown budget {budget_name!r}; choose from {sorted(BUDGETS)}")
    b = BUDGETS[budget_name]
    return PendulumSplits(data_dir(P.profile), b["train_sequences"], b["val_sequences"], int(test_sequences),
                          b["seq_len"], float(train_max_noise), int(P.pendulum.data_seed), regime_test_seed(P))


def regime_test_seed(P) -> int:
    """The budgets' test split (the noise-regime map's): ``pend_data_seed + 2``."""
    return int(P.pendulum.data_seed) + SPLIT_SEED_OFFSET["test"]


@dataclass(frozen=True)
class VariantRun:
    """One (variant, seed) at a budget, resolved as a study's run: its data, model, schedule and ``run_key``."""
    name: str
    seed: int
    budget: str
    spec: dict[str, Any]
    splits: PendulumSplits
    config: dict[str, Any]
    train: TrainConfig
    data_key: dict[str, Any]
    key: str
    folder: Path  # <out>/<budget>: the rows; the checkpoints under models/

    @property
    def stem(self) -> Path:
        return self.folder / "models" / f"{self.name}-seed{self.seed}-{self.key}"

    def noise(self, level: float | None = None) -> Noise:
        return Noise("rkn_uniform", self.spec["train_max_noise"] if level is None else level)


def variant_run(P, name: str, seed: int, budget_name: str = "small", out: str | Path | None = None) -> VariantRun:
    """Resolve a variant at a budget: the budget's schedule, which a variant's recipe may override (the batch of
    ``fit_the_mean``), on the budget's data at the variant's training noise."""
    spec = variant_spec(name)
    splits = budget_splits(P, budget_name, spec["train_max_noise"])
    budget = BUDGETS[budget_name]
    schedule = {k: budget[k] for k in PROFILE_SCHEDULE if k in budget} | {
        k: v for k, v in spec["train"].items() if k in PROFILE_SCHEDULE}
    config = default_config(spec["kind"], PENDULUM.input_kind, PENDULUM.out_dim, **spec["model"])
    train = variant_train_config(schedule, spec, seed)
    data_key = variant_data_key(splits, spec)
    folder = (Path(out) if out is not None else results_dir(P.profile, "ablation")) / budget_name
    return VariantRun(name, int(seed), budget_name, spec, splits, config, train, data_key,
                      run_key(config, train, data_key), folder)


def train_variant(P, name: str, seed: int, budget_name: str = "small", out: str | Path | None = None,
                  progress: bool = True):
    """Train (or resume, or load when finished) one variant at one seed; returns (TrainResult, VariantRun)."""
    run = variant_run(P, name, seed, budget_name, out)
    return _train(P, run, progress), run


def _train(P, run: VariantRun, progress: bool):
    spec, D = run.spec, run.splits

    def data():
        return (variant_data(D, "train", run.noise(), spec), variant_data(D, "val", run.noise(), spec),
                variant_fresh_training(D, spec, run.noise()))

    return train_or_load(run.config, run.train, run.stem, data, data_key=param_hash(run.data_key),
                         device=pick_device(P.device), progress=progress,
                         recipe={"variant": run.name, "budget": run.budget, "train_max_noise": spec["train_max_noise"],
                                 "blackouts": spec["blackouts"], "fresh_noise": bool(spec["train"].get("fresh_noise")),
                                 "fresh_motion": bool(spec["train"].get("fresh_motion"))})


def run_variant(P, name: str, seed: int, budget_name: str = "small", out: str | Path | None = None,
                progress: bool = True) -> dict[str, Any]:
    """Train (or resume) one variant at one seed and return its validation row."""
    run = variant_run(P, name, seed, budget_name, out)
    row_path = run.folder / f"{name}-seed{seed}.json"
    if row_path.exists():
        row = json.loads(row_path.read_text())
        if row.get("key") == run.key:
            return row

    t0 = time.perf_counter()
    res = _train(P, run, progress)
    seconds = time.perf_counter() - t0
    model = load_checkpoint(res.best_path)

    row: dict[str, Any] = {"variant": name, "kind": run.spec["kind"], "seed": seed, "budget": budget_name, "key": run.key,
                           "best_epoch": res.best_epoch, "best_val_loss": res.best_val_loss,
                           "train_seconds": seconds if not res.resumed_from else None}
    for level in EVAL_LEVELS:
        summary, _ = diagnose(model, load_split(run.splits, "val", run.noise(level)))
        row[f"mae_{level:g}"] = summary.pop("mae")
        if level == 0.75:
            row.update(summary)
    frames = blackout_frames(run.splits.seq_len)
    dark = with_blackout(load_split(run.splits, "val", run.noise(0.5)), *frames,
                         seed=run.splits.data_seed + BLACKOUT_SEED_OFFSET)
    summary, per_frame = diagnose(model, dark)
    row.update(blackout_summary(per_frame, frames))
    for field in ("gain_clean", "gain_pure", "gain_ratio"):
        if field in summary:
            row[f"{field}_blackout"] = summary[field]
    row["mae_per_frame_blackout"] = [round(float(v), 5) for v in per_frame]
    atomic_write_json(row_path, row)
    return row


def _is_current(P, row: dict, budget_name: str) -> bool:
    """Whether a row was trained by what this code would train now (same variant, schedule, data
    seed and frames): rows kept from before a change (the former OpenCV frames, a retired
    variant) stay readable but are marked, never mistaken for a rerun."""
    try:
        return row.get("key") == variant_run(P, row["variant"], int(row["seed"]), budget_name).key
    except ValueError:  # a variant no longer defined
        return False


def ablation_table(P, budget_name: str = "small", out: str | Path | None = None) -> pd.DataFrame:
    """Every finished row of a budget, one per (variant, seed), without the per-frame curve;
    ``current`` is False for a row the present code would train differently (``_is_current``)."""
    folder = (Path(out) if out is not None else results_dir(P.profile, "ablation")) / budget_name
    rows = [json.loads(p.read_text()) for p in sorted(folder.glob("*-seed*.json"))]
    frame = pd.DataFrame(rows)
    if rows:
        frame["current"] = [_is_current(P, r, budget_name) for r in rows]
    return frame.drop(columns=["mae_per_frame_blackout", "key", "key_before"], errors="ignore")


MARKDOWN_COLUMNS = {"variant": "variant", "kind": "model", "n_seeds": "seeds", "mae_0.5": "MAE 0.5",
                    "mae_0.75": "MAE 0.75", "mae_1": "MAE 1.0", "mae_blackout": "blackout",
                    "r_noise_spearman": "ρ(r, noise)", "gain_ratio_blackout": "gain pure/clean",
                    "prior_ratio": "‖Fz−w‖/‖z−w‖"}


def summary_markdown(summary: pd.DataFrame) -> str:
    """The summary as the markdown table that docs/dynamics.md quotes (seed means on validation;
    tests/test_prose_numbers.py checks the quoted table against the rows on disk)."""
    cols = [c for c in MARKDOWN_COLUMNS if c in summary]
    lines = ["| " + " | ".join(MARKDOWN_COLUMNS[c] for c in cols) + " |", "|" + "---|" * len(cols)]
    for _, r in summary.iterrows():
        cells = [("" if pd.isna(r[c]) else f"{r[c]:.3g}" if isinstance(r[c], float) else str(r[c])) for c in cols]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


MECHANISM_TARGETS = ("r_follows_noise", "gain_drops", "f_predicts", "coasts")


def mechanism_targets(summary: pd.DataFrame, min_seeds: int = 2, kinds: tuple[str, ...] = ("drf",),
                      pure_noise_free: bool = False) -> pd.DataFrame:
    """Which of the filter's targets each DRF variant of a summary (``summarise_ablation``) meets on
    validation, by the thresholds of claims F1 and F2: rank correlation of r with the noise, gain on
    pure noise against clean frames, one-step prediction ratio, blackout MAE. Only variants trained at
    the paper's max noise 0.5 (a variant trained on other noise changes what "out of distribution"
    means) with at least ``min_seeds`` seeds. Sorted best first: most targets met, then the lowest
    MAE at 0.75 -- the rule that chose the book's DRF (``protocols.PROTOCOLS['book']``). ``kinds``: the
    filters judged; ``pure_noise_free``: only variants trained without pure-noise frames (no training
    blackouts), for which the blackout is out of distribution (the third round's rule)."""
    from drfkit.study.claims import F1_GAIN_RATIO, F1_PREDICTION_RATIO, F1_RANK_CORRELATION, F2_BLACKOUT_MAE

    rows = summary[summary["kind"].isin(kinds) & (summary["n_seeds"] >= min_seeds)]
    rows = rows[[variant_spec(v)["train_max_noise"] == 0.5 and not (pure_noise_free and variant_spec(v)["blackouts"])
                 for v in rows["variant"]]].copy()
    rows["r_follows_noise"] = rows["r_noise_spearman"] >= F1_RANK_CORRELATION
    rows["gain_drops"] = rows["gain_ratio_blackout"] <= F1_GAIN_RATIO
    rows["f_predicts"] = rows["prior_ratio"] < F1_PREDICTION_RATIO
    rows["coasts"] = rows["mae_blackout"] <= F2_BLACKOUT_MAE
    rows["targets_met"] = rows[list(MECHANISM_TARGETS)].sum(axis=1)
    cols = ["variant", "kind", "n_seeds", *MECHANISM_TARGETS, "targets_met", "mae_0.5", "mae_0.75", "mae_blackout"]
    return rows.sort_values(["targets_met", "mae_0.75"], ascending=[False, True])[cols].reset_index(drop=True)


def round2_reading(summary: pd.DataFrame) -> str:
    """What the second round's summary (``summarise_ablation``) says, in sentences written from
    its numbers: per model kind the variant with the lowest validation MAE at the training noise,
    at 0.75 and in the blackout, then the DRF's best against the LSTM's and no_dynamics'."""
    if summary.empty:
        return "No finished row yet."
    lines = []
    best: dict[str, dict[str, Any]] = {}
    for kind, rows in summary.groupby("kind", sort=True):
        parts = []
        for col, label in (("mae_0.5", "at 0.5"), ("mae_0.75", "at 0.75"), ("mae_blackout", "in the blackout")):
            if col in rows and rows[col].notna().any():
                r = rows.loc[rows[col].idxmin()]
                parts.append(f"{label} {r['variant']} ({r[col]:.4f}, {int(r['n_seeds'])} seed(s))")
                best.setdefault(kind, {})[col] = float(r[col])
        lines.append(f"{kind}: lowest validation MAE " + "; ".join(parts) + ".")
    if "drf" in best:
        for other in ("lstm", "no_dynamics"):
            if other in best:
                ratios = [f"{label} {best['drf'][col] / best[other][col]:.2f}x" for col, label in
                          (("mae_0.5", "at 0.5"), ("mae_0.75", "at 0.75"), ("mae_blackout", "blackout"))
                          if col in best["drf"] and col in best[other]]
                lines.append(f"best DRF / best {other}: " + ", ".join(ratios) + ".")
    return "\n".join(lines)
