"""The protocol ablation of the pendulum study: which levers make the DRF filter?

Every variant (``drfkit.methods.protocols.VARIANTS``: a model kind, its options, a training-time
corruption) is trained on one small budget and judged on VALIDATION data only (the test split is never read here):

    val at the training noise, at 0.75 and at 1.0 (MAE, deterministic pass);
    val with its ``blackout_frames`` replaced by pure noise (MAE on and after the blackout);
    the mechanism diagnostics of ``drfkit.methods.diagnostics`` (r against noise at 0.75, gain on
    clean against pure-noise frames, one-step prediction, spectral radius of F_t).

A run is ``train_model`` with its own checkpoints (resumable); its row is written
atomically to ``<out>/<budget>/<variant>-seed<k>.json`` and reused while its fingerprint holds.

    python -m drfkit ablation --budget small --variants paper book --seeds 0 1 --threads 1
"""
from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import pandas as pd
import torch

from drfkit.data.noise import Noise
from drfkit.data.pendulum import (GENERATOR_VERSION, blackout_frames, fresh_noise_seed, generate_pendulum, load_pendulum,
                                  redraw_noise, with_blackout, with_random_blackouts)
from drfkit.methods.diagnostics import blackout_summary, diagnose
from drfkit.data.pendulum import BLACKOUT_SEED_OFFSET, TRAINING_BLACKOUT_SEED_OFFSET  # the profile's seed offsets: the same corruption
from drfkit.util.io import atomic_write_json, param_hash
from drfkit.util.paths import results_root
from drfkit.methods.protocols import ABLATION_BUDGETS as BUDGETS
from drfkit.methods.protocols import ROUND2_VARIANTS, ROUND3_VARIANTS, ROUND4_VARIANTS, VARIANTS, summarise_ablation, variant_spec
from drfkit.methods.train import SequenceData, TrainConfig, load_checkpoint, train_model

DATA_SEED = 1000  # the profiles' pend_data_seed: train = seed, val = seed + 1 (test, seed + 2, is never read)

EVAL_LEVELS = (0.5, 0.75, 1.0)
ROUNDS = {2: ROUND2_VARIANTS, 3: ROUND3_VARIANTS, 4: ROUND4_VARIANTS}
# fresh trajectories (the encoder probe): seeds far from every split's (data seed + 0, 1, 2)
FRESH_MOTION_SEED = 10_000_000


def _split(cache: Path, budget: dict, split: str, level: float) -> dict:
    n = budget["train_sequences"] if split == "train" else budget["val_sequences"]
    seed = DATA_SEED + (0 if split == "train" else 1)
    return load_pendulum(cache, f"ablation-{split}", n, budget["seq_len"], Noise("rkn_uniform", level), seed)


def _as_data(arrays: dict) -> SequenceData:
    return SequenceData(torch.from_numpy(arrays["images"]), torch.from_numpy(arrays["targets"]))


def _run(name: str, seed: int, budget_name: str, out: str | Path | None) -> tuple[dict, dict, Path, str]:
    """(budget, spec, budget folder, key) of one variant run; the key covers all that trains it."""
    if budget_name not in BUDGETS:
        raise ValueError(f"unknown budget {budget_name!r}; choose from {sorted(BUDGETS)}")
    budget, spec = BUDGETS[budget_name], variant_spec(name)
    root = Path(out) if out is not None else results_root() / "ablation"
    key_spec = {k: v for k, v in spec.items() if not (k == "train" and not v)}  # rows from before 'train' keep their key
    key = param_hash({"budget": budget, "spec": key_spec, "seed": seed, "data_seed": DATA_SEED,
                      "frames": GENERATOR_VERSION}, 8)
    return budget, spec, root / budget_name, key


def data_dir(out: str | Path | None) -> Path:
    """The data cache of an ablation folder (shared by every budget)."""
    return (Path(out) if out is not None else results_root() / "ablation") / "data"


def train_variant(name: str, seed: int, budget_name: str = "small", out: str | Path | None = None,
                  progress: bool = True):
    """Train (or resume, or load when finished) one variant at one seed; returns (TrainResult, key)."""
    budget, spec, folder, key = _run(name, seed, budget_name, out)
    cache = data_dir(out)
    noise = Noise("rkn_uniform", spec["train_max_noise"])
    clean_train = _split(cache, budget, "train", spec["train_max_noise"])
    train = clean_train
    if spec["blackouts"]:
        train = with_random_blackouts(train, spec["blackouts"]["fraction"], tuple(spec["blackouts"]["lengths"]),
                                      seed=DATA_SEED + TRAINING_BLACKOUT_SEED_OFFSET)
    val = _split(cache, budget, "val", spec["train_max_noise"])
    config = {"kind": spec["kind"], "input_kind": "pendulum", "out_dim": 2, **spec["model"]}
    cfg = train_config(budget, spec["train"], seed)
    fresh = None
    if spec["train"].get("fresh_motion"):
        def fresh(epoch: int) -> SequenceData:  # new trajectories (and their noise) every epoch: unlimited frames
            return _as_data(generate_pendulum(budget["train_sequences"], budget["seq_len"], noise,
                                              FRESH_MOTION_SEED + fresh_noise_seed(DATA_SEED, epoch)))
    elif spec["train"].get("fresh_noise"):
        def fresh(epoch: int) -> SequenceData:  # the same clean frames, new noise (and blackouts) per epoch
            return _as_data(redraw_noise(clean_train, noise, fresh_noise_seed(DATA_SEED, epoch), spec["blackouts"]))
    res = train_model(config, _as_data(train), _as_data(val), cfg, folder / "models" / f"{name}-seed{seed}-{key}",
                      data_key=key, progress=progress, fresh_train=fresh,
                      recipe={"variant": name, "budget": budget_name, "train_max_noise": spec["train_max_noise"],
                              "blackouts": spec["blackouts"], "fresh_noise": bool(spec["train"].get("fresh_noise")),
                              "fresh_motion": bool(spec["train"].get("fresh_motion"))})
    return res, key


def train_config(budget: dict, overrides: dict, seed: int) -> TrainConfig:
    """The budget's schedule with a variant's ``train`` overrides (``fresh_noise`` is the data's
    business; ``mse_warmup: "half"`` means half the budget's epochs)."""
    fields = {"epochs": budget["epochs"], "lr": budget["lr"], "batch_size": budget["batch_size"]}
    fields |= {k: v for k, v in overrides.items() if k not in ("fresh_noise", "fresh_motion")}
    if fields.get("mse_warmup") == "half":
        fields["mse_warmup"] = fields["epochs"] // 2
    return TrainConfig(seed=seed, **fields)


def run_variant(name: str, seed: int, budget_name: str = "small", out: str | Path | None = None,
                progress: bool = True) -> dict[str, Any]:
    """Train (or resume) one variant at one seed and return its validation row."""
    budget, spec, folder, key = _run(name, seed, budget_name, out)
    cache = data_dir(out)
    row_path = folder / f"{name}-seed{seed}.json"
    if row_path.exists():
        row = json.loads(row_path.read_text())
        if row.get("key") == key:
            return row

    t0 = time.perf_counter()
    res, _ = train_variant(name, seed, budget_name, out, progress)
    seconds = time.perf_counter() - t0
    model = load_checkpoint(res.best_path)

    row: dict[str, Any] = {"variant": name, "kind": spec["kind"], "seed": seed, "budget": budget_name, "key": key,
                           "best_epoch": res.best_epoch, "best_val_loss": res.best_val_loss,
                           "train_seconds": seconds if not res.resumed_from else None}
    for level in EVAL_LEVELS:
        summary, _ = diagnose(model, _split(cache, budget, "val", level))
        row[f"mae_{level:g}"] = summary.pop("mae")
        if level == 0.75:
            row.update(summary)
    frames = blackout_frames(budget["seq_len"])
    dark = with_blackout(_split(cache, budget, "val", 0.5), *frames, seed=DATA_SEED + BLACKOUT_SEED_OFFSET)
    summary, per_frame = diagnose(model, dark)
    row.update(blackout_summary(per_frame, frames))
    for field in ("gain_clean", "gain_pure", "gain_ratio"):
        if field in summary:
            row[f"{field}_blackout"] = summary[field]
    row["mae_per_frame_blackout"] = [round(float(v), 5) for v in per_frame]
    atomic_write_json(row_path, row)
    return row


def _is_current(row: dict, budget_name: str, out: str | Path | None) -> bool:
    """Whether a row was trained by what this code would train now (same variant, schedule, data
    seed and frames): rows kept from before a change (the former OpenCV frames, a retired
    variant) stay readable but are marked, never mistaken for a rerun."""
    try:
        return row.get("key") == _run(row["variant"], int(row["seed"]), budget_name, out)[3]
    except ValueError:  # a variant no longer defined
        return False


def ablation_table(budget_name: str = "small", out: str | Path | None = None) -> pd.DataFrame:
    """Every finished row of a budget, one per (variant, seed), without the per-frame curve;
    ``current`` is False for a row the present code would train differently (``_is_current``)."""
    folder = (Path(out) if out is not None else results_root() / "ablation") / budget_name
    rows = [json.loads(p.read_text()) for p in sorted(folder.glob("*-seed*.json"))]
    frame = pd.DataFrame(rows)
    if rows:
        frame["current"] = [_is_current(r, budget_name, out) for r in rows]
    return frame.drop(columns=["mae_per_frame_blackout", "key"], errors="ignore")


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
