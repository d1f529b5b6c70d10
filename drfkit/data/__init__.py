"""Layer 2, data: the noisy pendulum (``pendulum``), the simulated pedestrians (``sim_world``,
``sim_detector``) and their statistics (``sim_stats``), the nuScenes reader (``nuscenes``,
``nuscenes_tables``, ``pifpaf``), one record schema (``records``), the tensors every split comes in
(``sequence_data``), observation noise (``noise``), every frame the pendulum's renderer can draw
(``rod_bank``) and pictures of the data (``drawing``). Imports only ``drfkit.util``.

The modules are re-exported by name (``from drfkit.data import pendulum``), loaded on first use;
inside drfkit, import from the defining module (``from drfkit.data.pendulum import ...``).
"""
from __future__ import annotations

from drfkit.util.lazy import lazy_modules

__all__ = ['drawing', 'noise', 'nuscenes', 'nuscenes_tables', 'pendulum', 'pifpaf', 'records', 'rod_bank',
           'sequence_data', 'sim_detector', 'sim_stats', 'sim_world']

__getattr__ = lazy_modules(__name__, __all__)
