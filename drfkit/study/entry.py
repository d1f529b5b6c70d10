"""``Study``: one registry entry, everything the book knows about a study in one place.

A study is what the models are trained and judged on: its input kind and output size, the models it
can train (the registered model classes whose ``ModelSpec`` names it, ``Study.kinds``), the kind of its noise (``drfkit.data.noise.Noise``), the profile keys that hold its models
and noise levels, the paper's claim on Kalman-gain gating it is judged by (``gating_claim``), and the
callables that make its runs -- its data, what names that data in checkpoint hashes, each model's
options and schedule under a training protocol, and the fresh training data of a protocol that
redraws it every epoch. The profile ``P`` is read here and in the
callables only; what they return (``SequenceData``, a ``TrainConfig``, a dict of model options) is
what the methods below take.

This module imports only ``drfkit.data.noise`` and ``drfkit.models.kinds``: each study's module (``drfkit.study.pendulum_runs``,
``drfkit.study.pedestrian_runs``) builds its entry, ``drfkit.study.registry`` lists them.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

from drfkit.data.noise import Noise, check_noise
from drfkit.models.kinds import kinds_of


def no_fresh_training(P, protocol: str, noise=None) -> None:
    """The default ``Study.fresh_training``: the training split is drawn once."""
    return None


@dataclass(frozen=True)
class Study:
    name: str
    input_kind: str                # the models' input: 'pendulum' images or 'keypoints'
    out_dim: int                   # outputs per frame
    section: str                   # the profile's section of the study (P.<section>, drfkit.study.profile)
    models_key: str                # key in that section: the models a profile trains
    train_level_key: str           # key in that section: the training noise
    eval_levels_key: str           # key in that section: the test noise levels of the paper's tables
    sweep_key: str                 # key in that section: the noise sweep of notebook 04
    training_notebook: str         # the notebook that trains the study's models
    noise_kind: str                # drfkit.data.noise.NOISE_KINDS: what the study's noise levels mean
    protocols_key: str             # key in that section: the training protocols (a list that holds 'paper')
    all_protocols: tuple[str, ...]  # every protocol the study knows (a profile picks a subset)
    # (P, split, noise: Noise, protocol) -> SequenceData (``drfkit.study.studies.study_data`` makes the Noise)
    data: Callable[..., Any]
    # (P, protocol, noise kind) -> the dict that names the training and validation data in checkpoint hashes
    data_key: Callable[[Any, str, str], dict[str, Any]]
    # (P, kind, protocol) -> the options of ``drfkit.models.default_config`` for ``kind``
    model_options: Callable[[Any, str, str], dict[str, Any]]
    # (P, kind, seed, protocol) -> drfkit.methods.run_config.TrainConfig
    train_config: Callable[[Any, str, int, str], Any]
    # (P, protocol, training Noise) -> None, or fresh(epoch) -> SequenceData: the training split drawn anew
    # every epoch
    fresh_training: Callable[[Any, str, Any], Any] = no_fresh_training
    # the paper's claim on Kalman-gain gating in this study, an id of drfkit.study.claims.efficiency.GATING_CLAIMS
    # ('C7a': the gate keeps PICP near always-dropout at much less time; 'C7b': no clear gain over random
    # gating); '' = none, and notebook 06's sweep of the study is judged by no claim
    gating_claim: str = ""
    # DRF kinds judged by the DRF claims (C1, C2, F1, F2) in their own rows beside the paper's DRF, under each
    # protocol that trains them (``drfkit.study.claims.standins``)
    judged_drfs: tuple[str, ...] = ()
    noise_name: str = "noise"      # the noise parameter's name on axes ("p" alone reads as a dropout rate)
    target_name: str = ""          # what the output is, on axes before "MAE" ('' = the unit says it)
    target_unit: str = ""          # its unit, on axes

    @property
    def kinds(self) -> tuple[str, ...]:
        """Every model kind the study can train (a profile picks a subset): the registered model classes
        whose spec names the study or its section (``ModelSpec.studies``), in registration order -- so a
        variant entry on the same section trains the same models."""
        return kinds_of(self.name, self.section)

    def _get(self, P, key: str) -> Any:
        """``P.<section>.<key>``: a value of the study's section of the typed profile."""
        return getattr(getattr(P, self.section), key)

    def models(self, P, protocol: str = "paper") -> list[str]:
        """The models a profile trains under ``protocol``: the section's ``models_key`` list, or, for
        another protocol whose own profile section names ``models`` (the pendulum's ``book.models``),
        that list (a protocol may add a model the paper does not have, e.g. the known-dynamics filter)."""
        if protocol != "paper":
            own = getattr(getattr(getattr(P, self.section), protocol, None), "models", None)
            if own is not None:
                return list(own)
        return list(self._get(P, self.models_key))

    def train_level(self, P) -> float:
        return float(self._get(P, self.train_level_key))

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
        return [float(v) for v in self._get(P, self.eval_levels_key)]

    def shifted_levels(self, P) -> list[float]:
        """The test levels out of distribution: the paper's levels above the training noise (what C3
        and C5 judge)."""
        return [lv for lv in self.eval_levels(P) if lv > self.train_level(P)]

    def baselines(self, P) -> list[str]:
        """The profile's models the DRF is compared with (every one but the DRF)."""
        return [kind for kind in self.models(P) if kind != "drf"]

    def sweep_levels(self, P) -> list[float]:
        return [float(v) for v in self._get(P, self.sweep_key)]

    def protocols(self, P) -> list[str]:
        return list(self._get(P, self.protocols_key))

    def check_protocol(self, protocol: str) -> str:
        """``protocol`` if the study knows it, else a ValueError naming the ones it does."""
        if protocol not in self.all_protocols:
            raise ValueError(f"the {self.name} study has no training protocol {protocol!r}; "
                             f"it has {list(self.all_protocols)}")
        return protocol


__all__ = ["Study", "no_fresh_training"]
