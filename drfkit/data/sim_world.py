"""The simulated world of the pedestrian study: camera, ego vehicle, walking people, their
skeletons -- the ground truth that the simulated detector (``drfkit.data.sim_detector``) observes.

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
"""
from __future__ import annotations

import numpy as np

from drfkit.data.records import N_KEYPOINTS

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
    check_int(n_scenes, "n_scenes", 1)
    check_int(frames_per_scene, "frames_per_scene", 1)
    check_int(pedestrians_per_scene, "pedestrians_per_scene", 1)
    check_int(seed, "seed", 0)
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


def check_int(value, name: str, minimum: int) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be an integer, got {value!r}")
    if value < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {value}")

