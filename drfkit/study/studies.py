"""The cached artefacts of each study, owned in one place.

A notebook asks for what it needs (``pendulum_split(P, "test", 0.75)``,
``train_models(P, "pendulum")``); if the artefact is on disk under its parameter hash it
is loaded, otherwise it is built. So every notebook runs on its own, in any order, and
shares work with the others when run in sequence. What a study's data and runs are is its
registry entry's business (``drfkit.study.registry``); this module names, trains and loads them.

Seeds: data sets are fixed by ``*_data_seed`` (train = seed, val = seed + 1, test =
seed + 2), the same for every model seed; each seed in ``P.seeds`` changes a model's
initialisation, batch order and dropout masks.
"""
from __future__ import annotations

import dataclasses

from typing import Any

import pandas as pd

from drfkit.study import registry
from drfkit.study.entry import no_fresh_training
from drfkit.data.noise import Noise
from drfkit.util.io import atomic_write_csv, param_hash
from drfkit.util.paths import models_dir, tables_dir
from drfkit.util.device import pick_device
from drfkit.methods.run_config import run_key
from drfkit.methods.train import SequenceData, TrainConfig, TrainResult, history_frame, naming_fields, train_or_load
# each study's data, as notebooks ask for it
from drfkit.study.pedestrian_runs import pedestrian_data, pedestrian_records, pedestrian_split, target_statistics
from drfkit.study.pendulum_runs import SPLIT_SEED_OFFSET, pendulum_data, pendulum_split, split_seed


# ---------------------------------------------------------------------------- training
def study_noise(P, study: str, noise: Noise | float | None = None) -> Noise:
    """The ``Noise`` of ``study`` at ``noise`` (a level of the study's kind, a ``Noise`` of that kind,
    or None for the profile's training noise)."""
    return registry.study(study).noise(noise, P)


def study_data(P, study: str, split: str, noise: Noise | float | None = None, protocol: str = "paper") -> SequenceData:
    """A split of any study (``drfkit.study.registry``) under ``noise`` (``study_noise``; default: the training noise)."""
    entry = registry.study(study)
    return entry.data(P, split, entry.noise(noise, P), protocol)


def study_data_key(P, study: str, protocol: str = "paper") -> dict[str, Any]:
    """What names a study's training and validation data in checkpoint hashes."""
    entry = registry.study(study)
    return entry.data_key(P, protocol, entry.noise_kind)


def study_models(P, study: str, protocol: str = "paper") -> list[str]:
    return registry.study(study).models(P, protocol)


def model_config(study: str, kind: str, P=None, protocol: str = "paper", options: dict[str, Any] | None = None
                 ) -> dict[str, Any]:
    """The full configuration of ``kind`` in ``study`` under ``protocol``: the model's defaults with the
    options the study's entry gives it (``Study.model_options``), then ``options`` (a diagnostic
    variant of the model, e.g. Monoloco fed the DRF family's inputs)."""
    from drfkit.models import default_config

    spec = registry.study(study)
    return default_config(kind, spec.input_kind, spec.out_dim,
                          **(spec.model_options(P, kind, protocol) | dict(options or {})))


def train_config(P, study: str, kind: str, seed: int, protocol: str = "paper") -> TrainConfig:
    """Every run's schedule, from the study's entry (``Study.train_config``)."""
    return registry.study(study).train_config(P, kind, seed, protocol)


def fresh_training(P, study: str, protocol: str):
    """None, or ``fresh(epoch) -> SequenceData`` when ``protocol`` redraws the training data every epoch."""
    entry = registry.study(study)
    if entry.fresh_training is no_fresh_training:  # a study that never redraws needs no training noise
        return None
    return entry.fresh_training(P, protocol, entry.noise(None, P))


def checkpoint_stem(P, study: str, kind: str, seed: int, protocol: str = "paper",
                    options: dict[str, Any] | None = None, training_seed: int | None = None):
    """The checkpoint files' stem of the run in ``seed``'s slot (``training_seed``: of the run that slot would hold
    if it trained from that seed, e.g. the run a restart replaced)."""
    cfg = model_config(study, kind, P, protocol, options)
    train = train_config(P, study, kind, seed, protocol)
    if training_seed is not None:
        train = dataclasses.replace(train, seed=int(training_seed))
    return models_dir(P.profile) / f"{study}-{kind}-seed{seed}-{run_key(cfg, train, study_data_key(P, study, protocol))}"


def shared_run(P, study: str, kind: str, seed: int, protocol: str, other: str) -> bool:
    """Whether ``kind`` trains one and the same run under ``protocol`` and ``other`` (one checkpoint:
    Monoloco keeps its published schedule under every pedestrian protocol). The cheap parts first, so
    that the DRF family's data is not read to tell two different schedules apart."""
    if naming_fields(train_config(P, study, kind, seed, protocol)) != naming_fields(train_config(P, study, kind, seed, other)):
        return False
    if study_data_key(P, study, protocol) != study_data_key(P, study, other):
        return False
    return checkpoint_stem(P, study, kind, seed, protocol) == checkpoint_stem(P, study, kind, seed, other)


def curves_name(study: str, protocol: str = "paper") -> str:
    """File stem of a study's training curves (the paper protocol's keeps its old name)."""
    return f"{study}_training_curves" if protocol == "paper" else f"{study}_{protocol}_training_curves"


def train_models(P, study: str, progress: bool = True, kinds: list[str] | None = None,
                 seeds: list[int] | None = None, protocol: str = "paper", options: dict[str, Any] | None = None,
                 write_curves: bool = True) -> dict[tuple[str, int], TrainResult]:
    """Train (or load from cache / resume) every model of ``study`` for every seed.

    Writes ``tables/<curves_name>.csv`` with one row per model, seed and epoch
    (only when the whole set is trained and ``write_curves``: one writer per table, the notebook that
    trains the runs and ``python -m drfkit train``; ``kinds`` / ``seeds`` pick a subset, as the
    command line does to spread training over processes or sessions). ``options``: model
    options over the protocol's (``model_config``), for a diagnostic variant of ``kinds``.
    """
    device = pick_device(P.device)
    key = study_data_key(P, study, protocol)
    data_key = param_hash(key)
    recipe = {"study": study, "protocol": protocol, **key}
    data: list = []

    def splits():  # generated once, only when a run must train: a finished run loads from its files alone
        if not data:
            data.extend([study_data(P, study, "train", None, protocol), study_data(P, study, "val", None, protocol),
                         fresh_training(P, study, protocol)])
        return tuple(data)

    results, curves = {}, []
    for kind in kinds or study_models(P, study, protocol):
        for seed in seeds or P.seeds:
            config, cfg = model_config(study, kind, P, protocol, options), train_config(P, study, kind, seed, protocol)
            stem = checkpoint_stem(P, study, kind, seed, protocol, options)
            res = train_or_load(config, cfg, stem, splits, data_key=data_key, device=device, progress=progress,
                                recipe=recipe)
            results[(kind, seed)] = res
            curve = history_frame(res.history)
            curve.insert(0, "seed", seed)
            curve.insert(0, "model", kind)
            curves.append(curve)
    if write_curves and kinds is None and seeds is None and not options:
        atomic_write_csv(tables_dir(P.profile) / f"{curves_name(study, protocol)}.csv",
                         pd.concat(curves, ignore_index=True))
    return results


def trained_models(P, study: str, progress: bool = False, protocol: str = "paper",
                   write_curves: bool = False) -> dict[tuple[str, int], Any]:
    """The best checkpoint of every (model, seed), loaded in eval mode (trains what is missing); the
    training curves table only with ``write_curves`` (the notebook that trains these runs)."""
    from drfkit.methods.train import load_checkpoint

    device = pick_device(P.device)
    return {key: load_checkpoint(res.best_path, device)
            for key, res in train_models(P, study, progress, protocol=protocol, write_curves=write_curves).items()}


# ------------------------------------------------------------------------ command line
STUDIES = registry.STUDIES
TRAINING_NOTEBOOK = {name: s.training_notebook for name, s in STUDIES.items()}
