"""Reading the nuScenes dataset without the devkit: the official JSON tables, the keyframe camera
images, and the pedestrian annotations projected into each camera (ground-truth 2D boxes, the
devkit's ``box_in_image`` keep rule). The choices and the whole pipeline: ``drfkit.data.nuscenes``."""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Iterable, Mapping, Sequence

import numpy as np

TABLES = (
    "sample", "sample_data", "sample_annotation", "instance", "category",
    "calibrated_sensor", "ego_pose", "sensor", "scene",
)
ALL_CAMERAS = ("CAM_FRONT", "CAM_FRONT_RIGHT", "CAM_BACK_RIGHT", "CAM_BACK", "CAM_BACK_LEFT", "CAM_FRONT_LEFT")
DEFAULT_CAMERAS = ("CAM_FRONT",)
PEDESTRIAN_PREFIX = "human.pedestrian."


# --------------------------------------------------------------------------- tables
def read_tables(root: str | os.PathLike, version: str = "v1.0-mini") -> dict[str, list[dict]]:
    """Read the nuScenes JSON tables from ``<root>/<version>/<table>.json``: table -> list of rows."""
    folder = Path(root) / version
    tables = {}
    for name in TABLES:
        path = folder / f"{name}.json"
        if not path.is_file():
            raise FileNotFoundError(
                f"nuScenes table {path} not found; download nuScenes {version} (metadata) and pass "
                f"root= the folder that contains '{version}/' (e.g. /data/sets/nuscenes)"
            )
        try:
            with open(path, encoding="utf-8") as fh:
                rows = json.load(fh)
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise ValueError(f"nuScenes table {path} is not valid JSON ({exc}); download it again") from exc
        if not isinstance(rows, list):
            raise ValueError(f"nuScenes table {path} must hold a JSON list of records, got {type(rows).__name__}")
        tables[name] = rows
    return tables


def quaternion_to_rotation(q: Sequence[float] | np.ndarray) -> np.ndarray:
    """Rotation matrix of a quaternion (w, x, y, z) (nuScenes order): (..., 4) -> (..., 3, 3).

    The quaternion is normalised first; a zero quaternion is an error.
    """
    q = np.asarray(q, dtype=np.float64)
    if q.shape[-1:] != (4,):
        raise ValueError(f"quaternion must have shape (..., 4) as (w, x, y, z), got {q.shape}")
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(norm < 1e-12) or not np.all(np.isfinite(q)):
        raise ValueError("quaternion must be finite and non-zero")
    w, x, y, z = np.moveaxis(q / norm, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def box_corners(center: np.ndarray, size: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """The 8 corners of nuScenes boxes: center (..., 3), size (..., 3) as (w, l, h), rotation
    (..., 4) quaternion (w, x, y, z) -> (..., 8, 3). Length runs along the box's x axis,
    width along y, height along z (the devkit's convention)."""
    center, size = np.asarray(center, np.float64), np.asarray(size, np.float64)
    w, l, h = size[..., 0:1], size[..., 1:2], size[..., 2:3]
    sx = np.array([1, 1, 1, 1, -1, -1, -1, -1], dtype=np.float64)
    sy = np.array([1, -1, -1, 1, 1, -1, -1, 1], dtype=np.float64)
    sz = np.array([1, 1, -1, -1, 1, 1, -1, -1], dtype=np.float64)
    local = np.stack([l / 2 * sx, w / 2 * sy, h / 2 * sz], axis=-1)  # (..., 8, 3)
    rot = quaternion_to_rotation(rotation)
    return np.einsum("...ij,...kj->...ki", rot, local) + center[..., None, :]


def _lookup(rows: Mapping[str, object], table: str, token: str, referrer: str):
    """``rows[token]``, or a ValueError naming the referring row, the table and the token."""
    try:
        return rows[token]
    except (KeyError, TypeError):
        raise ValueError(
            f"{referrer} refers to {table} {token}, which has no row in {table}.json; "
            "the tables are incomplete or from different versions"
        ) from None


def camera_images(tables: Mapping[str, list[dict]], cameras: Iterable[str] = DEFAULT_CAMERAS) -> list[dict]:
    """Keyframe images of the given camera channels, sorted by (timestamp, channel).

    Each entry: token, filename, timestamp, channel, sample_token, scene_token, width,
    height, intrinsics (3, 3), and the poses (R_ego, t_ego: ego -> global; R_cam, t_cam:
    camera -> ego).
    """
    cameras = tuple(cameras)
    unknown = [c for c in cameras if c not in ALL_CAMERAS]
    if unknown or not cameras:
        raise ValueError(f"cameras must be a non-empty subset of {ALL_CAMERAS}, got {cameras}")
    sensors = {s["token"]: s for s in tables["sensor"]}
    calib = {c["token"]: c for c in tables["calibrated_sensor"]}
    poses = {e["token"]: e for e in tables["ego_pose"]}
    samples = {s["token"]: s for s in tables["sample"]}
    images = []
    for sd in tables["sample_data"]:
        if not sd.get("is_key_frame", False):
            continue
        referrer = f"sample_data {sd['token']}"
        cs = _lookup(calib, "calibrated_sensor", sd["calibrated_sensor_token"], referrer)
        channel = _lookup(sensors, "sensor", cs["sensor_token"], f"calibrated_sensor {cs['token']}")["channel"]
        if channel not in cameras:
            continue
        pose = _lookup(poses, "ego_pose", sd["ego_pose_token"], referrer)
        sample = _lookup(samples, "sample", sd["sample_token"], referrer)
        intrinsics = np.asarray(cs["camera_intrinsic"], dtype=np.float64)
        if intrinsics.shape != (3, 3):
            raise ValueError(f"calibrated_sensor {cs['token']} of {channel} has no 3x3 camera_intrinsic")
        images.append({
            "token": sd["token"],
            "filename": sd["filename"],
            "timestamp": int(sd["timestamp"]),
            "channel": channel,
            "sample_token": sd["sample_token"],
            "scene_token": sample["scene_token"],
            "width": int(sd.get("width", 1600)),
            "height": int(sd.get("height", 900)),
            "intrinsics": intrinsics,
            "R_ego": quaternion_to_rotation(pose["rotation"]),
            "t_ego": np.asarray(pose["translation"], dtype=np.float64),
            "R_cam": quaternion_to_rotation(cs["rotation"]),
            "t_cam": np.asarray(cs["translation"], dtype=np.float64),
        })
    images.sort(key=lambda im: (im["timestamp"], im["channel"], im["token"]))
    return images


def global_to_camera(points: np.ndarray, image: Mapping[str, np.ndarray]) -> np.ndarray:
    """Global points (..., 3) -> camera frame of ``image`` (an entry of ``camera_images``)."""
    ego = (np.asarray(points, np.float64) - image["t_ego"]) @ image["R_ego"]  # R^T (p - t), row vectors
    return (ego - image["t_cam"]) @ image["R_cam"]


def project_points(points_cam: np.ndarray, intrinsics: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates (u, v), each (...,), of camera-frame points (..., 3) under a 3x3 K:
    K [x, y, z] divided by its third entry (the devkit's ``view_points(..., normalize=True)``).
    Points at or behind the camera give inf/NaN or mirrored values; callers mask them."""
    uvw = np.asarray(points_cam, np.float64) @ np.asarray(intrinsics, np.float64).T
    with np.errstate(divide="ignore", invalid="ignore"):
        return uvw[..., 0] / uvw[..., 2], uvw[..., 1] / uvw[..., 2]


def box_in_image_any(corners_cam: np.ndarray, intrinsics: np.ndarray, width: int, height: int) -> np.ndarray:
    """The devkit's ``box_in_image(box, K, (width, height), vis_level=BoxVisibility.ANY)`` per box.

    corners_cam (..., 8, 3) box corners in the camera frame, intrinsics (3, 3) -> bool (...,).
    A box is kept when EVERY corner is more than 0.1 m in front of the camera (z > 0.1) and
    at least one corner is visible: projected strictly inside the image (0 < u < width and
    0 < v < height) and more than 1 m in front (z > 1).
    """
    corners_cam = np.asarray(corners_cam, np.float64)
    if corners_cam.shape[-2:] != (8, 3):
        raise ValueError(f"corners_cam must have shape (..., 8, 3), got {corners_cam.shape}")
    u, v = project_points(corners_cam, intrinsics)
    z = corners_cam[..., 2]
    visible = (u > 0) & (u < width) & (v > 0) & (v < height) & (z > 1)
    in_front = z > 0.1
    return visible.any(axis=-1) & in_front.all(axis=-1)


def project_annotations(
    tables: Mapping[str, list[dict]],
    cameras: Iterable[str] = DEFAULT_CAMERAS,
) -> dict[str, np.ndarray]:
    """Ground-truth pedestrians per keyframe camera image, in the camera frame.

    One row per (image, pedestrian annotation) whose box passes ``box_in_image_any`` (the
    devkit's keep rule), sorted by (scene_id, track_id, timestamp). Returns:
      'position' float64 (G,3) box centre in the camera frame; 'box' float64 (G,4) x, y, w, h
      of the extent of the 8 projected box corners, clipped to the image; 'intrinsics'
      (G,3,3); 'image_index' (G,) position in ``camera_images(tables, cameras)``; 'track_id', 'scene_id', 'timestamp',
      'image_id' int64 (G,); 'instance_token', 'channel' (G,) str.
    """
    cameras = tuple(cameras)
    images = camera_images(tables, cameras)
    categories = {c["token"]: c["name"] for c in tables["category"]}
    pedestrian_instances = {
        i["token"] for i in tables["instance"] if categories.get(i["category_token"], "").startswith(PEDESTRIAN_PREFIX)
    }
    by_sample: dict[str, list[dict]] = {}
    for ann in tables["sample_annotation"]:
        if ann["instance_token"] in pedestrian_instances:
            by_sample.setdefault(ann["sample_token"], []).append(ann)
    scene_order = {s["token"]: k for k, s in enumerate(sorted(tables["scene"], key=lambda s: s["name"]))}

    rows = []
    for index, image in enumerate(images):
        scene_id = _lookup(scene_order, "scene", image["scene_token"], f"sample {image['sample_token']}")
        anns = by_sample.get(image["sample_token"], [])
        if not anns:
            continue
        centres = np.array([a["translation"] for a in anns], dtype=np.float64)
        corners = box_corners(centres, np.array([a["size"] for a in anns]), np.array([a["rotation"] for a in anns]))
        centres_cam = global_to_camera(centres, image)  # (A,3)
        corners_cam = global_to_camera(corners, image)  # (A,8,3)
        k = image["intrinsics"]
        width, height = image["width"], image["height"]
        keep = box_in_image_any(corners_cam, k, width, height)  # (A,): all corners ahead, so u, v finite
        u, v = project_points(corners_cam, k)  # (A,8)
        for a in np.flatnonzero(keep):
            x0, x1 = np.clip(u[a].min(), 0, width), np.clip(u[a].max(), 0, width)
            y0, y1 = np.clip(v[a].min(), 0, height), np.clip(v[a].max(), 0, height)
            rows.append({
                "position": centres_cam[a], "box": np.array([x0, y0, x1 - x0, y1 - y0]),
                "intrinsics": k, "image_index": index, "timestamp": image["timestamp"],
                "scene_id": scene_id, "instance_token": anns[a]["instance_token"],
                "channel": image["channel"],
            })
    if not rows:
        return {
            "position": np.zeros((0, 3)), "box": np.zeros((0, 4)), "intrinsics": np.zeros((0, 3, 3)),
            "image_index": np.zeros(0, np.int64), "track_id": np.zeros(0, np.int64),
            "scene_id": np.zeros(0, np.int64), "timestamp": np.zeros(0, np.int64),
            "image_id": np.zeros(0, np.int64), "instance_token": np.zeros(0, str), "channel": np.zeros(0, str),
        }
    track_keys = sorted({(r["scene_id"], r["instance_token"], r["channel"]) for r in rows})
    track_of = {key: t for t, key in enumerate(track_keys)}
    for r in rows:
        r["track_id"] = track_of[(r["scene_id"], r["instance_token"], r["channel"])]
    rows.sort(key=lambda r: (r["scene_id"], r["track_id"], r["timestamp"]))
    out = {name: np.array([r[name] for r in rows]) for name in rows[0]}
    for name in ("image_index", "track_id", "scene_id", "timestamp"):
        out[name] = out[name].astype(np.int64)
    out["image_id"] = out["image_index"].copy()
    return out
