"""Observation noise for both studies.

Pendulum (the Recurrent Kalman Network benchmark, Becker et al. 2019)
---------------------------------------------------------------------
Each sequence carries a *clean factor* f_t in [0, 1] that drifts smoothly over time
(``rkn_noise_factors``): f = 1 is a clean frame, f = 0 pure noise. A frame is blended
with per-pixel uniform noise, ``noisy = f * image + (1 - f) * U(0, 255)``.

The benchmark has no "max noise" knob, but the DRF paper trains with a "maximum amount
of noise" of 50 % and evaluates at 75 %. The reading implemented here: the noise level
n = 1 - f is rescaled to ``n' = max_noise * n``, so n' lies in [0, max_noise], and the
frame is ``noisy = (1 - n') * image + n' * U(0, 255)`` (``blend_uniform_noise`` takes n').
max_noise = 1 is the benchmark itself; max_noise = 0 gives clean images. Because only
the rescaling depends on max_noise, one seed gives the same factor f at every
max_noise, so in- and out-of-distribution test sets differ only in how hard they are.

Pedestrians (the DRF paper)
---------------------------
``salt_and_pepper``: every pixel is independently replaced, with probability p, by
black (0) or white (255), half each; a colour pixel is replaced in all its channels.
The paper trains with p = 0.01 and evaluates at 0.025 and 0.05.

One value for both: ``Noise(kind, level)``
-----------------------------------------
A noise setting is one value everywhere in the book: ``Noise("rkn_uniform", 0.5)`` (the pendulum's
max noise) or ``Noise("salt_and_pepper", 0.025)`` (the pedestrians' p). The data layer takes it
and hashes ``noise.key()`` into its cache names, so two kinds at the same level never share a
file; each study names its kind in ``drfkit.study.registry`` (``Study.noise(level)``).

A new kind of noise
-------------------
A kind is its meaning (``NOISE_KINDS``) and what it does to a study's inputs: pendulum frames
(``drfkit.data.pendulum.FRAME_CORRUPTIONS``) or pedestrian camera images and keypoints
(``PEDESTRIAN_CORRUPTIONS`` below). All three are registries (``drfkit.util.registry``): one extension
file registers a kind in them, and the data, caches and checkpoint names of a study that names it follow.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from drfkit.util.registry import Registry

# kind -> what its level means
NOISE_KINDS: Registry = Registry("noise kind", {
    "rkn_uniform": "max noise of the RKN pendulum blend with uniform pixel noise (0 clean, 1 the benchmark)",
    "rkn_uniform_truncated": "rkn_uniform with each blended pixel truncated to an integer, as the benchmark's code "
                             "stores it, where rkn_uniform rounds (the same seed draws the same frames otherwise)",
    "salt_and_pepper": "probability that a pixel is replaced by black or white",
})


@dataclass(frozen=True)
class Noise:
    """A kind of image corruption and its level in [0, 1] (``NOISE_KINDS`` says what the level means)."""
    kind: str
    level: float

    def __post_init__(self) -> None:
        if self.kind not in NOISE_KINDS:
            raise ValueError(f"unknown noise kind {self.kind!r}; known kinds: {sorted(NOISE_KINDS)}")
        level = self.level
        if isinstance(level, bool) or not isinstance(level, (int, float, np.integer, np.floating)):
            raise TypeError(f"a noise level is a number in [0, 1] ({NOISE_KINDS[self.kind]}), got {level!r}")
        if not (math.isfinite(float(level)) and 0.0 <= float(level) <= 1.0):
            raise ValueError(f"a noise level of kind {self.kind} must lie in [0, 1] ({NOISE_KINDS[self.kind]}), "
                             f"got {level}")
        object.__setattr__(self, "level", float(level))

    def key(self) -> dict[str, object]:
        """What names this noise in cache hashes."""
        return {"kind": self.kind, "level": self.level}

    def __str__(self) -> str:
        return f"{self.kind} {self.level:g}"


def check_noise(noise, kind: str, where: str) -> Noise:
    """``noise`` if it is a ``Noise`` of ``kind``, else a clear error naming ``where``."""
    if not isinstance(noise, Noise):
        raise TypeError(f"{where} takes a Noise value, e.g. Noise({kind!r}, 0.5), got {noise!r}")
    if noise.kind != kind:
        raise ValueError(f"{where} takes {kind} noise ({NOISE_KINDS[kind]}), got {noise}")
    return noise

# Benchmark constants (the RKN pendulum benchmark, Becker et al. 2019).
RANDOM_WALK_STEP = 0.2  # f_{t+1} = clip(f_t + U(-0.2, 0.2), 0, 1)
T1_RANGE = (0.0, 0.25)  # lower threshold of the per-sequence rescaling
T2_RANGE = (0.75, 1.0)  # upper threshold
FIRST_CLEAN_FRAMES = 5


def rkn_noise_factors(n_sequences: int, seq_len: int, rng: np.random.Generator) -> np.ndarray:
    """Per-frame clean factors of the RKN benchmark, shape (N, T) float64 in [0, 1].

    f_0 ~ U(0, 1); f_{t+1} = clip(f_t + U(-0.2, 0.2), 0, 1); per sequence t1 ~ U(0, 0.25),
    t2 ~ U(0.75, 1); f = clip((f - t1) / (t2 - t1), 0, 1); the first 5 frames get f = 1.
    The rescaling pushes many frames to exactly 0 or 1, so sequences hold stretches of
    pure noise and stretches of clean frames, which is what makes dynamics worth having.
    """
    _check_positive_int(n_sequences, "n_sequences")
    _check_positive_int(seq_len, "seq_len")
    _check_rng(rng)
    factors = np.empty((n_sequences, seq_len), dtype=np.float64)
    factors[:, 0] = rng.uniform(0.0, 1.0, size=n_sequences)
    for t in range(seq_len - 1):
        step = rng.uniform(-RANDOM_WALK_STEP, RANDOM_WALK_STEP, size=n_sequences)
        factors[:, t + 1] = np.clip(factors[:, t] + step, 0.0, 1.0)
    t1 = rng.uniform(*T1_RANGE, size=(n_sequences, 1))
    t2 = rng.uniform(*T2_RANGE, size=(n_sequences, 1))
    factors = np.clip((factors - t1) / (t2 - t1), 0.0, 1.0)
    factors[:, :FIRST_CLEAN_FRAMES] = 1.0
    return factors


QUANTISERS = {"round": np.rint, "truncate": np.floor}  # the blend is >= 0, so floor is truncation


def blend_uniform_noise(
    images: np.ndarray, noise_level: np.ndarray, rng: np.random.Generator, quantise: str = "round"
) -> np.ndarray:
    """Convex blend with per-pixel uniform noise: ``(1 - n) * image + n * U(0, 255)``.

    images: uint8 (..., H, W). noise_level: (...) in [0, 1], one level n per image
    (n = 0 returns the image, n = 1 pure noise independent of the image).
    Returns uint8 (..., H, W): rounded to the nearest integer (``quantise="round"``, the book's), or
    truncated (``"truncate"``, what the benchmark's code does when it stores the blend in a uint8 array).
    The noise is drawn for every pixel whatever n is, so the stream of random numbers does not depend on n.
    """
    if quantise not in QUANTISERS:
        raise ValueError(f"quantise must be one of {sorted(QUANTISERS)}, got {quantise!r}")
    images = np.asarray(images)
    if images.dtype != np.uint8:
        raise TypeError(f"images must be uint8 (0..255), got dtype {images.dtype}; convert with .astype(np.uint8)")
    if images.ndim < 2:
        raise ValueError(f"images must have shape (..., H, W), got shape {images.shape}")
    _check_rng(rng)
    level = np.asarray(noise_level, dtype=np.float64)
    if level.shape != images.shape[:-2]:
        raise ValueError(
            f"noise_level must have one value per image, shape {images.shape[:-2]}, got {level.shape}"
        )
    if not np.all((level >= 0.0) & (level <= 1.0)):  # also rejects NaN
        raise ValueError("noise_level must lie in [0, 1] (and not be NaN)")
    noise = rng.random(size=images.shape, dtype=np.float32) * np.float32(255.0)
    n = level.astype(np.float32)[..., None, None]
    blended = (np.float32(1.0) - n) * images + n * noise
    return np.clip(QUANTISERS[quantise](blended), 0, 255).astype(np.uint8)


def salt_and_pepper(
    images: np.ndarray,
    p: float,
    rng: np.random.Generator,
    *,
    channels_last: bool | None = None,
) -> np.ndarray:
    """Replace each pixel, with probability p, by black (0) or white (255), half each.

    images: uint8 (..., H, W) grey or (..., H, W, C) colour. ``channels_last`` says which;
    None infers colour when ``images.ndim >= 3`` and the last axis has 3 or 4 entries
    (pass it explicitly for a grey batch whose width is 3 or 4). All channels of a pixel
    are replaced together. Returns a new uint8 array of the same shape.
    """
    images = np.asarray(images)
    if images.dtype != np.uint8:
        raise TypeError(f"images must be uint8 (0..255), got dtype {images.dtype}; convert with .astype(np.uint8)")
    if images.ndim < 2:
        raise ValueError(f"images must have shape (..., H, W) or (..., H, W, C), got shape {images.shape}")
    if isinstance(p, bool) or not isinstance(p, (int, float, np.integer, np.floating)):
        raise TypeError(f"p must be a real number in [0, 1], got {p!r}")
    if not 0.0 <= float(p) <= 1.0:  # also rejects NaN
        raise ValueError(f"p must lie in [0, 1] (probability that a pixel is replaced), got {p}")
    _check_rng(rng)
    if channels_last is None:
        channels_last = images.ndim >= 3 and images.shape[-1] in (3, 4)
    if channels_last and images.ndim < 3:
        raise ValueError(f"channels_last=True needs shape (..., H, W, C), got shape {images.shape}")
    pixel_shape = images.shape[:-1] if channels_last else images.shape
    # One uniform draw per pixel decides both whether and how: u < p/2 white, p/2 <= u < p black.
    u = rng.random(size=pixel_shape)
    white = u < 0.5 * p
    black = (u >= 0.5 * p) & (u < p)
    out = images.copy()
    out[white] = 255  # boolean mask over the pixel axes covers every channel of the pixel
    out[black] = 0
    return out


def _same_level(level: float) -> float:
    return level


@dataclass(frozen=True)
class PedestrianCorruption:
    """What a noise kind does to the pedestrian study's inputs at level in [0, 1].

    images     (pixels uint8 (..., H, W, C) colour, level, rng) -> corrupted uint8 of the same shape: the
               camera images PifPaf reads (``drfkit.data.nuscenes.write_noisy_images``) and the simulated
               frames drawn for show (``drfkit.data.drawing.render_frame``)
    strain     level -> the simulated detector's strain, on salt-and-pepper p's scale: how hard the noise
               hits the stand-in for PifPaf (``drfkit.data.sim_detector.detect``: its errors, misses and
               confidence drops grow with it; 0 a clean image)
    keypoints  None, or (keypoints float32 (M, 17, 3) pixel u, v, confidence; 0 = missed, level, rng) ->
               the same array corrupted after detection (noise that hits the detector's output itself)
    folder     the prefix of a level's PifPaf prediction folder ('p' -> 'p0.025'; '' -> '<kind>_')
    """
    images: Callable[[np.ndarray, float, np.random.Generator], np.ndarray]
    strain: Callable[[float], float] = _same_level
    keypoints: Callable[[np.ndarray, float, np.random.Generator], np.ndarray] | None = None
    folder: str = ""


def _salt_and_pepper_images(pixels: np.ndarray, p: float, rng: np.random.Generator) -> np.ndarray:
    return salt_and_pepper(pixels, p, rng, channels_last=True)


# noise kind -> how it corrupts the pedestrians' images and keypoints (a kind needs no entry for the pendulum)
PEDESTRIAN_CORRUPTIONS: Registry = Registry("corruption of pedestrian data", {
    "salt_and_pepper": PedestrianCorruption(_salt_and_pepper_images, folder="p"),
})


def pedestrian_corruption(noise, where: str) -> PedestrianCorruption:
    """The corruption of ``noise`` (a ``Noise``) in ``PEDESTRIAN_CORRUPTIONS``, else a clear error naming
    ``where`` and the registry."""
    if not isinstance(noise, Noise):
        raise TypeError(f"{where} takes a Noise value, e.g. Noise('salt_and_pepper', 0.025), got {noise!r}")
    if noise.kind not in PEDESTRIAN_CORRUPTIONS:
        raise ValueError(f"{where} has no corruption of pedestrian data for {noise}; kinds with one: "
                         f"{sorted(PEDESTRIAN_CORRUPTIONS)} (register yours in "
                         f"drfkit.data.noise.PEDESTRIAN_CORRUPTIONS)")
    return PEDESTRIAN_CORRUPTIONS[noise.kind]


def _check_positive_int(value, name: str) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be an integer, got {value!r}")
    if value < 1:
        raise ValueError(f"{name} must be >= 1, got {value}")


def _check_rng(rng) -> None:
    if not isinstance(rng, np.random.Generator):
        raise TypeError(f"rng must be a numpy Generator (np.random.default_rng(seed)), got {type(rng).__name__}")
