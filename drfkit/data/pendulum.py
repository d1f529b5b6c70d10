"""The noisy pendulum of the Recurrent Kalman Network benchmark (Becker et al. 2019).

Conventions (every angle in this module follows them)
------------------------------------------------------
* theta is the rod angle measured from *hanging straight down*: theta = 0 hangs below
  the pivot, theta = pi stands upright. Returned angles lie in [-pi, pi).
* In the image (x to the right, y *down*, pivot at the centre) the rod's tip sits at
  ``pivot + L * (sin theta, cos theta)``: theta = 0 is drawn below the pivot and a small
  positive theta swings the tip to the right (counter-clockwise as seen on screen).
* Targets are ``(cos theta, sin theta)`` in that order, the DRF paper's state X_t. In
  image terms cos theta is the tip's downward offset and sin theta its rightward one.
  (The benchmark itself stores (sin, cos); only the order differs.)

Physics (kept exactly as the benchmark has it)
---------------------------------------------------------------
The benchmark integrates the angle phi measured from *upright* (phi = theta + pi):
``phi'' = c sin(phi) - friction * phi'`` with ``c = g * l * m / I`` and ``I = m l^2 / 3``,
so c = 3 g / l (the benchmark's constant; a uniform rod about its end would have
3 g / (2 l), we keep the benchmark's). In theta this reads
``theta'' = -c sin(theta) - friction * theta'``, stable at theta = 0, small-angle
period 2 pi sqrt(l / (3 g)) = 1.158 s (23.2 frames). Semi-implicit Euler: per sub-step
``v <- v + h (c sin phi - friction v)`` then ``phi <- phi + h v`` (new v), h = 1e-4 s,
500 sub-steps per 0.05 s frame. After each frame the angular velocity receives
N(0, 0.1^2) transition noise and phi is wrapped to [0, 2 pi); theta = phi - pi.
Initial phi ~ U[0, 2 pi) (so theta is uniform too), initial velocity 0. m = l = 1,
g = 9.81, friction 0.1.

Rendering (the benchmark's own recipe)
--------------------------------------
Drawn as the RKN code draws it (ALRhub/rkn_share, ``PendulumData._generate_single_image``):
a float canvas (PIL mode 'F') of 128 x 128 filled with 0.0; ``ImageDraw.line`` from the
pivot (64, 64) to pivot + 55 * (sin theta, cos theta), intensity 1.0, width 8, *not*
anti-aliased (PIL draws float lines hard-edged, with no end caps); down-scaled to 24 x 24 with
the Lanczos filter (PIL's former ``ANTIALIAS``), clipped to [0, 1], times 255 and truncated to
uint8. Lanczos rings, so a frame holds small negative lobes (clipped to 0) and the rod's edges
are not a box average. A vertical rod's ink is centred on canvas pixel 64 (11.59 in the small
image's pixel-centre coordinates), but the hard-edged rod is not symmetric about its axis at
other angles; ``estimate_angle`` measures from the image centre (11.5), where its centroid points
least far off the drawn angle (mean 0.8, at most 2.3 degrees).
(The benchmark also jitters the drawn state by N(0, 1e-5); far below one grey level, left out.)

Noise: see ``drfkit.data.noise`` (per-sequence clean factor f, noise level
n' = max_noise * (1 - f), convex blend with uniform pixel noise).
"""
from __future__ import annotations

import os
import re

import numpy as np

from drfkit.data.noise import Noise, blend_uniform_noise, rkn_noise_factors
from drfkit.util.io import cached_npz
from drfkit.util.registry import Registry

# Seed conventions of the book's corrupted pendulum splits (every study draws them the same way).
TRAINING_BLACKOUT_SEED_OFFSET = 7  # which training sequences get a blackout: data seed + this
BLACKOUT_SEED_OFFSET = 11  # the blackout's pixel noise: split seed + this

# Physics (the benchmark's values)
from drfkit.data.pendulum_physics import (FRAME_DT, FRICTION, GRAVITY, LENGTH, MASS, N_SUBSTEPS,  # noqa: E402,F401
                                          TRANSITION_NOISE_STD)

# Rendering (the benchmark's values): the renderer lives in drfkit.data.rod_bank
from drfkit.data.rod_bank import (CANVAS_PIVOT, CANVAS_SIZE, IMAGE_SIZE, ROD_LENGTH_PX, ROD_WIDTH_PX,  # noqa: E402
                                  render_exact, render_pendulum_pil)
# the centre of the small image, pixel-centre coordinates (see the module docstring)
_IMAGE_PIVOT = CANVAS_PIVOT * IMAGE_SIZE / CANVAS_SIZE - 0.5

# Bump when the generator changes, so old caches are not reused (2: the benchmark's PIL frames).
GENERATOR_VERSION = 2
_NOISE_CHUNK = 256  # sequences blended at once (bounds the memory of the pixel noise)


def generate_pendulum(n_sequences: int, seq_len: int, noise: Noise, seed: int) -> dict[str, np.ndarray]:
    """Simulate, render and corrupt ``n_sequences`` pendulum sequences of ``seq_len`` frames at
    ``noise`` = ``Noise("rkn_uniform", max_noise)`` (the benchmark's; any kind in ``FRAME_CORRUPTIONS``).

    Returns a dict of arrays:
      'images'  uint8 (N, T, 24, 24)  noisy observations
      'clean'   uint8 (N, T, 24, 24)  the same frames without noise
      'targets' float32 (N, T, 2)     (cos theta, sin theta)
      'noise'   float32 (N, T)        per-frame noise level n' in [0, max_noise] (0 = clean)
      'theta'   float32 (N, T)        angle from hanging down, in [-pi, pi)

    Deterministic for a seed. Physics, the noise factor f and the pixel noise come from
    three independent child generators of ``SeedSequence(seed)``, so the same seed with a
    different ``max_noise`` gives the same motions, clean images and f; only the
    rescaling n' = max_noise * (1 - f) and hence the noisy images differ.
    """
    max_noise = _check_generation_args(n_sequences, seq_len, noise, seed)
    physics_rng, factor_rng, pixel_rng = (
        np.random.default_rng(child) for child in np.random.SeedSequence(seed).spawn(3)
    )
    # The benchmark draws the angle from upright in [0, 2 pi); shift to hanging-down.
    theta0 = physics_rng.uniform(0.0, 2.0 * np.pi, size=n_sequences) - np.pi
    theta, _ = _simulate(theta0, seq_len, physics_rng)
    clean = render_pendulum(theta)

    images, levels = FRAME_CORRUPTIONS[noise.kind](clean, max_noise, factor_rng, pixel_rng)
    targets = np.stack([np.cos(theta), np.sin(theta)], axis=-1).astype(np.float32)
    return {
        "images": images,
        "clean": clean,
        "targets": targets,
        "noise": levels,
        "theta": theta.astype(np.float32),
    }


def _corrupt(clean: np.ndarray, max_noise: float, factor_rng, pixel_rng, quantise: str = "round"
             ) -> tuple[np.ndarray, np.ndarray]:
    """(noisy images uint8 (N, T, 24, 24), levels float32 (N, T)) of clean frames: the benchmark's
    clean-factor walk rescaled to [0, max_noise], then the blend with uniform pixel noise (rounded, or
    truncated as the benchmark's code stores it: ``blend_uniform_noise``'s ``quantise``)."""
    n_sequences, seq_len = clean.shape[:2]
    factors = rkn_noise_factors(n_sequences, seq_len, factor_rng)
    levels = (max_noise * (1.0 - factors)).astype(np.float32)
    images = np.empty_like(clean)
    for start in range(0, n_sequences, _NOISE_CHUNK):
        chunk = slice(start, start + _NOISE_CHUNK)
        images[chunk] = blend_uniform_noise(clean[chunk], levels[chunk], pixel_rng, quantise)
    return images, levels


# noise kind -> how it corrupts a split's clean frames: (clean uint8 (N, T, 24, 24), level, factor_rng,
# pixel_rng) -> (noisy uint8 (N, T, 24, 24), per-frame noise float32 (N, T)). A new noise kind is its
# meaning in ``drfkit.data.noise.NOISE_KINDS`` and its corruption here, each added with ``.register``
# (``drfkit.util.registry``); the generator, the fresh noise of training and the caches (``Noise.key``
# names them) follow.
FRAME_CORRUPTIONS: Registry = Registry("corruption of pendulum frames", {
    "rkn_uniform": _corrupt,
    "rkn_uniform_truncated": lambda clean, max_noise, factor_rng, pixel_rng: _corrupt(clean, max_noise, factor_rng,
                                                                                      pixel_rng, "truncate"),
})


def check_frame_noise(noise, where: str) -> Noise:
    """``noise`` if it is a ``Noise`` whose kind can corrupt pendulum frames, else a clear error."""
    if not isinstance(noise, Noise):
        raise TypeError(f"{where} takes a Noise value, e.g. Noise('rkn_uniform', 0.5), got {noise!r}")
    if noise.kind not in FRAME_CORRUPTIONS:
        raise ValueError(f"{where} has no corruption of pendulum frames for {noise}; kinds with one: "
                         f"{sorted(FRAME_CORRUPTIONS)} (register yours in drfkit.data.pendulum.FRAME_CORRUPTIONS)")
    return noise


def redraw_noise(arrays: dict[str, np.ndarray], noise: Noise, seed: int,
                 blackouts: dict | None = None) -> dict[str, np.ndarray]:
    """A copy of a ``generate_pendulum`` split with new noise on the same clean frames: a new
    clean-factor walk and new pixel noise at ``noise`` (an rkn_uniform ``Noise``), and, if
    ``blackouts`` = {"fraction", "lengths"} is given, new random pure-noise windows
    (``with_random_blackouts``). Deterministic for ``seed``; training draws one per epoch
    (``fresh noise``), so the network never sees the same noisy pixel twice."""
    noise = check_frame_noise(noise, "redraw_noise")
    factor_rng, pixel_rng, blackout_seed = np.random.SeedSequence([int(seed), 17]).spawn(3)
    images, levels = FRAME_CORRUPTIONS[noise.kind](arrays["clean"], noise.level, np.random.default_rng(factor_rng),
                                                   np.random.default_rng(pixel_rng))
    out = dict(arrays) | {"images": images, "noise": levels}
    if blackouts:
        out = with_random_blackouts(out, blackouts["fraction"], tuple(blackouts["lengths"]),
                                    seed=int(blackout_seed.generate_state(1)[0]))
    return out


def fresh_noise_seed(data_seed: int, epoch: int) -> int:
    """The seed of epoch ``epoch``'s fresh training noise (``redraw_noise``) on the training split made
    from ``data_seed``: data_seed x 1000 + epoch, from these two alone, so that a resumed run draws
    what an uninterrupted one drew."""
    return int(data_seed) * 1000 + int(epoch)


def load_pendulum(
    cache_dir: str | os.PathLike,
    split: str,
    n_sequences: int,
    seq_len: int,
    noise: Noise,
    seed: int,
) -> dict[str, np.ndarray]:
    """``generate_pendulum`` cached as ``<cache_dir>/pendulum-<split>-<hash>.npz``.

    The hash covers every argument (and the generator version), so any change builds a
    new file; a corrupt file is rebuilt. ``split`` is a free label ('train', 'val',
    'test', ...) used in the file name; the caller picks distinct seeds per split.
    """
    if not isinstance(split, str) or not re.fullmatch(r"[A-Za-z0-9_.\-]+", split):
        raise ValueError(f"split must be a non-empty name of letters, digits, '_', '-', '.', got {split!r}")
    _check_generation_args(n_sequences, seq_len, noise, seed)
    params = {
        "split": split,
        "n_sequences": int(n_sequences),
        "seq_len": int(seq_len),
        "noise": noise.key(),
        "seed": int(seed),
        "generator_version": GENERATOR_VERSION,
    }
    return cached_npz(
        cache_dir,
        f"pendulum-{split}",
        params,
        lambda: generate_pendulum(n_sequences, seq_len, noise, seed),
    )


def render_pendulum(theta: np.ndarray) -> np.ndarray:
    """Clean images of the rod at angles ``theta`` (...) -> uint8 (..., 24, 24), drawn the
    benchmark's way (see the module docstring).

    theta is measured from hanging down (0 is drawn below the pivot, positive to the right).
    A frame depends on the rod's integer tip alone, so the frames come from the bank of every
    drawable image (``drfkit.data.rod_bank``): the same bytes as ``render_pendulum_pil``, ~700x faster.
    """
    return render_exact(theta)


def estimate_angle(clean_images: np.ndarray) -> np.ndarray:
    """Rod angle from clean images, uint8 (..., 24, 24) -> float64 (...) in (-pi, pi].

    The intensity-weighted centroid of a straight rod lies on the rod (half-way along it),
    so its direction from the pivot (the image centre) is the angle:
    theta = atan2(x_offset, y_offset) with y pointing down. An all-black image has no
    angle and gives NaN. Meant for clean images; noise pulls the centroid to the centre.
    """
    images = np.asarray(clean_images)
    if images.dtype != np.uint8:
        raise TypeError(f"clean_images must be uint8, got dtype {images.dtype}")
    if images.ndim < 2 or images.shape[-2:] != (IMAGE_SIZE, IMAGE_SIZE):
        raise ValueError(f"clean_images must have shape (..., {IMAGE_SIZE}, {IMAGE_SIZE}), got {images.shape}")
    weights = images.astype(np.float64)
    offsets = np.arange(IMAGE_SIZE, dtype=np.float64) - _IMAGE_PIVOT
    total = weights.sum(axis=(-2, -1))
    x = (weights * offsets[None, :]).sum(axis=(-2, -1))
    y = (weights * offsets[:, None]).sum(axis=(-2, -1))
    with np.errstate(invalid="ignore"):
        return np.where(total > 0, np.arctan2(x, y), np.nan)


def check_images(images) -> None:
    """Raise a clear error unless ``images`` is a non-empty uint8 array (N, T, 24, 24).

    Float images (including any holding NaN) are rejected by the dtype rule: the pipeline
    stores pixels as uint8 0..255 and scales them itself.
    """
    if not isinstance(images, np.ndarray):
        raise TypeError(f"images must be a numpy array, got {type(images).__name__}")
    if images.dtype != np.uint8:
        raise TypeError(
            f"images must be uint8 0..255 (N, T, {IMAGE_SIZE}, {IMAGE_SIZE}), got dtype {images.dtype}; "
            "float images (and any NaN in them) are not accepted, convert with np.clip(x, 0, 255).astype(np.uint8)"
        )
    if images.ndim != 4 or images.shape[2:] != (IMAGE_SIZE, IMAGE_SIZE):
        raise ValueError(f"images must have shape (N, T, {IMAGE_SIZE}, {IMAGE_SIZE}), got {images.shape}")
    if images.size == 0:
        raise ValueError(f"images is empty (shape {images.shape}); need at least one sequence and one frame")


def _simulate(
    theta0: np.ndarray,
    seq_len: int,
    rng: np.random.Generator | None,
    *,
    friction: float = FRICTION,
    transition_noise_std: float = TRANSITION_NOISE_STD,
    gravity: float = GRAVITY,
    length: float = LENGTH,
    mass: float = MASS,
    frame_dt: float = FRAME_DT,
    n_substeps: int = N_SUBSTEPS,
) -> tuple[np.ndarray, np.ndarray]:
    """Integrate N pendulums from rest at ``theta0`` (N,) (hanging-down convention).

    Returns (theta, velocity), each float64 (N, seq_len): frame 0 is the initial state,
    theta in [-pi, pi). Keyword arguments exist so tests can switch friction and
    transition noise off; ``rng`` may be None only when transition_noise_std is 0.
    """
    phi = np.asarray(theta0, dtype=np.float64).reshape(-1) + np.pi  # angle from upright
    phi = np.mod(phi, 2.0 * np.pi)
    n = phi.size
    if transition_noise_std > 0 and rng is None:
        raise ValueError("rng is needed when transition_noise_std > 0")
    inertia = mass * length**2 / 3.0
    c = gravity * length * mass / inertia
    h = frame_dt / n_substeps
    vel = np.zeros(n)
    accel = np.empty(n)
    damping = np.empty(n)
    phis = np.empty((n, seq_len))
    vels = np.empty((n, seq_len))
    phis[:, 0], vels[:, 0] = phi, vel
    for t in range(1, seq_len):
        for _ in range(n_substeps):
            # v += h (c sin phi - friction v); phi += h v_new   (in place: this loop is the hot path)
            np.sin(phi, out=accel)
            accel *= c
            np.multiply(vel, friction, out=damping)
            accel -= damping
            accel *= h
            vel += accel
            np.multiply(vel, h, out=damping)
            phi += damping
        if transition_noise_std > 0:
            vel += rng.normal(0.0, transition_noise_std, size=n)
        np.mod(phi, 2.0 * np.pi, out=phi)
        phis[:, t], vels[:, t] = phi, vel
    return phis - np.pi, vels


def _check_generation_args(n_sequences, seq_len, noise, seed) -> float:
    """The level of ``noise`` (a ``Noise`` with a ``FRAME_CORRUPTIONS`` entry) once every argument is checked."""
    for name, value in (("n_sequences", n_sequences), ("seq_len", seq_len)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise TypeError(f"{name} must be an integer, got {value!r}")
        if value < 1:
            raise ValueError(f"{name} must be >= 1, got {value}")
    check_frame_noise(noise, "the pendulum generator")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise TypeError(f"seed must be a non-negative integer, got {seed!r}")
    if seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed}")
    return noise.level


# Frames of the blackout test: 15 frames of pure noise in the middle of a 75-frame sequence,
# long enough (about 2/3 of a swing) that only a model of the motion can bridge them.
BLACKOUT_FRAMES = (30, 45)


def blackout_frames(seq_len: int) -> tuple[int, int]:
    """BLACKOUT_FRAMES for sequences of at least 60 frames (15 frames after the blackout to
    watch the recovery); for shorter ones the same shape scaled: frames [0.4 T, 0.6 T)."""
    if seq_len >= 60:
        return BLACKOUT_FRAMES
    if seq_len < 10:
        raise ValueError(f"a blackout test needs sequences of at least 10 frames, got {seq_len}")
    return int(0.4 * seq_len), int(0.6 * seq_len)


def with_blackout(arrays: dict[str, np.ndarray], start: int, stop: int, seed: int) -> dict[str, np.ndarray]:
    """A copy of a ``generate_pendulum`` split whose frames [start, stop) are pure uniform noise
    (noise level 1, independent of the image) in every sequence; 'noise' says 1.0 there."""
    images = arrays["images"]
    if not 0 <= start < stop <= images.shape[1]:
        raise ValueError(f"blackout frames [{start}, {stop}) must lie inside the {images.shape[1]} frames "
                         "of the sequences; use shorter windows or longer sequences")
    out = dict(arrays)
    rng = np.random.default_rng(seed)
    out["images"], out["noise"] = images.copy(), arrays["noise"].copy()
    window = out["images"][:, start:stop]
    out["images"][:, start:stop] = blend_uniform_noise(window, np.ones(window.shape[:2]), rng)
    out["noise"][:, start:stop] = 1.0
    return out


def with_random_blackouts(arrays: dict[str, np.ndarray], fraction: float, lengths: tuple[int, int],
                          seed: int, first_frame: int = 5) -> dict[str, np.ndarray]:
    """Training-time corruption: in a ``fraction`` of the sequences (drawn with ``seed``), one
    window of pure-noise frames, its length uniform in ``lengths`` (inclusive, capped at
    T - first_frame) and its start
    uniform in [first_frame, T - length]. Without such frames every frame is informative at
    low max noise and a model can do well without ever carrying its state forward."""
    if not 0.0 <= float(fraction) <= 1.0:
        raise ValueError(f"fraction must lie in [0, 1], got {fraction!r}")
    n, steps = arrays["images"].shape[:2]
    if not 1 <= lengths[0] <= lengths[1] or steps <= first_frame:
        raise ValueError(f"blackout lengths {lengths} must satisfy 1 <= lo <= hi, and sequences ({steps} frames) "
                         f"must be longer than first_frame = {first_frame}")
    hi = min(lengths[1], steps - first_frame)  # short sequences: windows capped at what fits
    lo = min(lengths[0], hi)
    rng = np.random.default_rng(seed)
    chosen = rng.random(n) < fraction
    length = rng.integers(lo, hi + 1, size=n)
    start = first_frame + (rng.random(n) * (steps - first_frame - length + 1)).astype(np.int64)
    frames = np.arange(steps)
    dark = chosen[:, None] & (frames >= start[:, None]) & (frames < (start + length)[:, None])   # (N, T)
    out = dict(arrays)
    out["images"], out["noise"] = arrays["images"].copy(), arrays["noise"].copy()
    pure = blend_uniform_noise(arrays["images"][dark], np.ones(int(dark.sum())), rng)
    out["images"][dark] = pure
    out["noise"][dark] = 1.0
    return out
