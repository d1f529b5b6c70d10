"""Pictures of the simulated pedestrians: a synthetic camera frame at a noise level, and
skeletons drawn over an image. Only for showing the data; nothing is trained on these pixels."""
from __future__ import annotations

from typing import Mapping

import numpy as np

from drfkit.data.noise import Noise, pedestrian_corruption
from drfkit.data.records import N_KEYPOINTS
from drfkit.data.sim_world import COCO_SKELETON, CX, CY, FX, FY, IMAGE_HEIGHT, IMAGE_WIDTH


def render_frame(
    truth_or_records: Mapping[str, np.ndarray],
    image_id: int,
    p: "float | Noise",
    seed: int = 0,
) -> np.ndarray:
    """A synthetic RGB camera image of one keyframe under noise ``p``: a ``Noise`` of a kind with a
    pedestrian corruption (``drfkit.data.noise.PEDESTRIAN_CORRUPTIONS``), or a number, salt-and-pepper's p.

    Sky and road gradients with lane lines converging at the horizon, and each pedestrian
    of ``image_id`` as a filled stick figure (thickness scaled with its size, farthest
    drawn first). Takes simulated truth (uses the true skeleton) or records (uses the
    detected keypoints). Returns uint8 (900, 1600, 3), RGB. Only for showing noise levels;
    nothing is trained on these pixels.
    """
    import cv2

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
    noise = p if isinstance(p, Noise) else Noise("salt_and_pepper", p)
    corrupt = pedestrian_corruption(noise, "render_frame").images
    return corrupt(img, noise.level, np.random.default_rng(np.random.SeedSequence([seed, int(image_id), 3])))


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
