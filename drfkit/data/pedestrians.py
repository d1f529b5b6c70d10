"""A simulated nuScenes-like pedestrian data set, and the entry point for both sources.

Why a simulation: the paper uses nuScenes images and PifPaf keypoints, which need a
licence-gated download and a GPU keypoint detector. The simulation keeps what matters for
the study -- tracks of walking people seen at 2 Hz by a moving front camera, keypoints
whose quality drops with salt-and-pepper noise and with distance -- and produces records in
the same format as the real loader (``drfkit.data.nuscenes``), so everything downstream
runs on either.

The source is one parameter (``ped_source``): ``load_pedestrians`` returns the records of
``drfkit.data.records`` from the simulation or from the real nuScenes + PifPaf reader. The
simulation is two modules: ``drfkit.data.sim_world`` (the ground truth) and
``drfkit.data.sim_detector`` (the keypoint detector standing in for PifPaf);
``drfkit.data.drawing`` draws its frames.
"""
from __future__ import annotations

import os
from typing import Any, Mapping

import numpy as np

from drfkit.data.noise import Noise, check_noise
from drfkit.data.records import check_records
from drfkit.data.sim_detector import DetectorConfig, simulate_records
from drfkit.data.sim_world import simulate_truth

# Bump when the simulation or detector changes behaviour, so cached files are rebuilt.
SIMULATOR_VERSION = 1


def noise_dir_name(noise: Noise) -> str:
    """Folder name of one noise level's PifPaf predictions: 'p0.025' for salt-and-pepper 0.025."""
    return f"p{check_noise(noise, 'salt_and_pepper', 'noise_dir_name').level:g}"


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
    """Pedestrian records under salt-and-pepper ``noise`` from either source.

    source='simulated': ``simulate_truth(n_scenes, frames_per_scene, seed, **simulation)``
    observed by ``simulate_records(truth, noise, seed, detector)``, cached as
    ``<cache_dir>/pedestrians-sim-<hash>.npz`` with every parameter in the hash.
    source='nuscenes': ``drfkit.data.nuscenes.load_nuscenes_records`` reading the tables
    under ``nuscenes_root`` and PifPaf predictions from ``<predictions_root>/p<level>/``
    (``noise_dir_name``, e.g. ``p0.025``); the simulation arguments are ignored, and
    nothing is cached (the files on disk are the source of truth).
    Both return records that pass ``check_records``.
    """
    from drfkit.util.io import cached_npz

    check_noise(noise, "salt_and_pepper", "the pedestrian data")
    if source == "simulated":
        detector = DetectorConfig.from_dict(detector)
        simulation = dict(simulation or {})
        params = {
            "source": source, "noise": noise.key(), "n_scenes": n_scenes,
            "frames_per_scene": frames_per_scene, "seed": seed, "detector": detector.to_dict(),
            "simulation": simulation, "simulator_version": SIMULATOR_VERSION,
        }

        def build() -> dict[str, np.ndarray]:
            truth = simulate_truth(n_scenes, frames_per_scene, seed, **simulation)
            return simulate_records(truth, noise, seed, detector)

        rec = cached_npz(cache_dir, "pedestrians-sim", params, build)
    elif source == "nuscenes":
        from drfkit.data import nuscenes

        if nuscenes_root is None or predictions_root is None:
            raise ValueError(
                "source='nuscenes' needs nuscenes_root (folder holding '<version>/' tables and "
                "'samples/') and predictions_root (folder with one PifPaf output folder per noise "
                "level, named like 'p0.025')"
            )
        from pathlib import Path

        rec = nuscenes.load_nuscenes_records(
            nuscenes_root, Path(predictions_root) / noise_dir_name(noise), noise,
            version=nuscenes_version, cameras=tuple(cameras or nuscenes.DEFAULT_CAMERAS),
        )
    else:
        raise ValueError(f"source must be 'simulated' or 'nuscenes', got {source!r}")
    check_records(rec)
    return rec
