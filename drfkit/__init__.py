"""drfkit: deep recursive filters, the library behind the DRF study book.

Modules: ``filter`` (differentiable Kalman filter), ``models`` (DRF, no_dynamics, LSTM,
Monoloco), ``data`` (pendulum, pedestrians, nuScenes, noise), ``train``, ``uncertainty``,
``metrics``, ``evaluate``, ``timing``, ``gating``, ``report``; ``params``, ``runtime``,
``manifest`` and ``pipeline`` run the notebooks.
"""
from drfkit.train import load_checkpoint

__version__ = "0.1.0"
__all__ = ["load_checkpoint", "__version__"]
