"""drfkit: deep recursive filters, the library behind the DRF study book.

Packages by layer; a module imports only from its own layer and the layers below it
(``tests/test_structure.py`` checks it):

``util`` (files, paths, progress, device) -> ``core`` (Kalman filter, metrics) -> ``data``
(pendulum, pedestrians, nuScenes, noise) -> ``models`` (DRF, no_dynamics, LSTM, Monoloco) ->
``methods`` (training, uncertainty, gating, diagnostics, oracle, timing: explicit arguments) ->
``study`` (the registry, the profile's schema, each study's data, runs and evaluation, the paper's
numbers and the claims: the readers of the profile) -> ``report`` (figures, tables, the results
text) -> ``book`` (notebook start-up, the pipeline, the grid, the manifest, the commands).

``python -m drfkit`` lists the commands.
"""
from drfkit.methods.train import load_checkpoint

__version__ = "0.1.0"
__all__ = ["load_checkpoint", "__version__"]
