"""The pedestrian study's runs: per-detection records (simulated, or nuScenes + PifPaf) cut into
sequences, what names them, and each model's options and schedule under a training protocol
(``drfkit.methods.protocols.PEDESTRIAN_PROTOCOLS``). ``PEDESTRIANS`` is its registry entry.

Why a simulation: the paper uses nuScenes images and PifPaf keypoints, which need a licence-gated
download and a GPU keypoint detector. The simulation keeps what matters for the study -- tracks of
walking people seen at 2 Hz by a moving front camera, keypoints whose quality drops with
salt-and-pepper noise and with distance -- and produces records in the same format as the real
loader (``drfkit.data.nuscenes``), so everything downstream runs on either. The source is one
parameter (``ped_source``): ``load_pedestrians`` returns the records of ``drfkit.data.records`` from
the simulation (``drfkit.data.sim_world``, the ground truth, seen by ``drfkit.data.sim_detector``, the
keypoint detector standing in for PifPaf; ``drfkit.data.drawing`` draws its frames) or from the real
nuScenes + PifPaf reader.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import torch

from drfkit.data import nuscenes
from drfkit.data.noise import Noise, pedestrian_corruption
from drfkit.data.records import check_records, make_sequences, split_by_scene
from drfkit.data.sequence_data import SequenceData
from drfkit.data.sim_detector import DetectorConfig, simulate_records
from drfkit.data.sim_world import simulate_truth
from drfkit.methods.protocols import PEDESTRIAN_PROTOCOLS
from drfkit.methods.run_config import TrainConfig
from drfkit.study.entry import Study
from drfkit.util.io import param_hash
from drfkit.util.paths import data_dir

# Bump when the simulation or detector changes behaviour, so cached files are rebuilt.
SIMULATOR_VERSION = 1
# the profile's pedestrians fields that name the data in checkpoint hashes, by the flat names the hashes
# always had -> the field of P.pedestrians
DATA_FIELDS = {name: name.removeprefix("ped_") for name in (
    "ped_source", "nuscenes_root", "nuscenes_version", "pifpaf_predictions", "ped_n_scenes",
    "ped_frames_per_scene", "ped_train_p", "ped_seq_len", "ped_data_seed", "sim_detector")}


# One attempt at closing the DRF family's gap to the input-matched Monoloco in distribution (notebook 03): the
# family's keypoint encoder (53 -> 128 -> 64, 23 k weights in no_dynamics) at about Monoloco's width (412 k weights,
# 256 wide): hidden 512, features 256, decoder 256 (no_dynamics 191 k, the DRF 309 k). A diagnostic variant of the
# paper protocol's runs (``studies.train_models(..., options=WIDE_KEYPOINT_MODELS)``), not a protocol of the study.
WIDE_KEYPOINT_MODELS = {"encoder_hidden": 512, "feature_dim": 256, "decoder_hidden": 256}


def load_simulated_pedestrians(
    cache_dir: str | os.PathLike,
    noise: Noise,
    *,
    n_scenes: int = 165,
    frames_per_scene: int = 20,
    seed: int = 0,
    detector: DetectorConfig | Mapping[str, Any] | None = None,
    simulation: Mapping[str, Any] | None = None,
) -> dict[str, np.ndarray]:
    """Simulated pedestrian records under ``noise`` (a kind with a pedestrian corruption,
    ``drfkit.data.noise.PEDESTRIAN_CORRUPTIONS``: the paper's salt-and-pepper):
    ``simulate_truth(n_scenes, frames_per_scene, seed, **simulation)`` observed by
    ``simulate_records(truth, noise, seed, detector)``, cached as ``<cache_dir>/pedestrians-sim-<hash>.npz``
    with every parameter in the hash. The records pass ``check_records``."""
    from drfkit.util.io import cached_npz

    pedestrian_corruption(noise, "the pedestrian data")
    detector = DetectorConfig.from_dict(detector)
    simulation = dict(simulation or {})
    params = {
        "source": "simulated", "noise": noise.key(), "n_scenes": n_scenes,
        "frames_per_scene": frames_per_scene, "seed": seed, "detector": detector.to_dict(),
        "simulation": simulation, "simulator_version": SIMULATOR_VERSION,
    }

    def build() -> dict[str, np.ndarray]:
        truth = simulate_truth(n_scenes, frames_per_scene, seed, **simulation)
        return simulate_records(truth, noise, seed, detector)

    rec = cached_npz(cache_dir, "pedestrians-sim", params, build)
    check_records(rec)
    return rec


def load_pedestrians(
    cache_dir: str | os.PathLike,
    source: str,
    noise: Noise,
    *,
    n_scenes: int = 165,
    frames_per_scene: int = 20,
    seed: int = 0,
    detector: DetectorConfig | Mapping[str, Any] | None = None,
    nuscenes_root: str | os.PathLike | None = None,
    predictions_root: str | os.PathLike | None = None,
    nuscenes_version: str = "v1.0-mini",
    cameras: tuple[str, ...] | None = None,
    simulation: Mapping[str, Any] | None = None,
) -> dict[str, np.ndarray]:
    """Pedestrian records under ``noise`` (salt-and-pepper, or another kind with a pedestrian corruption)
    from either source (``ped_source``).

    source='simulated': ``load_simulated_pedestrians`` (cached under
    ``cache_dir``). source='nuscenes': ``drfkit.data.nuscenes.load_nuscenes_records`` reading the tables
    under ``nuscenes_root`` and PifPaf predictions from ``<predictions_root>/p<level>/``
    (``noise_dir_name``, e.g. ``p0.025``); the simulation arguments are ignored, and nothing is
    cached (the files on disk are the source of truth). Both return records that pass ``check_records``.
    """
    pedestrian_corruption(noise, "the pedestrian data")
    if source == "simulated":
        return load_simulated_pedestrians(cache_dir, noise, n_scenes=n_scenes, frames_per_scene=frames_per_scene,
                                          seed=seed, detector=detector, simulation=simulation)
    if source == "nuscenes":
        if nuscenes_root is None or predictions_root is None:
            raise ValueError(
                "source='nuscenes' needs nuscenes_root (folder holding '<version>/' tables and "
                "'samples/') and predictions_root (folder with one PifPaf output folder per noise "
                "level, named like 'p0.025')")
        return nuscenes.load_nuscenes_records(
            nuscenes_root, Path(predictions_root) / nuscenes.noise_dir_name(noise), noise,
            version=nuscenes_version, cameras=tuple(cameras or nuscenes.DEFAULT_CAMERAS))
    raise ValueError(f"source must be 'simulated' or 'nuscenes', got {source!r}")


def pedestrian_records(P, noise: Noise | float | None = None) -> dict[str, Any]:
    """Per-detection records under ``noise``, all splits: a ``Noise`` as given (any kind with a pedestrian
    corruption: the registry entry that calls decides), or a salt-and-pepper p (None: the training noise)."""
    noise = noise if isinstance(noise, Noise) else PEDESTRIANS.noise(noise, P)
    return load_pedestrians(
        data_dir(P.profile), P.pedestrians.source, noise, n_scenes=P.pedestrians.n_scenes,
        frames_per_scene=P.pedestrians.frames_per_scene, seed=P.pedestrians.data_seed,
        detector=DetectorConfig.from_dict(P.pedestrians.sim_detector),
        nuscenes_root=P.pedestrians.nuscenes_root or None, predictions_root=P.pedestrians.pifpaf_predictions or None,
        nuscenes_version=P.pedestrians.nuscenes_version)


def pedestrian_split(P, split: str, noise: Noise | float | None = None) -> dict[str, Any]:
    """Sequences of one split (split by scene, the same scenes at every noise level)."""
    splits = split_by_scene(pedestrian_records(P, noise), seed=P.pedestrians.data_seed)
    return make_sequences(splits[split], P.pedestrians.seq_len)


def pedestrian_data(P, split: str, noise: Noise | float | None = None, protocol: str = "paper") -> SequenceData:
    """A split as tensors: every protocol trains on the same sequences."""
    PEDESTRIANS.check_protocol(protocol)
    seqs = pedestrian_split(P, split, noise)
    return SequenceData(torch.from_numpy(seqs["inputs"]), torch.from_numpy(seqs["targets"]),
                        torch.from_numpy(seqs["mask"]))


def pedestrian_data_key(P, protocol: str = "paper", noise_kind: str = "salt_and_pepper") -> dict[str, Any]:
    PEDESTRIANS.check_protocol(protocol)
    # records under another kind of noise are other data; the paper's kind keeps the names it had
    other_kind = {"noise_kind": noise_kind} if noise_kind != "salt_and_pepper" else {}
    return {name: getattr(P.pedestrians, field) for name, field in DATA_FIELDS.items()} | other_kind


_TARGET_STATISTICS: dict[str, dict[str, float]] = {}  # per pedestrian data key: read the split once


def target_statistics(P) -> dict[str, float]:
    """Mean and standard deviation of the training depths (valid frames), rounded to cm so
    the configuration (and the checkpoint names hashed from it) is stable."""
    key = param_hash(pedestrian_data_key(P))
    if key not in _TARGET_STATISTICS:
        train = pedestrian_data(P, "train")
        depths = train.targets[train.mask] if train.mask is not None else train.targets
        _TARGET_STATISTICS[key] = {"target_offset": round(float(depths.mean()), 2),
                                   "target_scale": round(float(depths.std()), 2)}
    return dict(_TARGET_STATISTICS[key])


def pedestrian_model_options(P, kind: str, protocol: str = "paper") -> dict[str, Any]:
    """For the DRF family the decoder works in standardised depth units (``target_statistics`` of the
    training split, which needs ``P``); Monoloco keeps its published design (metres directly)."""
    PEDESTRIANS.check_protocol(protocol)
    return target_statistics(P) if kind != "monoloco" and P is not None else {}


def pedestrian_train_config(P, kind: str, seed: int, protocol: str = "paper") -> TrainConfig:
    """Monoloco: its published schedule under every protocol -- StepLR(20, 0.9), single frames, no
    gradient clipping, the epoch selected on validation L1 of mu (Bertoni et al. 2019, as in their
    code). The DRF family: Adam at the profile's lr, epochs and batch (batch and clipping at 10 are
    ours), with the protocol's recipe (``PEDESTRIAN_PROTOCOLS``)."""
    PEDESTRIANS.check_protocol(protocol)
    if kind == "monoloco":
        return TrainConfig(epochs=P.monoloco.epochs, lr=P.monoloco.lr, batch_size=P.monoloco.batch_size,
                           seed=seed, lr_step=20, lr_gamma=0.9, framewise=True, grad_clip=None, select_on="l1")
    return TrainConfig(epochs=P.pedestrians.epochs, lr=P.pedestrians.lr, batch_size=P.pedestrians.batch_size, seed=seed,
                       **PEDESTRIAN_PROTOCOLS[protocol])


PEDESTRIANS = Study(
    "pedestrians", "keypoints", 1, section="pedestrians",
    models_key="models", train_level_key="train_p", eval_levels_key="eval_p", sweep_key="sweep_p",
    training_notebook="03_nuscenes_training", noise_kind="salt_and_pepper", protocols_key="protocols",
    all_protocols=tuple(PEDESTRIAN_PROTOCOLS), data=pedestrian_data, data_key=pedestrian_data_key,
    model_options=pedestrian_model_options, train_config=pedestrian_train_config, gating_claim="C7b",
    noise_name="salt-and-pepper p", target_name="depth", target_unit="(m)")

__all__ = ["PEDESTRIANS", "SIMULATOR_VERSION", "load_pedestrians", "load_simulated_pedestrians", "pedestrian_data",
           "pedestrian_data_key", "pedestrian_model_options", "pedestrian_records", "pedestrian_split",
           "pedestrian_train_config", "target_statistics"]
