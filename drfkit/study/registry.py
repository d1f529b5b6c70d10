"""The studies of the book, one entry each (``drfkit.study.entry.Study``): every module that needs a
study's facts looks here, and nothing outside a study's entry branches on its name.

Adding a study is one module that builds its ``Study`` (its data and run callables, as
``drfkit.study.pendulum_runs`` does), one line below, and its keys in ``drfkit.study.params``. A variant
of a study on the same profile section (another noise kind, say: ``dataclasses.replace(PENDULUM,
name=..., noise_kind=...)``) needs no key of its own: an extension file registers it with
``STUDIES.register`` (``drfkit.util.registry``).
"""
from __future__ import annotations

from drfkit.study.entry import Study
from drfkit.study.pedestrian_runs import PEDESTRIANS
from drfkit.study.pendulum_runs import PENDULUM
from drfkit.util.registry import Registry

STUDIES: Registry = Registry("study", {s.name: s for s in (PENDULUM, PEDESTRIANS)})


def study(name: str) -> Study:
    """The registry entry of ``name``, or a ValueError listing the studies."""
    if name not in STUDIES:
        raise ValueError(f"unknown study {name!r}; expected one of {sorted(STUDIES)}")
    return STUDIES[name]


__all__ = ["STUDIES", "Study", "study"]
