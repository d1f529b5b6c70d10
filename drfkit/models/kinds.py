"""``MODEL_CLASSES``, the registry of model kinds, and what reads the kinds' specs (``drfkit.models.spec``).

``drfkit.models`` registers the book's classes here; a layer that only reads specs (the protocols, the
studies' kinds, the bench, the report) imports this module rather than the models themselves.
"""
from __future__ import annotations

from drfkit.models.spec import ModelSpec, own_spec
from drfkit.util.registry import Registry

# kind -> model class (``drfkit.models.sequence.SequenceModel``); registration order is the order of every
# list of models the book shows (study kinds, protocol tables, report columns, legends)
MODEL_CLASSES: Registry = Registry("model kind")


def model_spec(kind: str) -> ModelSpec:
    """The ``ModelSpec`` of a registered kind, or a ValueError naming the registry."""
    if kind not in MODEL_CLASSES:
        raise ValueError(f"unknown model kind {kind!r}; expected one of {sorted(MODEL_CLASSES)} "
                         "(register a class in drfkit.models.MODEL_CLASSES)")
    return own_spec(MODEL_CLASSES[kind], kind)


def kinds_of(*studies: str) -> tuple[str, ...]:
    """The registered kinds whose spec names any of ``studies`` (study names or profile sections), in
    registration order."""
    return tuple(kind for kind in MODEL_CLASSES if set(model_spec(kind).studies) & set(studies))


__all__ = ["MODEL_CLASSES", "kinds_of", "model_spec"]
