"""drfkit: deep recursive filters, the library behind the DRF study book.

Packages by layer; a module imports only from its own layer and the layers below it
(``tests/test_structure.py`` checks it):

``util`` (files, paths, progress, device) -> ``core`` (Kalman filter, metrics) -> ``data``
(pendulum, pedestrians, nuScenes, noise) -> ``models`` (DRF, no_dynamics, LSTM, Monoloco) ->
``methods`` (training, uncertainty, gating, diagnostics, references, timing: explicit arguments) ->
``study`` (the registry, the profile's schema, each study's data, runs and evaluation, the paper's
numbers and the claims: the readers of the profile) -> ``report`` (figures, tables, the results
text) -> ``book`` (notebook start-up, the pipeline, the grid, the manifest, the commands).

``python -m drfkit`` lists the commands.
"""
from __future__ import annotations

from typing import Any

__version__ = "0.1.0"
__all__ = ["load_checkpoint", "__version__"]


def __getattr__(name: str) -> Any:
    """``drfkit.load_checkpoint`` on first use: importing drfkit (or ``python -m drfkit --help``) loads no
    torch (``tests/test_structure.py`` checks it)."""
    if name == "load_checkpoint":
        from drfkit.methods.train import load_checkpoint
        return load_checkpoint
    raise AttributeError(f"module 'drfkit' has no attribute {name!r}")
