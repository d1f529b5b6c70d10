"""The cached artefacts of each study, owned in one place.

A notebook asks for what it needs (``pendulum_split(P, "test", 0.75)``,
``train_models(P, "pendulum")``); if the artefact is on disk under its parameter hash it
is loaded, otherwise it is built. So every notebook runs on its own, in any order, and
shares work with the others when run in sequence.

Seeds: data sets are fixed by ``*_data_seed`` (train = seed, val = seed + 1, test =
seed + 2), the same for every model seed; each seed in ``P.seeds`` changes a model's
initialisation, batch order and dropout masks.
"""
from __future__ import annotations

from typing import Any

import pandas as pd
import torch

from drfkit.study import registry
from drfkit.data.noise import Noise
from drfkit.data.pendulum import TRAINING_BLACKOUT_SEED_OFFSET
from drfkit.util.io import atomic_write_csv, param_hash
from drfkit.util.paths import data_dir, models_dir, tables_dir
from drfkit.methods.protocols import PROTOCOLS, protocol_spec
from drfkit.util.device import pick_device
from drfkit.methods.train import SequenceData, TrainConfig, TrainResult, history_frame, naming_fields, train_model

SPLIT_SEED_OFFSET = {"train": 0, "val": 1, "test": 2}


# --------------------------------------------------------------------------- pendulum
def pendulum_split(P, split: str, noise: Noise | float | None = None) -> dict[str, Any]:
    """Arrays of a pendulum split; ``noise`` a ``Noise`` or its max noise level (default: the training noise)."""
    from drfkit.data.pendulum import load_pendulum

    n = {"train": P.pend_train_sequences, "val": P.pend_val_sequences, "test": P.pend_test_sequences}[split]
    return load_pendulum(data_dir(P.profile), split, n, P.pend_seq_len, study_noise(P, "pendulum", noise),
                         P.pend_data_seed + SPLIT_SEED_OFFSET[split])


def pendulum_data(P, split: str, noise: Noise | float | None = None, protocol: str = "paper") -> SequenceData:
    """A split as tensors; a protocol with training blackouts (``drfkit.methods.protocols``) adds them to
    the training split only (validation and test stay as the benchmark makes them)."""
    from drfkit.data.pendulum import with_random_blackouts

    arrays = pendulum_split(P, split, noise)
    blackouts = protocol_spec(protocol, "drf")["blackouts"]
    if split == "train" and blackouts:
        arrays = with_random_blackouts(arrays, blackouts["fraction"], tuple(blackouts["lengths"]),
                                       seed=P.pend_data_seed + TRAINING_BLACKOUT_SEED_OFFSET)
    return SequenceData(torch.from_numpy(arrays["images"]), torch.from_numpy(arrays["targets"]))




def _pendulum_data_key(P, protocol: str = "paper") -> dict[str, Any]:
    from drfkit.data.pendulum import GENERATOR_VERSION

    key = {k: getattr(P, k) for k in ("pend_train_sequences", "pend_val_sequences", "pend_seq_len",
                                        "pend_train_max_noise", "pend_data_seed")}
    blackouts = protocol_spec(protocol, "drf")["blackouts"]
    # a run trained on other frames is another run: since generator 2 (the benchmark's own frames) the
    # generator enters the key; runs on the first generator's frames keep the names they had
    frames = {"frames": GENERATOR_VERSION} if GENERATOR_VERSION != 1 else {}
    fresh = {"fresh_noise": True} if protocol_spec(protocol, "drf")["train"].get("fresh_noise") else {}
    return key | ({"train_blackouts": blackouts} if blackouts else {}) | frames | fresh


# ------------------------------------------------------------------------- pedestrians
def pedestrian_records(P, noise: Noise | float | None = None) -> dict[str, Any]:
    """Per-detection records under ``noise`` (a ``Noise`` or its salt-and-pepper p; default the training
    noise), all splits."""
    from drfkit.data.pedestrians import load_pedestrians
    from drfkit.data.sim_detector import DetectorConfig

    return load_pedestrians(
        data_dir(P.profile), P.ped_source, study_noise(P, "pedestrians", noise), n_scenes=P.ped_n_scenes,
        frames_per_scene=P.ped_frames_per_scene, seed=P.ped_data_seed,
        detector=DetectorConfig.from_dict(P.sim_detector),
        nuscenes_root=P.nuscenes_root or None, predictions_root=P.pifpaf_predictions or None,
        nuscenes_version=P.nuscenes_version)


def pedestrian_split(P, split: str, noise: Noise | float | None = None) -> dict[str, Any]:
    """Sequences of one split (split by scene, the same scenes at every noise level)."""
    from drfkit.data.records import make_sequences, split_by_scene

    splits = split_by_scene(pedestrian_records(P, noise), seed=P.ped_data_seed)
    return make_sequences(splits[split], P.ped_seq_len)


def pedestrian_data(P, split: str, noise: Noise | float | None = None, protocol: str = "paper") -> SequenceData:
    _pedestrian_protocol(protocol)
    seqs = pedestrian_split(P, split, noise)
    return SequenceData(torch.from_numpy(seqs["inputs"]), torch.from_numpy(seqs["targets"]),
                        torch.from_numpy(seqs["mask"]))


def _pedestrian_protocol(protocol: str) -> None:
    if protocol != "paper":
        raise ValueError(f"the pedestrian study has only the paper's protocol so far, got {protocol!r}")


def _pedestrian_data_key(P, protocol: str = "paper") -> dict[str, Any]:
    _pedestrian_protocol(protocol)
    return {k: getattr(P, k) for k in ("ped_source", "nuscenes_root", "nuscenes_version", "pifpaf_predictions",
                                         "ped_n_scenes", "ped_frames_per_scene", "ped_train_p", "ped_seq_len",
                                         "ped_data_seed", "sim_detector")}


# ---------------------------------------------------------------------------- training
def study_noise(P, study: str, noise: Noise | float | None = None) -> Noise:
    """The ``Noise`` of ``study`` at ``noise`` (a level of the study's kind, a ``Noise`` of that kind,
    or None for the profile's training noise)."""
    return registry.study(study).noise(noise, P)


def study_data(P, study: str, split: str, noise: Noise | float | None = None, protocol: str = "paper") -> SequenceData:
    """A split of any study (``drfkit.study.registry``) under ``noise`` (``study_noise``; default: the training noise)."""
    return globals()[registry.study(study).data](P, split, noise, protocol)


def study_data_key(P, study: str, protocol: str = "paper") -> dict[str, Any]:
    """What names a study's training and validation data in checkpoint hashes."""
    return globals()[registry.study(study).data_key](P, protocol)


def study_models(P, study: str) -> list[str]:
    return registry.study(study).models(P)


_TARGET_STATISTICS: dict[str, dict[str, float]] = {}  # per pedestrian data key: read the split once


def target_statistics(P) -> dict[str, float]:
    """Mean and standard deviation of the training depths (valid frames), rounded to cm so
    the configuration (and the checkpoint names hashed from it) is stable."""
    key = param_hash(_pedestrian_data_key(P))
    if key not in _TARGET_STATISTICS:
        train = pedestrian_data(P, "train")
        depths = train.targets[train.mask] if train.mask is not None else train.targets
        _TARGET_STATISTICS[key] = {"target_offset": round(float(depths.mean()), 2),
                                   "target_scale": round(float(depths.std()), 2)}
    return dict(_TARGET_STATISTICS[key])


def model_config(study: str, kind: str, P=None, protocol: str = "paper") -> dict[str, Any]:
    """The full configuration of ``kind`` in ``study`` under ``protocol`` (``drfkit.methods.protocols``:
    its model options). For the DRF family on pedestrians the decoder works in standardised
    depth units (``target_statistics`` of the training split, which needs ``P``); Monoloco keeps
    its published design (metres directly)."""
    from drfkit.models import default_config

    spec = registry.study(study)
    overrides = {}
    if study == "pedestrians":
        _pedestrian_protocol(protocol)
        if kind != "monoloco" and P is not None:
            overrides = target_statistics(P)
    else:
        overrides = dict(protocol_spec(protocol, kind)["model"])
    return default_config(kind, spec.input_kind, spec.out_dim, **overrides)


def train_config(P, study: str, kind: str, seed: int, protocol: str = "paper") -> TrainConfig:
    """Every run's schedule, in one place. The DRF family: Adam at the profile's lr, epochs and
    batch; the paper gives lr 1e-4 and 200 epochs; batch 50 and clipping the gradient norm at 10
    (a guard against the odd exploding step through the recursion) are ours. Monoloco: its
    published schedule -- StepLR(20, 0.9), single frames, no gradient clipping, and the epoch
    selected on validation L1 of mu."""
    if study == "pendulum" and protocol == "book":  # the book's schedule: its own profile keys
        recipe = recipe_fields(protocol_spec(protocol, kind))
        if recipe.get("mse_warmup") == "half":
            recipe["mse_warmup"] = P.pend_book_epochs // 2
        return TrainConfig(epochs=P.pend_book_epochs, lr=P.pend_book_lr, batch_size=P.pend_book_batch_size,
                           seed=seed, patience=P.pend_book_patience, **recipe)
    if study == "pendulum":
        return TrainConfig(epochs=P.pend_epochs, lr=P.pend_lr, batch_size=P.pend_batch_size, seed=seed,
                           patience=P.pend_patience)
    _pedestrian_protocol(protocol)
    if kind == "monoloco":  # Bertoni et al. 2019, as in their code
        return TrainConfig(epochs=P.monoloco_epochs, lr=P.monoloco_lr, batch_size=P.monoloco_batch_size,
                           seed=seed, lr_step=20, lr_gamma=0.9, framewise=True, grad_clip=None, select_on="l1")
    return TrainConfig(epochs=P.ped_epochs, lr=P.ped_lr, batch_size=P.ped_batch_size, seed=seed)


# what the profile owns of a schedule; a variant's ``train`` recipe (``drfkit.methods.protocols``) sets the rest
PROFILE_SCHEDULE = ("epochs", "lr", "batch_size", "patience")


def recipe_fields(spec: dict[str, Any]) -> dict[str, Any]:
    """The ``TrainConfig`` fields of a variant's training recipe (objective, beta, schedule, windows,
    selection, prior weight) at paper scale: the profile's schedule keys and the data's business
    (``fresh_noise``) left out."""
    return {k: v for k, v in spec["train"].items() if k not in PROFILE_SCHEDULE and k != "fresh_noise"}


def fresh_training(P, protocol: str, noise: Noise | float | None = None):
    """``fresh_train(epoch)`` for ``drfkit.methods.train.train_model`` when the protocol redraws the training
    noise every epoch (None otherwise): the training split's clean frames under new noise (and new
    blackouts), drawn from ``pend_data_seed * 1000 + epoch`` alone, so a resumed run sees what an
    uninterrupted one saw."""
    from drfkit.data.pendulum import redraw_noise

    spec = protocol_spec(protocol, "drf")
    if not spec["train"].get("fresh_noise"):
        return None
    clean, level = pendulum_split(P, "train", noise), study_noise(P, "pendulum", noise)

    def fresh(epoch: int) -> SequenceData:
        arrays = redraw_noise(clean, level, P.pend_data_seed * 1000 + epoch, spec["blackouts"])
        return SequenceData(torch.from_numpy(arrays["images"]), torch.from_numpy(arrays["targets"]))

    return fresh


def checkpoint_stem(P, study: str, kind: str, seed: int, protocol: str = "paper"):
    cfg = model_config(study, kind, P, protocol)
    key = param_hash({"model": cfg, "train": naming_fields(train_config(P, study, kind, seed, protocol)),
                      "data": study_data_key(P, study, protocol)}, 8)
    return models_dir(P.profile) / f"{study}-{kind}-seed{seed}-{key}"


def curves_name(study: str, protocol: str = "paper") -> str:
    """File stem of a study's training curves (the paper protocol's keeps its old name)."""
    return f"{study}_training_curves" if protocol == "paper" else f"{study}_{protocol}_training_curves"


def train_models(P, study: str, progress: bool = True, kinds: list[str] | None = None,
                 seeds: list[int] | None = None, protocol: str = "paper") -> dict[tuple[str, int], TrainResult]:
    """Train (or load from cache / resume) every model of ``study`` for every seed.

    Writes ``tables/<curves_name>.csv`` with one row per model, seed and epoch
    (only when the whole set is trained; ``kinds`` / ``seeds`` pick a subset, as the
    command line below does to spread training over processes or sessions).
    """
    device = pick_device(P.device)
    train, val = study_data(P, study, "train", None, protocol), study_data(P, study, "val", None, protocol)
    data_key = param_hash(study_data_key(P, study, protocol))
    fresh = fresh_training(P, protocol) if study == "pendulum" else None
    results, curves = {}, []
    for kind in kinds or study_models(P, study):
        for seed in seeds or P.seeds:
            res = train_model(model_config(study, kind, P, protocol), train, val,
                              train_config(P, study, kind, seed, protocol),
                              checkpoint_stem(P, study, kind, seed, protocol), data_key=data_key, device=device,
                              progress=progress, fresh_train=fresh)
            results[(kind, seed)] = res
            curve = history_frame(res.history)
            curve.insert(0, "seed", seed)
            curve.insert(0, "model", kind)
            curves.append(curve)
    if kinds is None and seeds is None:
        atomic_write_csv(tables_dir(P.profile) / f"{curves_name(study, protocol)}.csv",
                         pd.concat(curves, ignore_index=True))
    return results


def trained_models(P, study: str, progress: bool = False, protocol: str = "paper") -> dict[tuple[str, int], Any]:
    """The best checkpoint of every (model, seed), loaded in eval mode (trains what is missing)."""
    from drfkit.methods.train import load_checkpoint

    device = pick_device(P.device)
    return {key: load_checkpoint(res.best_path, device)
            for key, res in train_models(P, study, progress, protocol=protocol).items()}


# ------------------------------------------------------------------------ command line
STUDIES = registry.STUDIES
TRAINING_NOTEBOOK = {name: s.training_notebook for name, s in STUDIES.items()}
