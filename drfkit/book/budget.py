"""How long a profile's training takes on this machine, before running it.

``python -m drfkit budget --profile paper`` measures one training step (forward, loss,
backward) of every model at the profile's batch size and sequence length, on the profile's
real training split, with ``torch.utils.benchmark``; multiplies by batches per epoch,
epochs and seeds; and writes ``results/<profile>/training_budget.csv``. It is an estimate
(no optimiser step, no validation pass, no data loading), measured, not guessed. The
``epochs_done`` and ``hours_left`` columns count the epochs already in the profile's
``models/*-last.pt`` checkpoints, so the table also says how much of a resumable run is left.
"""
from __future__ import annotations

import numpy as np
import pandas as pd
import torch

from drfkit.study import registry, studies
from drfkit.util.io import torch_load_checked
from drfkit.methods.timing.training import training_step_times
from drfkit.methods.train import run_finished


def epochs_done(P, study: str, kind: str) -> tuple[int, int]:
    """(epochs trained, epochs still to train) for ``kind`` over the profile's seeds, read
    from the ``-last.pt`` checkpoints; a run stopped by its patience has none left."""
    done = left = 0
    for seed in P.seeds:
        cfg = studies.train_config(P, study, kind, seed)
        stem = studies.checkpoint_stem(P, study, kind, seed)
        last = stem.with_name(f"{stem.name}-last.pt")
        state = torch_load_checked(last) if last.exists() else {"epoch": 0, "best_epoch": 0}
        epoch = int(state["epoch"])
        done += epoch
        left += 0 if epoch and run_finished(epoch, int(state["best_epoch"]), cfg) else max(cfg.epochs - epoch, 0)
    return done, left


RATIO_BASE = "no_dynamics"  # the denominator of step_ratio (the speed target: a DRF epoch <= 1.5x a no_dynamics one)


def training_budget(P, min_run_time: float = 1.0) -> pd.DataFrame:
    """One row per (study, model): step time, batches per epoch, epochs, seeds, hours.

    Models that train on the same batches (same single-frame flag and batch size) are timed
    together in interleaved rounds (``timing.training_step_times``), so ``step_ratio``, a
    model's step over ``ratio_to``'s (no_dynamics where it is in the group) as the median of
    per-round ratios, is measured in one run and robust to a slow spell of the machine.
    ``flop_ratio`` is the same ratio for the step's counted arithmetic (``timing.count_flops``):
    what ``step_ratio`` would be if both models ran their products at the same rate.
    """
    rows = []
    for study in registry.STUDIES:  # every registered study, in the registry's order
        train = studies.study_data(P, study, "train")
        configs = {kind: studies.train_config(P, study, kind, P.seeds[0]) for kind in studies.study_models(P, study)}
        groups: dict[tuple[bool, int], list[str]] = {}
        for kind, cfg in configs.items():
            groups.setdefault((cfg.framewise, cfg.batch_size), []).append(kind)
        for (framewise, batch_size), kinds in groups.items():
            kinds = sorted(kinds, key=lambda k: k != RATIO_BASE)  # the base first: it is the denominator
            data = train.frames() if framewise else train
            batch = min(batch_size, len(data))
            step = training_step_times({k: studies.model_config(study, k, P) for k in kinds}, data.inputs[:batch],
                                       data.targets[:batch], n_batches_per_epoch=1, min_run_time=min_run_time,
                                       with_flops=True)
            ratio = f"ratio_to_{kinds[0]}"
            for kind, s in zip(kinds, step.itertuples()):
                cfg = configs[kind]
                step_s = float(s.step_median_s)
                batches = int(np.ceil(len(data) / cfg.batch_size))
                hours = step_s * batches * cfg.epochs * len(P.seeds) / 3600
                done, left = epochs_done(P, study, kind)
                rows.append({"study": study, "model": kind, "batch": batch,
                             "frames_per_item": int(data.inputs.shape[1]), "step_s": step_s,
                             "step_ratio": float(getattr(s, ratio)), "ratio_to": kinds[0], "rounds": int(s.rounds),
                             "flop_ratio": float(getattr(s, f"flop_{ratio}")),
                             "batches_per_epoch": batches, "epoch_s": step_s * batches, "epochs": cfg.epochs,
                             "seeds": len(P.seeds), "hours": hours, "epochs_done": done,
                             "hours_left": hours * left / (cfg.epochs * len(P.seeds)),
                             "threads": torch.get_num_threads()})
    return pd.DataFrame(rows)
