"""The RKN pendulum benchmark's physics constants (Becker et al. 2019), apart from its generator
(``drfkit.data.pendulum``, which re-exports them), so that a model built on the true equations (the
known-dynamics filter, ``drfkit.models.known_dynamics``) reads them without the generator's noise and
caches."""
from __future__ import annotations

MASS = 1.0
LENGTH = 1.0
GRAVITY = 9.81
FRICTION = 0.1
FRAME_DT = 0.05
N_SUBSTEPS = 500  # 500 x 1e-4 s per frame
TRANSITION_NOISE_STD = 0.1

__all__ = ["FRAME_DT", "FRICTION", "GRAVITY", "LENGTH", "MASS", "N_SUBSTEPS", "TRANSITION_NOISE_STD"]
