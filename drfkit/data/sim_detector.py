"""The simulated keypoint detector of the pedestrian study.

**This stands in for PifPaf run on salt-and-pepper-noised images.** It does not look at
pixels: it perturbs the true projected keypoints with errors that grow with the noise
probability p and with distance (people small in pixels suffer more), see ``detect``.

Coupling across noise levels: ``simulate_records(truth, noise, seed, config)`` draws every
random number with shapes that do not depend on p, from a generator seeded by ``seed``
alone, and p only scales them. The same seed at p = 0.01, 0.025, 0.05 therefore observes the
same people with the same "luck": each keypoint's Gaussian error grows monotonically with p,
confidences only fall, and the sets of outliers, missed keypoints and missed detections only
grow.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from drfkit.data.noise import Noise, pedestrian_corruption
from drfkit.data.records import N_KEYPOINTS, check_records
from drfkit.data.sim_world import IMAGE_HEIGHT, IMAGE_WIDTH, check_int


@dataclass(frozen=True)
class DetectorConfig:
    """Parameters of the simulated keypoint detector (``detect``); every field has a default.

    Size ratio r = ref_height_px / height_px (r > 1 for people smaller in the image than
    ``ref_height_px``, i.e. farther away; ~22 m for the default 100 px).
    """

    ref_height_px: float = 100.0
    # keypoint position error, standard deviation in pixels:
    # pixel_sigma + height_px * (rel_sigma + p * noise_sigma_gain * (1 + r))
    pixel_sigma: float = 1.0
    rel_sigma: float = 0.012
    noise_sigma_gain: float = 0.5
    # probability that a keypoint is missed: miss_base + miss_far * r + p * miss_noise_gain * (1 + r)
    miss_base: float = 0.02
    miss_far: float = 0.02
    miss_noise_gain: float = 2.0
    miss_max: float = 0.95
    # probability of a gross outlier: outlier_base + p * outlier_noise_gain; it is displaced by
    # height_px * outlier_scale * U(0.3, 1) in a uniform direction
    outlier_base: float = 0.01
    outlier_noise_gain: float = 1.0
    outlier_scale: float = 0.5
    # confidence: conf_base - conf_far * r - p * conf_noise_gain * (1 + r) + conf_sd * N(0, 1)
    #             - conf_error_drop * (squared error in sd units), clipped to [conf_min, 1]
    conf_base: float = 0.8
    conf_far: float = 0.05
    conf_noise_gain: float = 2.0
    conf_sd: float = 0.1
    conf_error_drop: float = 0.05
    conf_min: float = 0.05
    # probability that a whole detection is missed:
    # det_miss_base + det_miss_far * r + p * det_miss_noise_gain * (1 + r), at most det_miss_max
    det_miss_base: float = 0.02
    det_miss_far: float = 0.03
    det_miss_noise_gain: float = 3.0
    det_miss_max: float = 0.98
    # a detection with fewer detected keypoints than this is dropped (PifPaf would not report it)
    min_keypoints: int = 3
    # the detection box is the detected keypoints' extent grown by this fraction on each side
    box_margin: float = 0.1

    def __post_init__(self) -> None:
        probabilities = ("miss_base", "miss_max", "outlier_base", "conf_base", "conf_min",
                         "det_miss_base", "det_miss_max")
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name == "min_keypoints":
                if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 1 <= value <= N_KEYPOINTS:
                    raise ValueError(f"DetectorConfig.min_keypoints must be an integer in [1, 17], got {value!r}")
                continue
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
                raise TypeError(f"DetectorConfig.{f.name} must be a number, got {value!r}")
            if not math.isfinite(value) or value < 0:
                raise ValueError(f"DetectorConfig.{f.name} must be a finite number >= 0, got {value}")
            if f.name in probabilities and value > 1:
                raise ValueError(f"DetectorConfig.{f.name} is a probability and must lie in [0, 1], got {value}")
        if self.ref_height_px <= 0:
            raise ValueError(f"DetectorConfig.ref_height_px must be > 0, got {self.ref_height_px}")
        if not 0 < self.conf_min <= self.conf_base:
            raise ValueError(
                f"DetectorConfig needs 0 < conf_min <= conf_base, got conf_min={self.conf_min}, conf_base={self.conf_base}"
            )

    @classmethod
    def from_dict(cls, d: Mapping[str, Any] | None) -> "DetectorConfig":
        """Build from a dict (e.g. a params/*.yaml section); unknown keys are an error."""
        if d is None:
            return cls()
        if isinstance(d, DetectorConfig):
            return d
        if not isinstance(d, Mapping):
            raise TypeError(f"detector settings must be a dict, got {type(d).__name__}")
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ValueError(f"unknown DetectorConfig key(s) {unknown}; known keys: {sorted(known)}")
        return cls(**dict(d))

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def detect(
    truth: Mapping[str, np.ndarray],
    noise: Noise,
    rng: np.random.Generator,
    config: DetectorConfig | None = None,
) -> dict[str, np.ndarray]:
    """Simulated PifPaf on images under ``noise``: truth -> records. p below is the noise's strain
    (``drfkit.data.noise.PEDESTRIAN_CORRUPTIONS``: salt-and-pepper's probability p itself); a kind that
    corrupts keypoints too has them corrupted after detection, by draws after the detector's own.

    **A stand-in for PifPaf on noisy images**, not an image model. For each true
    pedestrian-keyframe (rows of ``simulate_truth``), with r = ref_height_px / height_px:
      * each keypoint is displaced by Gaussian pixel error with sd
        pixel_sigma + height_px * (rel_sigma + p * noise_sigma_gain * (1 + r));
      * with probability outlier_base + p * outlier_noise_gain it is a gross outlier,
        displaced by a large fraction of the body height in a random direction;
      * it is missed (u = v = conf = 0) with probability
        miss_base + miss_far * r + p * miss_noise_gain * (1 + r) (at most miss_max), and always
        when its true projection lies outside the image;
      * its confidence falls with r, with p and with the size of its own error;
      * the whole detection is missed with probability
        det_miss_base + det_miss_far * r + p * det_miss_noise_gain * (1 + r) (at most
        det_miss_max), or when fewer than ``min_keypoints`` keypoints survive.
    Detected positions are clipped to the image; the box is the detected keypoints' extent
    grown by ``box_margin``. The random draws have shapes independent of p and p only scales
    them, so one generator state gives coupled observations across noise levels.

    Returns records (``drfkit.data.records``) of the detected rows, noise = the noise's level.
    """
    config = DetectorConfig() if config is None else DetectorConfig.from_dict(config)
    corruption = pedestrian_corruption(noise, "the simulated detector")
    p = float(corruption.strain(noise.level))
    if not isinstance(rng, np.random.Generator):
        raise TypeError(f"rng must be a numpy Generator (np.random.default_rng(seed)), got {type(rng).__name__}")
    for name in ("keypoints_px", "in_image", "height_px", "position", "intrinsics", "track_id"):
        if name not in truth:
            raise ValueError(f"truth misses {name!r}; pass the output of simulate_truth")
    c = config
    true_px = truth["keypoints_px"].astype(np.float64)  # (M,17,2)
    m = len(true_px)

    # Every draw first, with p-independent shapes (the coupling across noise levels).
    z_xy = rng.standard_normal((m, N_KEYPOINTS, 2))
    u_miss = rng.random((m, N_KEYPOINTS))
    z_conf = rng.standard_normal((m, N_KEYPOINTS))
    u_out = rng.random((m, N_KEYPOINTS))
    out_angle = rng.uniform(0.0, 2 * np.pi, (m, N_KEYPOINTS))
    out_mag = rng.uniform(0.3, 1.0, (m, N_KEYPOINTS))
    u_det = rng.random(m)

    h_px = truth["height_px"].astype(np.float64)[:, None]  # (M,1)
    r = c.ref_height_px / np.maximum(h_px, 1e-6)
    strain = p * (1.0 + r)  # how hard the noise hits a person of this size
    sigma = c.pixel_sigma + h_px * (c.rel_sigma + c.noise_sigma_gain * strain)  # (M,1)
    uv = true_px + sigma[..., None] * z_xy
    outlier = u_out < (c.outlier_base + c.outlier_noise_gain * p)
    offset = (h_px * c.outlier_scale)[..., None] * out_mag[..., None] * np.stack(
        [np.cos(out_angle), np.sin(out_angle)], axis=-1)
    uv = np.where(outlier[..., None], uv + offset, uv)
    uv[..., 0] = np.clip(uv[..., 0], 0.0, IMAGE_WIDTH - 1.0)
    uv[..., 1] = np.clip(uv[..., 1], 0.0, IMAGE_HEIGHT - 1.0)

    p_miss = np.minimum(c.miss_base + c.miss_far * r + c.miss_noise_gain * strain, c.miss_max)
    detected = (u_miss >= p_miss) & truth["in_image"]
    conf = c.conf_base - c.conf_far * r - c.conf_noise_gain * strain + c.conf_sd * z_conf \
        - c.conf_error_drop * np.sum(z_xy**2, axis=-1)
    conf = np.clip(conf, c.conf_min, 1.0)
    keypoints = np.where(detected[..., None], np.concatenate([uv, conf[..., None]], axis=-1), 0.0)

    p_det_miss = np.minimum(c.det_miss_base + c.det_miss_far * r[:, 0] + c.det_miss_noise_gain * strain[:, 0],
                            c.det_miss_max)
    keep = (u_det >= p_det_miss) & (detected.sum(axis=1) >= c.min_keypoints)

    kp = keypoints[keep]
    if corruption.keypoints is not None:  # after every draw above, so the detector's own draws stay coupled
        kp = np.where(detected[keep][..., None], corruption.keypoints(kp.astype(np.float32), noise.level, rng), 0.0)
    det = detected[keep]
    u_min, u_max = np.where(det, kp[..., 0], np.inf).min(axis=1), np.where(det, kp[..., 0], -np.inf).max(axis=1)
    v_min, v_max = np.where(det, kp[..., 1], np.inf).min(axis=1), np.where(det, kp[..., 1], -np.inf).max(axis=1)
    w, h = u_max - u_min, v_max - v_min
    box = np.stack([u_min - c.box_margin * w, v_min - c.box_margin * h,
                    (1 + 2 * c.box_margin) * w, (1 + 2 * c.box_margin) * h], axis=-1)

    position = truth["position"][keep].astype(np.float32)
    rec = {
        "keypoints": kp.astype(np.float32),
        "intrinsics": truth["intrinsics"][keep].astype(np.float32),
        "position": position,
        "depth": position[:, 2].copy(),
        "distance": np.linalg.norm(position, axis=1).astype(np.float32),
        "box": box.astype(np.float32),
        "track_id": truth["track_id"][keep].astype(np.int64),
        "scene_id": truth["scene_id"][keep].astype(np.int64),
        "timestamp": truth["timestamp"][keep].astype(np.int64),
        "image_id": truth["image_id"][keep].astype(np.int64),
        "noise": np.full(int(keep.sum()), noise.level, dtype=np.float32),
    }
    check_records(rec)
    return rec


def simulate_records(
    truth: Mapping[str, np.ndarray],
    noise: Noise,
    seed: int = 0,
    config: DetectorConfig | Mapping[str, Any] | None = None,
) -> dict[str, np.ndarray]:
    """Observe the simulated people under ``noise`` (salt-and-pepper, or a kind registered in
    ``drfkit.data.noise.PEDESTRIAN_CORRUPTIONS``; see ``detect``).

    The detector's generator depends on ``seed`` only, so calls with the same truth and seed
    at different levels see the same people with coupled detector randomness.
    """
    check_int(seed, "seed", 0)
    rng = np.random.default_rng(np.random.SeedSequence([seed, 11]))
    return detect(truth, noise, rng, DetectorConfig.from_dict(config))
