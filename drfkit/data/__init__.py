"""Layer 2, data: the noisy pendulum (``pendulum``), the simulated pedestrians (``sim_world``,
``sim_detector``, ``pedestrians``), the nuScenes reader (``nuscenes``, ``nuscenes_tables``,
``pifpaf``), one record schema (``records``), observation noise (``noise``) and pictures of the
data (``drawing``). Imports only ``drfkit.util``.

The modules are re-exported by name (``from drfkit.data import pendulum``), loaded on first use;
inside drfkit, import from the defining module (``from drfkit.data.pendulum import ...``).
"""
from __future__ import annotations

import importlib

__all__ = ['drawing', 'noise', 'nuscenes', 'nuscenes_tables', 'pedestrians', 'pendulum', 'pifpaf', 'records',
           'sim_detector', 'sim_world']


def __getattr__(name: str):
    if name in __all__:
        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
