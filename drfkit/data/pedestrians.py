"""A simulated nuScenes-like pedestrian data set, and the entry point for both sources.

Why a simulation: the paper uses nuScenes images and PifPaf keypoints, which need a
licence-gated download and a GPU keypoint detector. The simulation keeps what matters for
the study -- tracks of walking people seen at 2 Hz by a moving front camera, keypoints
whose quality drops with salt-and-pepper noise and with distance -- and produces records in
the same format as the real loader (``drfkit.data.nuscenes``), so everything downstream
runs on either.

The world
---------
* Camera: nuScenes CAM_FRONT intrinsics (fx = fy = 1266.417, cx = 816.267, cy = 491.507),
  1600 x 900 pixels, 1.5 m above a flat road, looking straight ahead (no pitch); camera
  frame x right, y down, z forward.
* Ego vehicle: per scene a speed drawn from ``ego_speed_range`` (default 0-12 m/s) with a
  small constant acceleration, and a gentle constant yaw rate (sd 0.04 rad/s).
* Keyframes every 0.5 s (2 Hz), ``frames_per_scene`` per scene.
* Pedestrians: height ~ N(1.72, 0.09) clipped to [1.5, 1.95] m; 15 % stand still, the
  others walk at U(1.0, 1.8) m/s along the road (55 %), across it (30 %) or in any direction
  (15 %), and turn now and then (probability ``turn_prob`` per keyframe, turn ~ N(0, 0.8 rad)).
  Each is placed at a random keyframe at a depth in ``spawn_depth_range`` inside the field
  of view and walks forwards and backwards in time from there, so people enter and leave
  the view. A pedestrian is *recorded* at a keyframe only while its box centre projects
  inside the image and ``min_depth`` < depth <= ``max_depth`` (defaults 1 m and 50 m).
* Skeleton: the 17 COCO keypoints of a stick body with body proportions scaled by height,
  a walking gait (legs and arms swing in opposition, knees flex during swing) whose phase
  advances with distance walked (stride = 0.83 x height), rotated by the walking heading and
  projected with the intrinsics.

Default sizes follow the paper's "about 3300 images with about 3700 pedestrian instances":
165 scenes x 20 keyframes = 3300 images, and ``pedestrians_per_scene`` = 23 spawned people
per scene give about 3780 distinct recorded tracks (seeds 0-2; the tests check 3400-4000),
of which about 99.6 % are detected at least once at p = 0.01; about 33 000 pedestrian-keyframe
records at p = 0.01, mean depth 28 m. A track here is one person
seen by the one camera; it may leave and re-enter the view (``make_sequences`` breaks it at
such gaps).

The detector (``detect``)
-------------------------
**This stands in for PifPaf run on salt-and-pepper-noised images.** It does not look at
pixels: it perturbs the true projected keypoints with errors that grow with the noise
probability p and with distance (people small in pixels suffer more), see ``detect``.

Coupling across noise levels: ``simulate_records(truth, p, seed, config)`` draws every
random number with shapes that do not depend on p, from a generator seeded by ``seed``
alone, and p only scales them. The same seed at p = 0.01, 0.025, 0.05 therefore observes the
same people with the same "luck": each keypoint's Gaussian error grows monotonically with p,
confidences only fall, and the sets of outliers, missed keypoints and missed detections only
grow.
"""
from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from drfkit.data.records import COCO_KEYPOINTS, N_KEYPOINTS, RECORD_FIELDS, check_records

# Bump when the simulation or detector changes behaviour, so cached files are rebuilt.
SIMULATOR_VERSION = 1

IMAGE_WIDTH = 1600
IMAGE_HEIGHT = 900
FX = FY = 1266.417
CX, CY = 816.267, 491.507
CAM_FRONT_INTRINSICS = np.array([[FX, 0.0, CX], [0.0, FY, CY], [0.0, 0.0, 1.0]])
KEYFRAME_DT_S = 0.5
TIMESTAMP_ORIGIN_US = 1_533_000_000_000_000  # an arbitrary 2018 epoch, like nuScenes
SCENE_TIME_SPACING_US = 3_600_000_000  # scenes an hour apart, so timestamps never collide

# COCO skeleton edges (0-based keypoint indices) used for drawing.
COCO_SKELETON = (
    (15, 13), (13, 11), (16, 14), (14, 12), (11, 12), (5, 11), (6, 12), (5, 6),
    (5, 7), (6, 8), (7, 9), (8, 10), (1, 2), (0, 1), (0, 2), (1, 3), (2, 4), (3, 5), (4, 6),
)

# Body proportions as fractions of standing height, (forward, left, up) from the ground
# point between the feet. Limbs are built from these by the gait in ``_body_keypoints``.
_HEAD = np.array([
    [0.055, 0.0, 0.925],     # nose
    [0.045, 0.03, 0.94],     # left eye
    [0.045, -0.03, 0.94],    # right eye
    [-0.005, 0.07, 0.93],    # left ear
    [-0.005, -0.07, 0.93],   # right ear
])
_SHOULDER_HALF_WIDTH, _SHOULDER_HEIGHT = 0.125, 0.815
_HIP_HALF_WIDTH, _HIP_HEIGHT = 0.085, 0.52
_UPPER_ARM, _FOREARM = 0.17, 0.16
_THIGH, _SHANK = 0.245, 0.245
_ANKLE_HEIGHT = 0.035  # ankle joint above the ground, standing foot
_STRIDE_PER_HEIGHT = 0.83


# --------------------------------------------------------------------------- ground truth
def simulate_truth(
    n_scenes: int = 165,
    frames_per_scene: int = 20,
    seed: int = 0,
    *,
    pedestrians_per_scene: int = 23,
    spawn_depth_range: tuple[float, float] = (3.0, 50.0),
    min_depth: float = 1.0,
    max_depth: float = 50.0,
    ego_speed_range: tuple[float, float] = (0.0, 12.0),
    standing_fraction: float = 0.15,
    turn_prob: float = 0.05,
    camera_height: float = 1.5,
) -> dict[str, np.ndarray]:
    """Simulate scenes and return the ground truth of every recorded pedestrian-keyframe.

    Returns a dict of arrays with one row per (pedestrian, keyframe) in which the person is
    recorded (box centre inside the image, ``min_depth`` < depth <= ``max_depth``), rows
    ordered by scene, track, time (M rows):
      'skeleton' float32 (M,17,3) COCO keypoints in the camera frame (m);
      'keypoints_px' float32 (M,17,2) their projections (u, v) in pixels;
      'in_image' bool (M,17) projection inside the image and in front of the camera;
      'position' float32 (M,3) 3D box centre in the camera frame; 'depth', 'distance' (M,);
      'intrinsics' float32 (M,3,3); 'height' (M,) m; 'height_px' (M,) = fy * height / depth;
      'speed' (M,) m/s; 'heading' (M,) walking direction relative to the camera's forward
      axis (rad, positive to the left);
      'track_id', 'scene_id', 'timestamp' (us), 'image_id' int64 (M,);
      'n_images' int64 (1,) the number of simulated images (keyframes), with or without people.
    Deterministic for a seed.
    """
    _check_int(n_scenes, "n_scenes", 1)
    _check_int(frames_per_scene, "frames_per_scene", 1)
    _check_int(pedestrians_per_scene, "pedestrians_per_scene", 1)
    _check_int(seed, "seed", 0)
    lo, hi = spawn_depth_range
    if not 0 < lo < hi:
        raise ValueError(f"spawn_depth_range must be (low, high) with 0 < low < high, got {spawn_depth_range}")
    if not 0 <= min_depth < max_depth:
        raise ValueError(f"need 0 <= min_depth < max_depth, got {min_depth}, {max_depth}")
    if not 0 <= ego_speed_range[0] <= ego_speed_range[1]:
        raise ValueError(f"ego_speed_range must be (low, high) with 0 <= low <= high, got {ego_speed_range}")
    for name, value in (("standing_fraction", standing_fraction), ("turn_prob", turn_prob)):
        if not 0 <= value <= 1:
            raise ValueError(f"{name} must lie in [0, 1], got {value}")
    if not camera_height > 0:
        raise ValueError(f"camera_height must be positive, got {camera_height}")

    rng_ego, rng_ped = (np.random.default_rng(s) for s in np.random.SeedSequence([seed, 7]).spawn(2))
    n_frames, dt = frames_per_scene, KEYFRAME_DT_S
    t = np.arange(n_frames) * dt  # (F,)

    # Ego trajectory per scene (S, F): speed with a gentle drift, constant yaw rate.
    v0 = rng_ego.uniform(*ego_speed_range, size=(n_scenes, 1))
    accel = rng_ego.normal(0.0, 0.3, size=(n_scenes, 1))
    yaw_rate = rng_ego.normal(0.0, 0.04, size=(n_scenes, 1))
    ego_speed = np.clip(v0 + accel * t, 0.0, max(ego_speed_range[1], 0.0) * 1.25)
    ego_yaw = yaw_rate * t
    mid_yaw = ego_yaw + 0.5 * yaw_rate * dt  # heading at the middle of each step
    step = ego_speed * dt
    ego_xy = np.zeros((n_scenes, n_frames, 2))
    ego_xy[:, 1:, 0] = np.cumsum(step * np.cos(mid_yaw), axis=1)[:, :-1]
    ego_xy[:, 1:, 1] = np.cumsum(step * np.sin(mid_yaw), axis=1)[:, :-1]

    # Pedestrians (P = S * per scene), all drawn whatever is later visible.
    per = pedestrians_per_scene
    n_ped = n_scenes * per
    scene_of = np.repeat(np.arange(n_scenes), per)
    height = np.clip(rng_ped.normal(1.72, 0.09, size=n_ped), 1.5, 1.95)
    standing = rng_ped.random(n_ped) < standing_fraction
    speed = np.where(standing, 0.0, rng_ped.uniform(1.0, 1.8, size=n_ped))
    spawn_frame = rng_ped.integers(0, n_frames, size=n_ped)
    spawn_depth = rng_ped.uniform(lo, hi, size=n_ped)
    half_fov = CX / FX  # tan of the half horizontal field of view
    spawn_lateral = rng_ped.uniform(-1.0, 1.0, size=n_ped) * spawn_depth * half_fov
    kind = rng_ped.random(n_ped)
    along = kind < 0.55
    across = (kind >= 0.55) & (kind < 0.85)
    base = ego_yaw[scene_of, spawn_frame]
    heading0 = np.where(
        along,
        base + np.pi * rng_ped.integers(0, 2, size=n_ped) + rng_ped.normal(0, 0.2, size=n_ped),
        np.where(
            across,
            base + np.pi * (rng_ped.integers(0, 2, size=n_ped) - 0.5) + rng_ped.normal(0, 0.3, size=n_ped),
            rng_ped.uniform(-np.pi, np.pi, size=n_ped),
        ),
    )
    turns = np.where(rng_ped.random((n_ped, n_frames)) < turn_prob, rng_ped.normal(0, 0.8, (n_ped, n_frames)), 0.0)
    turns[:, 0] = 0.0
    heading = heading0[:, None] + np.cumsum(turns + rng_ped.normal(0, 0.05, (n_ped, n_frames)), axis=1)
    phase0 = rng_ped.uniform(0, 2 * np.pi, size=n_ped)

    # Walk: displacement from frame 0, then shift so the person is at its spawn point at spawn_frame.
    walk_step = (speed * dt)[:, None]
    disp = np.zeros((n_ped, n_frames, 2))
    disp[:, 1:, 0] = np.cumsum(walk_step * np.cos(heading), axis=1)[:, :-1]
    disp[:, 1:, 1] = np.cumsum(walk_step * np.sin(heading), axis=1)[:, :-1]
    cam_xy_spawn = ego_xy[scene_of, spawn_frame]
    yaw_spawn = ego_yaw[scene_of, spawn_frame]
    spawn_xy = cam_xy_spawn + spawn_depth[:, None] * np.stack([np.cos(yaw_spawn), np.sin(yaw_spawn)], -1) \
        + spawn_lateral[:, None] * np.stack([np.sin(yaw_spawn), -np.cos(yaw_spawn)], -1)
    ped_xy = spawn_xy[:, None, :] - disp[np.arange(n_ped), spawn_frame][:, None, :] + disp  # (P, F, 2)
    gait_phase = phase0[:, None] + 2 * np.pi * np.arange(n_frames) * (walk_step / (_STRIDE_PER_HEIGHT * height[:, None]))

    # Ground point in the camera frame (camera at the ego position; x right, z forward).
    rel = ped_xy - ego_xy[scene_of]  # (P, F, 2)
    yaw = ego_yaw[scene_of]
    cos_y, sin_y = np.cos(yaw), np.sin(yaw)
    ground_z = rel[..., 0] * cos_y + rel[..., 1] * sin_y
    ground_x = rel[..., 0] * sin_y - rel[..., 1] * cos_y
    centre_y = camera_height - 0.5 * height[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        u_c = FX * ground_x / ground_z + CX
        v_c = FY * centre_y / ground_z + CY
    recorded = (ground_z > min_depth) & (ground_z <= max_depth) & (u_c >= 0) & (u_c < IMAGE_WIDTH) \
        & (v_c >= 0) & (v_c < IMAGE_HEIGHT)
    ped_idx, frame_idx = np.nonzero(recorded)  # row-major: ordered by pedestrian, then time
    m = len(ped_idx)
    if m == 0:
        raise ValueError("the simulation recorded no pedestrian; use more scenes or pedestrians_per_scene")

    rel_heading = heading[ped_idx, frame_idx] - yaw[ped_idx, frame_idx]
    body = _body_keypoints(height[ped_idx], speed[ped_idx], gait_phase[ped_idx, frame_idx])  # (M,17,3) f,l,up
    cos_h, sin_h = np.cos(rel_heading)[:, None], np.sin(rel_heading)[:, None]
    fwd, left, up = body[..., 0], body[..., 1], body[..., 2]
    # Ego frame (x forward, y left): offset = f (cos h, sin h) + l (-sin h, cos h); camera x = -y_ego.
    cam_dz = fwd * cos_h - left * sin_h
    cam_dx = -(fwd * sin_h + left * cos_h)
    gx, gz = ground_x[ped_idx, frame_idx][:, None], ground_z[ped_idx, frame_idx][:, None]
    skeleton = np.stack([gx + cam_dx, camera_height - up, gz + cam_dz], axis=-1)  # (M,17,3)
    z_safe = np.maximum(skeleton[..., 2], 1e-3)
    kp_px = np.stack([FX * skeleton[..., 0] / z_safe + CX, FY * skeleton[..., 1] / z_safe + CY], axis=-1)
    in_image = (skeleton[..., 2] > 0.1) & (kp_px[..., 0] >= 0) & (kp_px[..., 0] < IMAGE_WIDTH) \
        & (kp_px[..., 1] >= 0) & (kp_px[..., 1] < IMAGE_HEIGHT)

    position = np.stack([gx[:, 0], centre_y[ped_idx, 0], gz[:, 0]], axis=-1)
    scene_id = scene_of[ped_idx]
    return {
        "skeleton": skeleton.astype(np.float32),
        "keypoints_px": kp_px.astype(np.float32),
        "in_image": in_image,
        "position": position.astype(np.float32),
        "depth": position[:, 2].astype(np.float32),
        "distance": np.linalg.norm(position.astype(np.float32), axis=1).astype(np.float32),
        "intrinsics": np.broadcast_to(CAM_FRONT_INTRINSICS.astype(np.float32), (m, 3, 3)).copy(),
        "height": height[ped_idx].astype(np.float32),
        "height_px": (FY * height[ped_idx] / position[:, 2]).astype(np.float32),
        "speed": speed[ped_idx].astype(np.float32),
        "heading": np.angle(np.exp(1j * rel_heading)).astype(np.float32),
        "track_id": ped_idx.astype(np.int64),
        "scene_id": scene_id.astype(np.int64),
        "timestamp": (TIMESTAMP_ORIGIN_US + scene_id * SCENE_TIME_SPACING_US
                      + frame_idx * int(KEYFRAME_DT_S * 1e6)).astype(np.int64),
        "image_id": (scene_id * n_frames + frame_idx).astype(np.int64),
        "n_images": np.array([n_scenes * n_frames], dtype=np.int64),
    }


def _body_keypoints(height: np.ndarray, speed: np.ndarray, phase: np.ndarray) -> np.ndarray:
    """COCO keypoints of walking bodies in the body frame (forward, left, up), metres.

    height, speed, phase: (M,). Legs swing by +-0.45 rad at 1.4 m/s (scaled with speed,
    zero when standing), arms by +-0.35 rad in opposition, knees flex during the swing;
    the body is lowered so that the lower ankle stays 3.5 % of the height above the road.
    Returns (M, 17, 3).
    """
    m = len(height)
    gait = np.clip(speed / 1.4, 0.0, 1.3)
    leg_amp, arm_amp, knee_amp = 0.45 * gait, 0.35 * gait, 0.6 * gait
    s, c = np.sin(phase), np.cos(phase)
    out = np.zeros((m, N_KEYPOINTS, 3))
    out[:, :5] = _HEAD[None]
    for side, sign in ((0, 1.0), (1, -1.0)):  # left = 0, right = 1
        lateral = sign  # left keypoints on +left
        swing = sign * s  # left and right legs in opposition
        hip_angle = leg_amp * swing
        knee_flex = knee_amp * np.maximum(0.0, sign * c)
        arm_angle = -arm_amp * swing  # arms opposite to the legs
        elbow_flex = 0.15 + 0.8 * np.maximum(arm_angle, 0.0)
        shoulder = np.stack([np.zeros(m), np.full(m, lateral * _SHOULDER_HALF_WIDTH), np.full(m, _SHOULDER_HEIGHT)], -1)
        hip = np.stack([np.zeros(m), np.full(m, lateral * _HIP_HALF_WIDTH), np.full(m, _HIP_HEIGHT)], -1)
        elbow = shoulder + _UPPER_ARM * _limb(arm_angle)
        wrist = elbow + _FOREARM * _limb(arm_angle + elbow_flex)
        knee = hip + _THIGH * _limb(hip_angle)
        ankle = knee + _SHANK * _limb(hip_angle - knee_flex)
        out[:, 5 + side] = shoulder
        out[:, 7 + side] = elbow
        out[:, 9 + side] = wrist
        out[:, 11 + side] = hip
        out[:, 13 + side] = knee
        out[:, 15 + side] = ankle
    # Stance foot on the ground: the body drops while the legs are spread (the natural bob).
    out[..., 2] -= (np.minimum(out[:, 15, 2], out[:, 16, 2]) - _ANKLE_HEIGHT)[:, None]
    return out * height[:, None, None]


def _limb(angle: np.ndarray) -> np.ndarray:
    """Unit vector hanging down, rotated forward by ``angle`` in the sagittal plane: (M, 3)."""
    return np.stack([np.sin(angle), np.zeros_like(angle), -np.cos(angle)], axis=-1)


# --------------------------------------------------------------------------- the detector
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
    p: float,
    rng: np.random.Generator,
    config: DetectorConfig | None = None,
) -> dict[str, np.ndarray]:
    """Simulated PifPaf on images with salt-and-pepper probability p: truth -> records.

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

    Returns records (``drfkit.data.records``) of the detected rows, noise_p = p.
    """
    config = DetectorConfig() if config is None else DetectorConfig.from_dict(config)
    if isinstance(p, bool) or not isinstance(p, (int, float, np.integer, np.floating)) or not 0 <= p <= 1:
        raise ValueError(f"p (salt-and-pepper probability) must be a number in [0, 1], got {p!r}")
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
    noise = p * (1.0 + r)
    sigma = c.pixel_sigma + h_px * (c.rel_sigma + c.noise_sigma_gain * noise)  # (M,1)
    uv = true_px + sigma[..., None] * z_xy
    outlier = u_out < (c.outlier_base + c.outlier_noise_gain * p)
    offset = (h_px * c.outlier_scale)[..., None] * out_mag[..., None] * np.stack(
        [np.cos(out_angle), np.sin(out_angle)], axis=-1)
    uv = np.where(outlier[..., None], uv + offset, uv)
    uv[..., 0] = np.clip(uv[..., 0], 0.0, IMAGE_WIDTH - 1.0)
    uv[..., 1] = np.clip(uv[..., 1], 0.0, IMAGE_HEIGHT - 1.0)

    p_miss = np.minimum(c.miss_base + c.miss_far * r + c.miss_noise_gain * noise, c.miss_max)
    detected = (u_miss >= p_miss) & truth["in_image"]
    conf = c.conf_base - c.conf_far * r - c.conf_noise_gain * noise + c.conf_sd * z_conf \
        - c.conf_error_drop * np.sum(z_xy**2, axis=-1)
    conf = np.clip(conf, c.conf_min, 1.0)
    keypoints = np.where(detected[..., None], np.concatenate([uv, conf[..., None]], axis=-1), 0.0)

    p_det_miss = np.minimum(c.det_miss_base + c.det_miss_far * r[:, 0] + c.det_miss_noise_gain * noise[:, 0],
                            c.det_miss_max)
    keep = (u_det >= p_det_miss) & (detected.sum(axis=1) >= c.min_keypoints)

    kp = keypoints[keep]
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
        "noise_p": np.full(int(keep.sum()), p, dtype=np.float32),
    }
    check_records(rec)
    return rec


def simulate_records(
    truth: Mapping[str, np.ndarray],
    p: float,
    seed: int = 0,
    config: DetectorConfig | Mapping[str, Any] | None = None,
) -> dict[str, np.ndarray]:
    """Observe the simulated people at salt-and-pepper probability p (see ``detect``).

    The detector's generator depends on ``seed`` only, so calls with the same truth and seed
    at different p see the same people with coupled detector randomness.
    """
    _check_int(seed, "seed", 0)
    rng = np.random.default_rng(np.random.SeedSequence([seed, 11]))
    return detect(truth, p, rng, DetectorConfig.from_dict(config))


# --------------------------------------------------------------------------- entry point
def noise_dir_name(noise_p: float) -> str:
    """Folder name of one noise level's PifPaf predictions: 'p0.025' for 0.025 (``f'p{p:g}'``)."""
    return f"p{float(noise_p):g}"


def load_pedestrians(
    cache_dir: str | os.PathLike,
    source: str,
    noise_p: float,
    *,
    n_scenes: int = 165,
    frames_per_scene: int = 20,
    seed: int = 0,
    detector: DetectorConfig | Mapping[str, Any] | None = None,
    nuscenes_root: str | os.PathLike | None = None,
    predictions_root: str | os.PathLike | None = None,
    nuscenes_version: str = "v1.0-mini",
    cameras: tuple[str, ...] | None = None,
    simulation: Mapping[str, Any] | None = None,
) -> dict[str, np.ndarray]:
    """Pedestrian records at salt-and-pepper probability ``noise_p`` from either source.

    source='simulated': ``simulate_truth(n_scenes, frames_per_scene, seed, **simulation)``
    observed by ``simulate_records(truth, noise_p, seed, detector)``, cached as
    ``<cache_dir>/pedestrians-sim-<hash>.npz`` with every parameter in the hash.
    source='nuscenes': ``drfkit.data.nuscenes.load_nuscenes_records`` reading the tables
    under ``nuscenes_root`` and PifPaf predictions from ``<predictions_root>/p<noise_p>/``
    (``noise_dir_name``, e.g. ``p0.025``); the simulation arguments are ignored, and
    nothing is cached (the files on disk are the source of truth).
    Both return records that pass ``check_records``.
    """
    from drfkit.io import cached_npz

    if source == "simulated":
        detector = DetectorConfig.from_dict(detector)
        simulation = dict(simulation or {})
        if not isinstance(noise_p, (int, float, np.integer, np.floating)) or not 0 <= noise_p <= 1:
            raise ValueError(f"noise_p must be a number in [0, 1], got {noise_p!r}")
        params = {
            "source": source, "noise_p": float(noise_p), "n_scenes": n_scenes,
            "frames_per_scene": frames_per_scene, "seed": seed, "detector": detector.to_dict(),
            "simulation": simulation, "simulator_version": SIMULATOR_VERSION,
        }

        def build() -> dict[str, np.ndarray]:
            truth = simulate_truth(n_scenes, frames_per_scene, seed, **simulation)
            return simulate_records(truth, float(noise_p), seed, detector)

        rec = cached_npz(cache_dir, "pedestrians-sim", params, build)
    elif source == "nuscenes":
        from drfkit.data import nuscenes

        if nuscenes_root is None or predictions_root is None:
            raise ValueError(
                "source='nuscenes' needs nuscenes_root (folder holding '<version>/' tables and "
                "'samples/') and predictions_root (folder with one PifPaf output folder per noise "
                "level, named like 'p0.025')"
            )
        from pathlib import Path

        rec = nuscenes.load_nuscenes_records(
            nuscenes_root, Path(predictions_root) / noise_dir_name(noise_p), noise_p,
            version=nuscenes_version, cameras=tuple(cameras or nuscenes.DEFAULT_CAMERAS),
        )
    else:
        raise ValueError(f"source must be 'simulated' or 'nuscenes', got {source!r}")
    check_records(rec)
    return rec


# --------------------------------------------------------------------------- pictures
def render_frame(
    truth_or_records: Mapping[str, np.ndarray],
    image_id: int,
    p: float,
    seed: int = 0,
) -> np.ndarray:
    """A synthetic RGB camera image of one keyframe with salt-and-pepper noise at p.

    Sky and road gradients with lane lines converging at the horizon, and each pedestrian
    of ``image_id`` as a filled stick figure (thickness scaled with its size, farthest
    drawn first). Takes simulated truth (uses the true skeleton) or records (uses the
    detected keypoints). Returns uint8 (900, 1600, 3), RGB. Only for showing noise levels;
    nothing is trained on these pixels.
    """
    import cv2

    from drfkit.data.noise import salt_and_pepper

    ids = truth_or_records["image_id"]
    if not np.any(ids == image_id):
        raise ValueError(f"image_id {image_id} has no pedestrian in the given data; pick one of np.unique(data['image_id'])")
    img = _background()
    rows = np.flatnonzero(ids == image_id)
    rows = rows[np.argsort(-truth_or_records["depth"][rows])]  # painter's order: far first
    if "keypoints_px" in truth_or_records:
        kps = np.concatenate([truth_or_records["keypoints_px"][rows],
                              truth_or_records["in_image"][rows][..., None].astype(np.float32)], axis=-1)
    else:
        kps = truth_or_records["keypoints"][rows]
    depth = truth_or_records["depth"][rows]
    for kp, z, track in zip(kps, depth, truth_or_records["track_id"][rows]):
        colour = _track_colour(int(track))
        thickness = max(1, int(round(0.09 * FY / max(float(z), 0.5))))  # ~9 cm limbs
        ok = kp[:, 2] > 0
        pts = np.round(kp[:, :2]).astype(np.int32)
        for a, b in COCO_SKELETON:
            if ok[a] and ok[b]:
                cv2.line(img, tuple(int(x) for x in pts[a]), tuple(int(x) for x in pts[b]), colour, thickness, cv2.LINE_AA)
        torso = [i for i in (5, 6, 12, 11) if ok[i]]
        if len(torso) == 4:
            cv2.fillConvexPoly(img, pts[torso], colour, cv2.LINE_AA)
        head = [i for i in range(5) if ok[i]]
        if head:
            centre = pts[head].mean(axis=0).astype(int)
            cv2.circle(img, (int(centre[0]), int(centre[1])), max(2, int(round(0.11 * FY / max(float(z), 0.5)))),
                       colour, -1, cv2.LINE_AA)
    return salt_and_pepper(img, float(p), np.random.default_rng(np.random.SeedSequence([seed, int(image_id), 3])))


def _background() -> np.ndarray:
    """Sky gradient above the horizon (v = cy), grey road below with lane lines: (900,1600,3) uint8."""
    import cv2

    v = np.arange(IMAGE_HEIGHT, dtype=np.float64)[:, None]
    horizon = int(round(CY))
    sky_t = np.clip(v / horizon, 0, 1)
    sky = (1 - sky_t) * np.array([90, 140, 215]) + sky_t * np.array([200, 220, 240])
    road_t = np.clip((v - horizon) / (IMAGE_HEIGHT - horizon), 0, 1)
    road = (1 - road_t) * np.array([150, 150, 150]) + road_t * np.array([75, 75, 80])
    column = np.where(v < horizon, sky, road)  # (H, 3)
    img = np.ascontiguousarray(np.broadcast_to(column[:, None, :], (IMAGE_HEIGHT, IMAGE_WIDTH, 3))).astype(np.uint8)
    for lateral in (-5.4, -1.8, 1.8, 5.4):  # lane lines 3.6 m apart, on the road 1.5 m below the camera
        z_near, z_far = 1.5 * FY / (IMAGE_HEIGHT - CY), 400.0
        p_near = (int(CX + FX * lateral / z_near), IMAGE_HEIGHT - 1)
        p_far = (int(CX + FX * lateral / z_far), int(CY + FY * 1.5 / z_far))
        cv2.line(img, p_near, p_far, (235, 235, 235), 3, cv2.LINE_AA)
    return img


def _track_colour(track: int) -> tuple[int, int, int]:
    rng = np.random.default_rng(track)
    return tuple(int(x) for x in rng.integers(30, 200, size=3))


def draw_skeletons(
    image: np.ndarray,
    keypoints: np.ndarray,
    colour: tuple[int, int, int] = (255, 40, 40),
    thickness: int = 2,
    min_conf: float = 0.0,
) -> np.ndarray:
    """Draw COCO skeletons on a copy of ``image`` (uint8 (H, W, 3)).

    keypoints: (17, 3) or (N, 17, 3) pixel u, v, conf (a keypoint is drawn when
    conf > min_conf), or (17, 2)/(N, 17, 2) positions that are all drawn. Returns the copy.
    """
    import cv2

    image = np.asarray(image)
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
        raise ValueError(f"image must be uint8 (H, W, 3), got {image.dtype} {image.shape}")
    kps = np.asarray(keypoints, dtype=np.float64)
    if kps.ndim == 2:
        kps = kps[None]
    if kps.ndim != 3 or kps.shape[1] != N_KEYPOINTS or kps.shape[2] not in (2, 3):
        raise ValueError(f"keypoints must have shape (17, 3), (N, 17, 3), (17, 2) or (N, 17, 2), got {np.shape(keypoints)}")
    if kps.shape[2] == 2:
        kps = np.concatenate([kps, np.ones(kps.shape[:2] + (1,))], axis=-1)
    out = np.ascontiguousarray(image.copy())
    for kp in kps:
        ok = np.isfinite(kp).all(axis=1) & (kp[:, 2] > min_conf)
        pts = np.round(np.where(np.isfinite(kp[:, :2]), kp[:, :2], 0)).astype(int)
        for a, b in COCO_SKELETON:
            if ok[a] and ok[b]:
                cv2.line(out, (int(pts[a, 0]), int(pts[a, 1])), (int(pts[b, 0]), int(pts[b, 1])), colour, thickness, cv2.LINE_AA)
        for i in np.flatnonzero(ok):
            cv2.circle(out, (int(pts[i, 0]), int(pts[i, 1])), thickness + 1, colour, -1, cv2.LINE_AA)
    return out


def _check_int(value, name: str, minimum: int) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be an integer, got {value!r}")
    if value < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {value}")


__all__ = [
    "COCO_KEYPOINTS", "COCO_SKELETON", "CAM_FRONT_INTRINSICS", "DetectorConfig", "RECORD_FIELDS",
    "detect", "draw_skeletons", "load_pedestrians", "noise_dir_name", "render_frame",
    "simulate_records", "simulate_truth",
]
