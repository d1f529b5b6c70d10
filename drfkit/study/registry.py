"""The studies of the book, one entry each: every module that needs a study's facts looks here.

A study is what the models are trained and judged on: its input kind and output size, the models
it can train, the kind of its noise (``drfkit.data.noise.Noise``), and the profile keys that hold
its models, noise levels and protocols. Its data
functions live in ``drfkit.study.studies`` under the names given here (``data``: (P, split, noise,
protocol) -> SequenceData; ``data_key``: (P, protocol) -> the dict that names its data in
checkpoint hashes). Adding a study is one entry here, its two data functions, and its keys in
``drfkit.study.params``.

This module imports only ``drfkit.data.noise`` (which imports nothing from drfkit), so anything
may import it.
"""
from __future__ import annotations

from dataclasses import dataclass

from drfkit.data.noise import Noise, check_noise


@dataclass(frozen=True)
class Study:
    name: str
    input_kind: str                # the models' input: 'pendulum' images or 'keypoints'
    out_dim: int                   # outputs per frame
    kinds: tuple[str, ...]         # every model kind the study can train (a profile picks a subset)
    models_key: str                # profile key: the models a profile trains
    train_level_key: str           # profile key: the training noise
    eval_levels_key: str           # profile key: the test noise levels of the paper's tables
    sweep_key: str                 # profile key: the noise sweep of notebook 03
    training_notebook: str         # the notebook that trains the study's models
    data: str                      # function in drfkit.study.studies: (P, split, noise, protocol) -> SequenceData
    data_key: str                  # function in drfkit.study.studies: (P, protocol) -> dict naming the data
    noise_kind: str                # drfkit.data.noise.NOISE_KINDS: what the study's noise levels mean
    protocols_key: str | None = None  # profile key: the training protocols; None = the paper's only

    def models(self, P) -> list[str]:
        return list(getattr(P, self.models_key))

    def train_level(self, P) -> float:
        return float(getattr(P, self.train_level_key))

    def noise(self, level: "float | Noise | None", P=None) -> Noise:
        """The study's ``Noise`` at ``level`` (None: the profile's training level; a ``Noise`` must be
        of the study's kind)."""
        if level is None:
            if P is None:
                raise ValueError(f"{self.name}: no noise level given and no profile to take the training level from")
            level = self.train_level(P)
        if isinstance(level, Noise):
            return check_noise(level, self.noise_kind, f"the {self.name} study")
        return Noise(self.noise_kind, level)

    def eval_levels(self, P) -> list[float]:
        return [float(v) for v in getattr(P, self.eval_levels_key)]

    def protocols(self, P) -> list[str]:
        return list(getattr(P, self.protocols_key)) if self.protocols_key else ["paper"]


STUDIES: dict[str, Study] = {s.name: s for s in (
    Study("pendulum", "pendulum", 2, ("drf", "no_dynamics", "lstm"), "pend_models", "pend_train_max_noise",
          "pend_eval_max_noise", "pend_sweep_max_noise", "01_pendulum_training", "pendulum_data",
          "_pendulum_data_key", "rkn_uniform", protocols_key="pend_protocols"),
    Study("pedestrians", "keypoints", 1, ("drf", "no_dynamics", "lstm", "monoloco"), "ped_models", "ped_train_p",
          "ped_eval_p", "ped_sweep_p", "02_nuscenes_training", "pedestrian_data", "_pedestrian_data_key",
          "salt_and_pepper"),
)}


def study(name: str) -> Study:
    """The registry entry of ``name``, or a ValueError listing the studies."""
    if name not in STUDIES:
        raise ValueError(f"unknown study {name!r}; expected one of {sorted(STUDIES)}")
    return STUDIES[name]


__all__ = ["STUDIES", "Study", "study"]
