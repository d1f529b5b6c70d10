"""Models of the study: DRF, its two baselines, Monoloco and the known-dynamics filter, behind one interface.

See ``drfkit.models.sequence`` for the interface every model exposes (the DRF itself is
``drfkit.models.drf``), and ``build_model(config)`` to rebuild a model from the ``config`` a
checkpoint stores.

``MODEL_CLASSES`` (kind -> class) is the registry of model kinds; each class declares its
``ModelSpec`` (``drfkit.models.spec``: label, colour, studies, bench modes, protocol variants), so
a model added in one file (``drfkit.util.registry``) is listed wherever the book lists models.
"""
from __future__ import annotations

import inspect
from typing import Any

from drfkit.models.drf import CalibratedGainDRF, DeepRecursiveFilter, SteepGainDRF
from drfkit.models.known_dynamics import KnownDynamicsFilter
from drfkit.models.monoloco import Monoloco, centre_keypoints, relative_laplace_loss
from drfkit.models.parts import Decoder, ImageEncoder, KeypointEncoder, ObservationHeads
from drfkit.models.recursion import TransitionNetwork
from drfkit.models.sequence import INPUT_KINDS, LSTMBaseline, NoDynamics, SequenceModel, gaussian_nll
from drfkit.models.kinds import MODEL_CLASSES, kinds_of, model_spec
from drfkit.models.spec import ModelSpec

# the book's kinds, in the order every list of models shows them (tables, legends, study kinds)
for _cls in (DeepRecursiveFilter, CalibratedGainDRF, SteepGainDRF, NoDynamics, LSTMBaseline, Monoloco, KnownDynamicsFilter):
    MODEL_CLASSES.register(_cls.kind, _cls)


def _accepted_keys(cls: type) -> set[str]:
    """Constructor keywords of cls, following ``**kwargs`` up to the base classes."""
    keys: set[str] = set()
    for klass in cls.__mro__:
        if "__init__" not in vars(klass) or klass in (SequenceModel,):
            continue
        params = inspect.signature(klass.__init__).parameters.values()
        keys |= {p.name for p in params if p.kind is p.POSITIONAL_OR_KEYWORD
                 and p.name != "self" and not p.name.startswith("_")}
        if not any(p.kind is p.VAR_KEYWORD for p in params):
            break
    return keys


def build_model(config: dict[str, Any]) -> SequenceModel:
    """Rebuild a model from ``model.config``: ``{'kind': 'drf'|'no_dynamics'|'lstm'|'monoloco',
    'input_kind': 'pendulum'|'keypoints', ...hyperparameters}``. Unknown keys are errors."""
    if not isinstance(config, dict) or "kind" not in config:
        raise ValueError(f"config must be a dict with a 'kind' in {sorted(MODEL_CLASSES)}, got {config!r}")
    kwargs = dict(config)
    kind = kwargs.pop("kind")
    if kind not in MODEL_CLASSES:
        raise ValueError(f"unknown model kind {kind!r}; expected one of {sorted(MODEL_CLASSES)}")
    cls = MODEL_CLASSES[kind]
    unknown = set(kwargs) - _accepted_keys(cls)
    if unknown:
        raise ValueError(f"config for {kind!r} has unknown keys {sorted(unknown)}; "
                         f"accepted: {sorted(_accepted_keys(cls))}")
    return cls(**kwargs)


def default_config(kind: str, input_kind: str, out_dim: int, **overrides: Any) -> dict[str, Any]:
    """The full config (every hyperparameter at its default unless overridden) of a model."""
    return dict(build_model({"kind": kind, "input_kind": input_kind, "out_dim": out_dim,
                             **overrides}).config)


__all__ = [
    "build_model", "default_config", "kinds_of", "model_spec", "ModelSpec", "MODEL_CLASSES", "INPUT_KINDS", "SequenceModel",
    "CalibratedGainDRF", "SteepGainDRF", "DeepRecursiveFilter", "KnownDynamicsFilter", "NoDynamics", "LSTMBaseline", "Monoloco",
    "ImageEncoder", "KeypointEncoder", "ObservationHeads", "TransitionNetwork", "Decoder",
    "gaussian_nll", "centre_keypoints", "relative_laplace_loss",
]
