"""Move the protocol ablation's and the noise-regime map's committed rows to the one run key.

Until the ablation went the studies' way, its rows were keyed by its own formula (``legacy_key``: the budget, the
variant's spec, the seed, a hard-coded data seed 1000 and the generator version) and trained on a sparse model
configuration; now every run is named by ``drfkit.methods.run_config.run_key`` (full model configuration, the
naming fields of its ``TrainConfig``, the study's data key). The training itself did not change: ``--verify``
checks, for every variant and budget, that the new path resolves the same ``TrainConfig``, a model with the same
configuration and the same initial weights, and the same data, as the legacy formula below (and, for the
checkpoints kept locally, that their stored configuration agrees). A row is migrated only if its key is the
legacy formula's for it (it was current before the move); its old key stays in ``key_before`` so that
tests/test_protocols.py can check the migration. Rows that were stale stay stale.

    python tools/migrate_run_keys.py --profile paper --verify      # check only
    python tools/migrate_run_keys.py --profile paper --write       # rewrite the rows' keys, move local checkpoints

The ablation's checkpoints are not committed; those trained before the move are renamed to their new stem and their
fingerprint rewritten (``migrate_checkpoints``), so that they are found instead of retrained.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from drfkit.data.pendulum import GENERATOR_VERSION  # noqa: E402
from drfkit.methods.protocols import ABLATION_BUDGETS, VARIANTS, variant_spec  # noqa: E402
from drfkit.methods.run_config import TrainConfig  # noqa: E402
from drfkit.util.io import atomic_write_json, param_hash  # noqa: E402

LEGACY_DATA_SEED = 1000  # the ablation's former module constant


# ---------------------------------------------------------------- the legacy formula, frozen as it was
def legacy_key(name: str, seed: int, budget_name: str) -> str:
    spec = variant_spec(name)
    key_spec = {k: v for k, v in spec.items() if not (k == "train" and not v)}
    return param_hash({"budget": ABLATION_BUDGETS[budget_name], "spec": key_spec, "seed": seed,
                       "data_seed": LEGACY_DATA_SEED, "frames": GENERATOR_VERSION}, 8)


def legacy_model_config(spec: dict[str, Any]) -> dict[str, Any]:
    return {"kind": spec["kind"], "input_kind": "pendulum", "out_dim": 2, **spec["model"]}


def legacy_train_config(budget: dict[str, Any], overrides: dict[str, Any], seed: int) -> TrainConfig:
    fields = {"epochs": budget["epochs"], "lr": budget["lr"], "batch_size": budget["batch_size"]}
    fields |= {k: v for k, v in overrides.items() if k not in ("fresh_noise", "fresh_motion")}
    if fields.get("mse_warmup") == "half":
        fields["mse_warmup"] = fields["epochs"] // 2
    return TrainConfig(seed=seed, **fields)


def legacy_regime_key(P, kind_or_reference: str, train_noise: float, seed: int, budget_name: str,
                      settings: dict[str, Any], n_particles: int | None) -> str:
    from drfkit.methods.protocols import regime_variant

    kind = "no_dynamics" if kind_or_reference == "physics_reference" else kind_or_reference
    run = legacy_key(regime_variant(kind, train_noise), seed, budget_name)
    extra = {} if n_particles is None else {"n_particles": int(n_particles)}
    return param_hash({"run": run, **extra, **settings}, 8)


# ---------------------------------------------------------------- checks and the migration
def verify(P, budgets: list[str], checkpoints: Path | None) -> list[str]:
    """Differences between the legacy resolution and the new one (empty: the same training)."""
    import numpy as np
    import torch

    from drfkit.data.noise import Noise
    from drfkit.data.pendulum import load_pendulum
    from drfkit.models import build_model
    from drfkit.study import ablation
    from drfkit.study.pendulum_runs import load_split

    problems, verify.checkpoints = [], 0
    for budget_name in budgets:
        for name in VARIANTS:
            run = ablation.variant_run(P, name, 0, budget_name)
            spec, budget = run.spec, ABLATION_BUDGETS[budget_name]
            if run.train != legacy_train_config(budget, spec["train"], 0):
                problems.append(f"{budget_name}/{name}: TrainConfig {run.train} != {legacy_train_config(budget, spec['train'], 0)}")
            torch.manual_seed(0)
            old = build_model(legacy_model_config(spec))
            torch.manual_seed(0)
            new = build_model(run.config)
            if old.config != new.config or any(not torch.equal(a, b) for a, b in
                                               zip(old.state_dict().values(), new.state_dict().values())):
                problems.append(f"{budget_name}/{name}: the model differs")
    # the data, once per budget and noise level (the legacy cache name and seeds against load_split)
    for budget_name in budgets:
        b = ABLATION_BUDGETS[budget_name]
        for level in sorted({variant_spec(v)["train_max_noise"] for v in VARIANTS}):
            D = ablation.budget_splits(P, budget_name, level)
            for split, offset in (("train", 0), ("val", 1)):
                n = b["train_sequences"] if split == "train" else b["val_sequences"]
                legacy = load_pendulum(D.cache, f"ablation-{split}", n, b["seq_len"], Noise("rkn_uniform", level),
                                       LEGACY_DATA_SEED + offset)
                new = load_split(D, split, Noise("rkn_uniform", level))
                if not all(np.array_equal(legacy[k], new[k]) for k in legacy):
                    problems.append(f"{budget_name}: {split} data at {level} differs")
    if checkpoints is not None:  # the runs trained locally: their stored configuration against the new path's
        for budget_name in budgets:
            for path in sorted((checkpoints / budget_name / "models").glob("*-best.pt")):
                state = torch.load(path, map_location="cpu", weights_only=False)
                meta = state.get("meta", {})
                recipe = meta.get("recipe") or {}
                if "variant" not in recipe:
                    continue
                seed = int(meta["train"]["seed"])
                run = ablation.variant_run(P, recipe["variant"], seed, budget_name)
                if meta.get("data") != legacy_key(recipe["variant"], seed, budget_name):
                    continue  # a run of a former recipe: not what a committed row was trained by
                checked = build_model(state["config"]).config == run.config and TrainConfig(**meta["train"]) == run.train
                problems += [] if checked else [f"{path.name}: its stored configuration differs from the new path's"]
                verify.checkpoints += 1
    return problems


def migrate(P, out: Path, write: bool) -> dict[str, int]:
    from drfkit.study import ablation, regime

    counts = {"migrated": 0, "already": 0, "stale": 0}

    def move(path: Path, row: dict, legacy: str, new: str) -> None:
        if row.get("key") == new:
            counts["already"] += 1
        elif row.get("key") == legacy:
            counts["migrated"] += 1
            if write:
                atomic_write_json(path, row | {"key": new, "key_before": legacy})
        else:
            counts["stale"] += 1

    for folder in sorted(p for p in out.iterdir() if p.is_dir() and p.name in ABLATION_BUDGETS):
        budget_name = folder.name
        for path in sorted(folder.glob("*-seed*.json")):
            row = json.loads(path.read_text())
            if row["variant"] not in VARIANTS:
                counts["stale"] += 1
                continue
            seed = int(row["seed"])
            move(path, row, legacy_key(row["variant"], seed, budget_name),
                 ablation.variant_run(P, row["variant"], seed, budget_name, out).key)
        levels, n_test, n_samples = P.pendulum.sweep_max_noise, P.dynamics.regime.test_sequences, P.uncertainty.n_samples
        settings = regime._settings(P, levels, n_test, n_samples)
        for path in sorted((folder / "regime").glob("*.json")):
            row = json.loads(path.read_text())
            model, train_noise, seed = row["model"], float(row["train_noise"]), int(row["seed"])
            particles = row.get("n_particles") if model == "physics_reference" else None
            try:
                legacy = legacy_regime_key(P, model, train_noise, seed, budget_name, settings, particles)
            except ValueError:  # a model the regime map no longer trains (a former name)
                counts["stale"] += 1
                continue
            if model == "physics_reference":
                new, _ = regime.reference_key(P, train_noise, seed, budget_name, out, levels, n_test, n_samples, particles)
            else:
                new, _ = regime.model_key(P, model, train_noise, seed, budget_name, out, levels, n_test, n_samples)
            move(path, row, legacy, new)
    return counts


def migrate_checkpoints(P, out: Path, write: bool) -> dict[str, int]:
    """Rename the ablation's local checkpoints (not committed) to their run's new stem and rewrite their
    fingerprint, so that a run trained before the move is found, resumed or extended instead of retrained. Only a
    run whose stem carries the legacy key and whose stored configuration the new path resolves is moved."""
    import re

    from drfkit.methods.run_config import fingerprint
    from drfkit.models import build_model
    from drfkit.study import ablation
    from drfkit.util.io import atomic_torch_save, torch_load_checked

    counts = {"moved": 0, "already": 0, "skipped": 0}
    for last_path in sorted(out.glob("*/models/*-last.pt")):
        budget_name = last_path.parent.parent.name
        match = re.fullmatch(r"(.+)-seed(\d+)-([0-9a-f]{8})-last\.pt", last_path.name)
        if budget_name not in ABLATION_BUDGETS or match is None or match.group(1) not in VARIANTS:
            counts["skipped"] += 1
            continue
        name, seed, key = match.group(1), int(match.group(2)), match.group(3)
        run = ablation.variant_run(P, name, seed, budget_name, out)
        if key == run.key:
            counts["already"] += 1
            continue
        best_path = Path(str(last_path).replace("-last.pt", "-best.pt"))
        last = torch_load_checked(last_path)
        best = torch_load_checked(best_path) if best_path.exists() else last.get("best")
        if key != legacy_key(name, seed, budget_name) or best is None or \
                build_model(best["config"]).config != run.config or TrainConfig(**best["meta"]["train"]) != run.train:
            counts["skipped"] += 1
            continue
        counts["moved"] += 1
        if not write:
            continue
        fp, data = fingerprint(run.config, run.train, param_hash(run.data_key)), param_hash(run.data_key)
        best = best | {"meta": best["meta"] | {"fingerprint": fp, "data": data}}
        last = last | {"fingerprint": fp, "best": None if last.get("best") is None else best}
        atomic_torch_save(Path(f"{run.stem}-best.pt"), best)
        atomic_torch_save(Path(f"{run.stem}-last.pt"), last)
        for old in (best_path, last_path):
            if old.exists() and old != Path(f"{run.stem}-{old.name.rsplit('-', 1)[1]}"):
                old.unlink()
    return counts


def main(argv: list[str] | None = None) -> int:
    from drfkit.study.params import for_notebook, load_profile
    from drfkit.util.paths import results_dir

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--profile", default="paper")
    ap.add_argument("--verify", action="store_true", help="check that the new path trains what the legacy one did")
    ap.add_argument("--write", action="store_true",
                    help="rewrite the rows' keys and move the local checkpoints (default: count only)")
    args = ap.parse_args(argv)
    P = for_notebook("02_pendulum_dynamics", load_profile(args.profile))
    out = results_dir(P.profile, "ablation")
    if args.verify:
        problems = verify(P, ["fit", "small"], out)
        print("\n".join(problems) or f"verified: {len(VARIANTS)} variants x 2 budgets resolve the legacy training "
              f"(and {verify.checkpoints} local checkpoints their stored configuration)")
        if problems:
            return 1
    print(migrate(P, out, args.write))
    print("local checkpoints:", migrate_checkpoints(P, out, args.write))
    return 0


if __name__ == "__main__":
    sys.exit(main())
