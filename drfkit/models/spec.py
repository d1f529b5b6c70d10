"""``ModelSpec``: what the book needs to show a model kind, declared on its class.

A model class carries its spec as the class attribute ``spec``; registering the class in
``drfkit.models.MODEL_CLASSES`` is then all it takes for the kind to appear wherever the book lists
models: the studies' kinds (``drfkit.study.entry.Study.kinds``), the pendulum's training protocols
(``drfkit.methods.protocols.PROTOCOLS``), the inference benchmark's modes (``drfkit.study.bench.MODES``),
the report's model columns and every figure's label and colour (``drfkit.report.figures``). Each of
those reads the registered classes in registration order, so the book's own order is the order its
classes are registered in.

A spec is read from the class itself, never inherited (``own_spec``): a subclass registered under a
new kind is a new model and says for itself where it belongs; one that declares nothing is in no
study, labelled by its kind, drawn in grey.

This module imports nothing, so a model's module can import it; the registry of kinds is
``drfkit.models.kinds``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping

DEFAULT_BENCH_MODES = ("batched", "no_sampling")  # timed with and without sampling (drfkit.study.bench)


@dataclass(frozen=True)
class ModelSpec:
    label: str                                # how tables, legends and axes name the kind
    colour: str = "gray"                      # its matplotlib colour in every figure
    # the studies it belongs to: a study's name, or its profile section (``Study.section``), which a variant
    # study registered on the same section (another noise kind, say) shares
    studies: tuple[str, ...] = ()
    # the modes the inference benchmark times it in (``drfkit.study.bench``'s docstring names them)
    bench_modes: tuple[str, ...] = DEFAULT_BENCH_MODES
    # pendulum protocol -> the variant (``drfkit.methods.protocols.VARIANTS``) that protocol trains for the
    # kind; a kind that names no variant of the 'paper' protocol trains there with its defaults
    protocols: Mapping[str, str] = field(default_factory=dict)
    report_column: bool = True                # a column of the report's per-model tables (the regime map)
    # a reference to read the learned models against rather than one of them: the line figures (blackout,
    # regime map) draw it dashed in black, as the particle-filter reference; bars keep ``colour``
    reference: bool = False

    def __post_init__(self) -> None:
        for name in ("studies", "bench_modes"):
            value = getattr(self, name)
            if isinstance(value, str) or not all(isinstance(v, str) and v for v in value):
                raise ValueError(f"ModelSpec.{name} is a tuple of names, got {value!r}")
            object.__setattr__(self, name, tuple(value))
        if not self.bench_modes:
            raise ValueError("ModelSpec.bench_modes names at least one mode")
        object.__setattr__(self, "protocols", dict(self.protocols))


def own_spec(cls: type, kind: str) -> ModelSpec:
    """The spec ``cls`` declares itself (its own ``spec`` attribute, not a base class's), or the spec of a
    kind that declares none: labelled ``kind``, grey, in no study."""
    spec = vars(cls).get("spec")
    if spec is None:
        return ModelSpec(label=kind)
    if not isinstance(spec, ModelSpec):
        raise TypeError(f"{cls.__name__}.spec must be a drfkit.models.spec.ModelSpec, got {spec!r}")
    return spec


__all__ = ["DEFAULT_BENCH_MODES", "ModelSpec", "own_spec"]
