"""The pendulum study's runs: its data, what names the data, and each model's options and schedule
under a training protocol (``drfkit.methods.protocols``). ``PENDULUM`` is its registry entry."""
from __future__ import annotations

from typing import Any

import torch

from drfkit.data.noise import Noise
from drfkit.data.pendulum import (GENERATOR_VERSION, TRAINING_BLACKOUT_SEED_OFFSET, fresh_noise_seed, load_pendulum,
                                  redraw_noise, with_random_blackouts)
from drfkit.data.sequence_data import SequenceData
from drfkit.methods.protocols import PROTOCOLS, protocol_spec
from drfkit.methods.run_config import TrainConfig
from drfkit.study.entry import Study
from drfkit.util.paths import data_dir

# data sets are fixed by ``*_data_seed`` (train = seed, val = seed + 1; the pendulum's test split by its own
# ``test_seed``, the pedestrians' test = seed + 2), the same for
# every model seed; each seed in ``P.seeds`` changes a model's initialisation, batch order and dropout
SPLIT_SEED_OFFSET = {"train": 0, "val": 1, "test": 2}
# what the profile owns of a schedule; a variant's ``train`` recipe (``drfkit.methods.protocols``) sets the rest
PROFILE_SCHEDULE = ("epochs", "lr", "batch_size", "patience")


def _noise(P, noise: Noise | float | None) -> Noise:
    """A ``Noise`` as given (any kind with a corruption of pendulum frames: the registry entry that
    calls decides), or a level of the benchmark's noise (None: the training level)."""
    return noise if isinstance(noise, Noise) else PENDULUM.noise(noise, P)


def split_seed(P, split: str) -> int:
    """The seed of a pendulum split: ``data_seed`` + 0 / 1 for train / val; the test split has its own
    ``test_seed``, so that a fresh one gives a test set no training or selection step has read."""
    if split == "test":
        seed = int(P.pendulum.test_seed)
        if seed in (P.pendulum.data_seed, P.pendulum.data_seed + 1):
            raise ValueError(f"pend_test_seed {seed} is the training or validation split's seed (data_seed "
                             f"{P.pendulum.data_seed} and + 1): the test set would repeat them; pick another")
        return seed
    return P.pendulum.data_seed + SPLIT_SEED_OFFSET[split]


def pendulum_split(P, split: str, noise: Noise | float | None = None) -> dict[str, Any]:
    """Arrays of a pendulum split; ``noise`` a ``Noise`` or its max noise level (default: the training noise)."""
    n = {"train": P.pendulum.train_sequences, "val": P.pendulum.val_sequences, "test": P.pendulum.test_sequences}[split]
    return load_pendulum(data_dir(P.profile), split, n, P.pendulum.seq_len, _noise(P, noise), split_seed(P, split))


def pendulum_data(P, split: str, noise: Noise | float | None = None, protocol: str = "paper") -> SequenceData:
    """A split as tensors; a protocol with training blackouts (``drfkit.methods.protocols``) adds them to
    the training split only (validation and test stay as the benchmark makes them)."""
    arrays = pendulum_split(P, split, noise)
    blackouts = protocol_spec(protocol, "drf")["blackouts"]
    if split == "train" and blackouts:
        arrays = with_random_blackouts(arrays, blackouts["fraction"], tuple(blackouts["lengths"]),
                                       seed=P.pendulum.data_seed + TRAINING_BLACKOUT_SEED_OFFSET)
    return _as_data(arrays)


def _as_data(arrays: dict[str, Any]) -> SequenceData:
    return SequenceData(torch.from_numpy(arrays["images"]), torch.from_numpy(arrays["targets"]))


def pendulum_data_key(P, protocol: str = "paper", noise_kind: str = "rkn_uniform") -> dict[str, Any]:
    # named by the parameters' flat names, as checkpoint hashes always were
    S = P.pendulum
    key = {"pend_train_sequences": S.train_sequences, "pend_val_sequences": S.val_sequences,
           "pend_seq_len": S.seq_len, "pend_train_max_noise": S.train_max_noise, "pend_data_seed": S.data_seed}
    # frames under another kind of noise are other data; the benchmark's kind keeps the names it had
    key |= {"noise_kind": noise_kind} if noise_kind != "rkn_uniform" else {}
    spec = protocol_spec(protocol, "drf")
    # a run trained on other frames is another run: since generator 2 (the benchmark's own frames) the
    # generator enters the key; runs on the first generator's frames keep the names they had
    frames = {"frames": GENERATOR_VERSION} if GENERATOR_VERSION != 1 else {}
    fresh = {"fresh_noise": True} if spec["train"].get("fresh_noise") else {}
    blackouts = {"train_blackouts": spec["blackouts"]} if spec["blackouts"] else {}
    return key | blackouts | frames | fresh


def _paper_default(protocol: str, kind: str) -> bool:
    """A kind that the paper's protocol does not list (a model added to the registry, not to
    ``drfkit.methods.protocols``) trains there with its defaults; other protocols name every kind."""
    return protocol == "paper" and protocol in PROTOCOLS and kind not in PROTOCOLS[protocol]


def pendulum_model_options(P, kind: str, protocol: str = "paper") -> dict[str, Any]:
    """The options of ``kind``'s variant under ``protocol``."""
    return {} if _paper_default(protocol, kind) else dict(protocol_spec(protocol, kind)["model"])


def recipe_fields(spec: dict[str, Any]) -> dict[str, Any]:
    """The ``TrainConfig`` fields of a variant's training recipe (objective, beta, schedule, windows,
    selection, prior weight) at paper scale: the profile's schedule keys and the data's business
    (``fresh_noise``) left out."""
    return {k: v for k, v in spec["train"].items() if k not in PROFILE_SCHEDULE and k not in ("fresh_noise", "fresh_motion")}


def pendulum_train_config(P, kind: str, seed: int, protocol: str = "paper") -> TrainConfig:
    """The paper's protocol: Adam at the profile's lr, epochs and batch (the paper gives lr 1e-4 and
    200 epochs; batch 50 and clipping the gradient norm at 10, a guard against the odd exploding step
    through the recursion, are ours). Any other protocol: its own profile section's schedule
    (``pend_<protocol>_*``) with the variant's recipe."""
    if protocol == "paper":
        return TrainConfig(epochs=P.pendulum.epochs, lr=P.pendulum.lr, batch_size=P.pendulum.batch_size, seed=seed,
                           patience=P.pendulum.patience)
    recipe = recipe_fields(protocol_spec(protocol, kind))
    schedule = {k: getattr(getattr(P.pendulum, protocol), k) for k in PROFILE_SCHEDULE}
    if recipe.get("mse_warmup") == "half":
        recipe["mse_warmup"] = schedule["epochs"] // 2
    return TrainConfig(seed=training_seed(P, kind, seed, protocol), **schedule, **recipe)


def training_seed(P, kind: str, seed: int, protocol: str) -> int:
    """The seed the run in ``seed``'s slot trains from: ``seed`` itself, unless the protocol's ``restarts`` replace
    it (the validation-only restart rule: a seed whose run failed the rule is retrained from the next unused seed,
    and the tables keep the slot's number so that every model has the profile's seeds)."""
    if protocol == "paper":  # the paper's protocol is the benchmark's: no restarts
        return int(seed)
    restarts = getattr(P.pendulum, protocol).restarts
    return int(restarts.get(kind, {}).get(seed, seed))


def pendulum_fresh_training(P, protocol: str, noise: Noise | float | None = None):
    """``fresh_train(epoch)`` for ``drfkit.methods.train.train_model`` when the protocol redraws the training
    noise every epoch (None otherwise): the training split's clean frames under new noise (and new
    blackouts), seeded by ``drfkit.data.pendulum.fresh_noise_seed`` alone, so a resumed run sees what
    an uninterrupted one saw."""
    spec = protocol_spec(protocol, "drf")
    if not spec["train"].get("fresh_noise"):
        return None
    clean, level = pendulum_split(P, "train", noise), _noise(P, noise)

    def fresh(epoch: int) -> SequenceData:
        return _as_data(redraw_noise(clean, level, fresh_noise_seed(P.pendulum.data_seed, epoch), spec["blackouts"]))

    return fresh


PENDULUM = Study(
    "pendulum", "pendulum", 2, section="pendulum",
    models_key="models", train_level_key="train_max_noise", eval_levels_key="eval_max_noise",
    sweep_key="sweep_max_noise", training_notebook="01_pendulum_training", noise_kind="rkn_uniform",
    protocols_key="protocols",
    all_protocols=tuple(PROTOCOLS), data=pendulum_data, data_key=pendulum_data_key,
    model_options=pendulum_model_options, train_config=pendulum_train_config,
    fresh_training=pendulum_fresh_training, gating_claim="C7a", noise_name="max noise",
    target_unit="(cos θ, sin θ)")

__all__ = ["PENDULUM", "PROFILE_SCHEDULE", "SPLIT_SEED_OFFSET", "split_seed", "pendulum_data", "pendulum_data_key",
           "pendulum_fresh_training", "pendulum_model_options", "pendulum_split", "pendulum_train_config", "training_seed",
           "recipe_fields"]
