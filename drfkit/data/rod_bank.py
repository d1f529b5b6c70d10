"""Every image the benchmark's renderer can draw, keyed by the rod's end point.

PIL draws the rod from the pivot (64, 64) to the tip (64 + 55 sin theta, 64 + 55 cos theta) on a
128 x 128 canvas and, for a float canvas, uses the tip's coordinates truncated to whole pixels. So a
frame is a function of the integer tip ``(floor(64 + 55 sin theta), floor(64 + 55 cos theta))``
alone: about 430 distinct images per revolution. ``rod_bank()`` holds them once:

    keys      int64 (J,)          tip x * 128 + tip y, sorted
    images    uint8 (J, 24, 24)   the frame of each tip (drawn by PIL once)
    arc_mean  float64 (J, 2)      mean (cos theta, sin theta) over the angles that draw image j
    arc_weight float64 (J,)       the fraction of the circle that draws image j (sums to 1)
    index     int64 (128 * 128,)  key -> j, -1 for a tip no angle of the construction grid reached

``render_exact(theta)`` is the renderer at lookup speed: images of tips in the bank are gathered,
any other tip (an arc thinner than the grid's step, never met in practice) is drawn by PIL, so the
result equals PIL's drawing for every angle (tests/test_rod_bank.py compares them; the 10^6-angle
comparison is in docs/rerun_time.md). The bank is also what the pixel-exact Bayes filter
(``drfkit.methods.pixel_bayes``) sums over: each image stands for its arc of angles.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

# Rendering (the benchmark's values).
IMAGE_SIZE = 24
CANVAS_SIZE = 128
CANVAS = CANVAS_SIZE
CANVAS_PIVOT = 64  # the benchmark's x0 = y0 = 64, in PIL's pixel-corner coordinates: the canvas centre
ROD_LENGTH_PX = 55.0
ROD_WIDTH_PX = 8
# Angles of the construction grid: 2^20 per revolution, a step of 6e-6 rad. An arc of angles drawing
# one image spans ~1.5e-2 rad on average; the grid meets every arc wider than its step.
GRID_ANGLES = 1 << 20


def rod_keys(theta: np.ndarray, pivot: float, length: float) -> np.ndarray:
    """Integer tip keys (...) of angles ``theta`` (...): floor(tip x) * 128 + floor(tip y)."""
    theta = np.asarray(theta, dtype=np.float64)
    tip_x = np.floor(pivot + length * np.sin(theta)).astype(np.int64)
    tip_y = np.floor(pivot + length * np.cos(theta)).astype(np.int64)
    return tip_x * CANVAS + tip_y


@dataclass(frozen=True)
class RodBank:
    keys: np.ndarray
    images: np.ndarray
    arc_mean: np.ndarray
    arc_weight: np.ndarray
    index: np.ndarray

    def __len__(self) -> int:
        return int(self.keys.size)

    def lookup(self, theta: np.ndarray) -> np.ndarray:
        """Bank index (...) of the image each angle draws; -1 where the tip is not in the bank."""
        return self.index[rod_keys(theta, CANVAS_PIVOT, ROD_LENGTH_PX)]


def render_pendulum_pil(theta: np.ndarray) -> np.ndarray:
    """The benchmark's frames (``drfkit.data.pendulum.render_pendulum``) drawn one by one with PIL, as the benchmark's code does (the
    reference that the bank is built from and tested against): a float canvas, the rod as a hard-edged
    line of width 8, Lanczos down to 24 x 24, clipped, times 255, truncated to uint8 (drfkit.data.pendulum)."""
    from PIL import Image, ImageDraw

    theta = np.asarray(theta, dtype=np.float64)
    if not np.all(np.isfinite(theta)):
        raise ValueError("theta must be finite")
    flat = theta.reshape(-1)
    tips_x = CANVAS_PIVOT + ROD_LENGTH_PX * np.sin(flat)
    tips_y = CANVAS_PIVOT + ROD_LENGTH_PX * np.cos(flat)
    out = np.empty((flat.size, IMAGE_SIZE, IMAGE_SIZE), dtype=np.uint8)
    for i in range(flat.size):
        canvas = Image.new("F", (CANVAS_SIZE, CANVAS_SIZE), 0.0)
        ImageDraw.Draw(canvas).line([(CANVAS_PIVOT, CANVAS_PIVOT), (float(tips_x[i]), float(tips_y[i]))],
                                    fill=1.0, width=ROD_WIDTH_PX)
        small = canvas.resize((IMAGE_SIZE, IMAGE_SIZE), resample=Image.Resampling.LANCZOS)
        # clip, scale, truncate (the benchmark stores 255 * x into a uint8 array: no rounding)
        out[i] = (255.0 * np.clip(np.asarray(small, dtype=np.float64), 0.0, 1.0)).astype(np.uint8)
    return out.reshape(theta.shape + (IMAGE_SIZE, IMAGE_SIZE))


@lru_cache(maxsize=1)
def rod_bank() -> RodBank:
    """The bank of the benchmark's renderer (built once per process, ~0.3 s)."""
    grid = -np.pi + 2.0 * np.pi * (np.arange(GRID_ANGLES) + 0.5) / GRID_ANGLES
    keys_all = rod_keys(grid, CANVAS_PIVOT, ROD_LENGTH_PX)
    keys, first, inverse, counts = np.unique(keys_all, return_index=True, return_inverse=True, return_counts=True)
    images = render_pendulum_pil(grid[first])
    trig = np.stack([np.cos(grid), np.sin(grid)], axis=-1)                      # (G, 2)
    sums = np.zeros((keys.size, 2))
    np.add.at(sums, inverse, trig)
    index = np.full(CANVAS * CANVAS, -1, dtype=np.int64)
    index[keys] = np.arange(keys.size)
    for arr in (keys, images, sums, index):
        arr.setflags(write=False)
    return RodBank(keys=keys, images=images, arc_mean=sums / counts[:, None],
                   arc_weight=counts / float(GRID_ANGLES), index=index)


def render_exact(theta: np.ndarray) -> np.ndarray:
    """The benchmark's frames of angles ``theta`` (...) -> uint8 (..., 24, 24), equal to PIL's drawing
    (``render_pendulum_pil``) for every angle, at the cost of a gather."""
    theta = np.asarray(theta, dtype=np.float64)
    if not np.all(np.isfinite(theta)):
        raise ValueError("theta must be finite")
    bank = rod_bank()
    flat = theta.reshape(-1)
    idx = bank.lookup(flat)
    out = bank.images[np.maximum(idx, 0)]
    missing = idx < 0
    if missing.any():  # a tip the grid did not meet: drawn as the benchmark draws it
        out[missing] = render_pendulum_pil(flat[missing])
    return out.reshape(theta.shape + out.shape[-2:])


__all__ = ["GRID_ANGLES", "RodBank", "render_exact", "render_pendulum_pil", "rod_bank", "rod_keys"]


def verify(n_angles: int, seed: int = 0, chunk: int = 20_000) -> int:
    """How many of ``n_angles`` random angles ``render_exact`` draws differently from PIL (0 expected)."""
    rng = np.random.default_rng(seed)
    mismatches = 0
    for start in range(0, n_angles, chunk):
        theta = rng.uniform(-np.pi, np.pi, min(chunk, n_angles - start))
        mismatches += int((render_exact(theta) != render_pendulum_pil(theta)).any(axis=(1, 2)).sum())
    return mismatches
