"""Real pedestrian records from nuScenes annotations and PifPaf keypoints (no devkit).

What you need on disk
---------------------
* ``<root>/<version>/*.json``: the official nuScenes tables (sample, sample_data,
  sample_annotation, instance, category, calibrated_sensor, ego_pose, sensor, scene);
* ``<root>/samples/CAM_*/...jpg``: the keyframe camera images (only for ``write_noisy_images``);
* one folder of PifPaf predictions per noise level, e.g. ``predictions/p0.025/``.

Pipeline for one noise level p
------------------------------
1. ``python -m drfkit.data.nuscenes noisify --root R --out NOISY --p 0.025`` writes
   salt-and-pepper copies of the keyframe camera images (lossless PNG by default, so the
   noise is exactly the paper's, at the same relative path with a ``.png`` suffix).
2. On a machine with PifPaf: ``mkdir -p predictions/p0.025`` (openpifpaf takes a missing
   folder as a file name), then ``python -m openpifpaf.predict NOISY/samples/CAM_FRONT/*.png
   --json-output predictions/p0.025`` (one ``<image file name>.predictions.json`` per image,
   here ``X.png.predictions.json``).
3. ``load_nuscenes_records(R, 'predictions/p0.025', Noise('salt_and_pepper', 0.025))``.

Choices (the paper is silent), and where they differ from Monoloco's nuScenes preparation
-----------------------------------------------------------------------------------------
* Cameras: CAM_FRONT only by default (``DEFAULT_CAMERAS``); Monoloco used all six (pass
  ``ALL_CAMERAS``). The book follows the DRF paper: its "about 3300 images" and the
  simulated stand-in are front-camera. A track is one pedestrian instance seen by one
  camera, ordered by timestamp.
* Keyframes only (``is_key_frame``), 2 Hz, where the annotations are.
* Classes: ``human.pedestrian.*`` only; Monoloco also kept bicycles and motorcycles (nuScenes
  annotates a rider as part of the cycle's box), but the paper's study is pedestrians.
* Keep rule: the devkit's ``box_in_image(box, K, imsize, vis_level=BoxVisibility.ANY)``,
  which Monoloco used (``box_in_image_any``): every box corner more than 0.1 m in front of
  the camera and at least one corner visible (inside the image and more than 1 m in front).
* Ground-truth 2D box: the extent of the 8 projected box corners clipped to the image.
  Monoloco projected a box of the annotation's width and height standing at the centre's
  depth (its centre plane); the corner extent is the box the whole 3D box covers in the
  image, and it is a little larger for near or turned pedestrians.
* Matching: PifPaf boxes are enlarged as Monoloco did before matching (``enlarge_boxes``:
  w/3.5 left and right, h/7 above and below, clipped to the image; ``box_margin=None``
  matches the raw box), then matched to a ground-truth box by IoU >= 0.3, greedily by
  decreasing IoU, one-to-one; unmatched boxes (missed people) and unmatched detections
  (false positives, other classes) are dropped. The records keep PifPaf's raw box.
* Prediction file names: for an image ``samples/CAM_FRONT/X.jpg`` the loader accepts
  ``X.jpg.predictions.json`` (openpifpaf >= 0.11), ``X.jpg.pifpaf.json`` (openpifpaf <= 0.10,
  the versions Monoloco used), ``X.jpg.json``, and the same three for the noisy PNG copy
  (``X.png.predictions.json``, ``X.png.pifpaf.json``, ``X.png.json``), anywhere under the
  predictions folder. Every prediction file of the level is read and checked, also those of
  images with no ground-truth pedestrian.
* Detections: ``keypoints`` (51 numbers) and ``bbox`` (x, y, w, h, as openpifpaf's own
  predict writes it in every version; files from Monoloco's own PifPaf wrapper hold
  x0, y0, x1, y1 instead and must be converted first) are required; ``score`` and
  ``category_id`` are not (openpifpaf <= 0.10 writes no ``category_id``). A detection whose
  ``category_id`` is present and not 1 (COCO person) is skipped: it is another class (e.g.
  from a detection head in the same run), which the matching would drop anyway. Keypoints
  with confidence 0 are set to (0, 0, 0); NaN keypoints are an error naming the file.
* Ids: scene_id = position of the scene in scene.json sorted by name; image_id = position of
  the camera image sorted by (timestamp, channel); track_id = position of (scene, instance,
  camera) in sorted order. A token that points to no row of its table is an error naming
  both tokens and the table.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import zlib
from pathlib import Path
from typing import Iterable, Mapping, Sequence

import numpy as np

from drfkit.data.noise import Noise, check_noise
from drfkit.data.records import N_KEYPOINTS, check_records
from drfkit.io import atomic_write_bytes

TABLES = (
    "sample", "sample_data", "sample_annotation", "instance", "category",
    "calibrated_sensor", "ego_pose", "sensor", "scene",
)
ALL_CAMERAS = ("CAM_FRONT", "CAM_FRONT_RIGHT", "CAM_BACK_RIGHT", "CAM_BACK", "CAM_BACK_LEFT", "CAM_FRONT_LEFT")
DEFAULT_CAMERAS = ("CAM_FRONT",)
PEDESTRIAN_PREFIX = "human.pedestrian."
MIN_IOU = 0.3
MONOLOCO_BOX_MARGIN = (1 / 3.5, 1 / 7)  # PifPaf box grown by w/3.5 on each side and h/7 above and below
PERSON_CATEGORY_ID = 1  # COCO 'person', what openpifpaf >= 0.11 writes for human poses


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


# --------------------------------------------------------------------------- predictions
def prediction_file_candidates(image_filename: str) -> list[str]:
    """File names that may hold the PifPaf output of a nuScenes image, in order of preference.

    For ``.../X.jpg``: ``X.jpg.predictions.json`` (openpifpaf >= 0.11), ``X.jpg.pifpaf.json``
    (openpifpaf <= 0.10), ``X.jpg.json``, then the same for the noisy PNG copy ``X.png``.
    """
    base = Path(image_filename).name
    stem = Path(image_filename).stem
    names = []
    for image_name in (base, f"{stem}.png"):
        for suffix in (".predictions.json", ".pifpaf.json", ".json"):
            if image_name + suffix not in names:
                names.append(image_name + suffix)
    return names


def expected_prediction_file(image_filename: str) -> str:
    """The file the README workflow makes for an image: openpifpaf.predict (>= 0.11) on the
    noisy PNG copy of ``.../X.jpg`` writes ``X.png.predictions.json``."""
    return f"{Path(image_filename).stem}.png.predictions.json"


def read_predictions(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One PifPaf ``--json-output`` file -> keypoints (D,17,3), boxes (D,4) x,y,w,h, scores (D,).

    Each detection needs 'keypoints' (51 numbers) and 'bbox' (x, y, w, h); 'score' (NaN when
    absent) and 'category_id' are optional (openpifpaf <= 0.10 writes no category_id). A
    detection whose category_id is present and not 1 (COCO person) is skipped: it is not a
    person. Keypoints with confidence 0 are zeroed; NaN/inf or a malformed detection is an
    error naming the file.
    """
    path = Path(path)
    try:
        with open(path, encoding="utf-8") as fh:
            detections = json.load(fh)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"PifPaf prediction file {path} is not valid JSON ({exc})") from exc
    if not isinstance(detections, list):
        raise ValueError(f"PifPaf prediction file {path} must hold a JSON list of detections")
    kps, boxes, scores = [], [], []
    for d in detections:
        if isinstance(d, dict) and d.get("category_id") not in (None, PERSON_CATEGORY_ID):
            continue  # another class (e.g. a detection head's output in the same run): not a person
        try:
            kp = np.asarray(d["keypoints"], dtype=np.float64)
            box = np.asarray(d["bbox"], dtype=np.float64)
            score = float(d.get("score", np.nan))
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"PifPaf prediction file {path}: a detection lacks 'keypoints' or 'bbox' ({exc})") from exc
        if kp.shape != (3 * N_KEYPOINTS,) or box.shape != (4,):
            raise ValueError(
                f"PifPaf prediction file {path}: keypoints must be 51 numbers and bbox 4, got {kp.shape}, {box.shape}"
            )
        if not (np.all(np.isfinite(kp)) and np.all(np.isfinite(box))):
            raise ValueError(f"PifPaf prediction file {path} holds NaN/inf keypoints or boxes")
        kps.append(kp.reshape(N_KEYPOINTS, 3))
        boxes.append(box)
        scores.append(score)
    keypoints = np.asarray(kps, dtype=np.float64).reshape(-1, N_KEYPOINTS, 3)
    keypoints[..., 2] = np.clip(keypoints[..., 2], 0.0, 1.0)
    keypoints[keypoints[..., 2] == 0] = 0.0  # a missed keypoint is (0, 0, 0)
    return keypoints, np.asarray(boxes, dtype=np.float64).reshape(-1, 4), np.asarray(scores, dtype=np.float64)


def enlarge_boxes(
    boxes: np.ndarray,
    width: float,
    height: float,
    margin: tuple[float, float] = MONOLOCO_BOX_MARGIN,
) -> np.ndarray:
    """Monoloco's enlargement of PifPaf boxes before IoU matching: boxes (D,4) x, y, w, h ->
    (D,4) x, y, w, h grown by margin[0] * w on the left and on the right and margin[1] * h
    above and below (Monoloco: w/3.5 and h/7), then clipped to the image [0, width] x [0, height].
    margin=(0, 0) only clips."""
    boxes = np.asarray(boxes, np.float64).reshape(-1, 4)
    mw, mh = (float(m) for m in margin)
    if not (mw >= 0 and mh >= 0):
        raise ValueError(f"box margin must be two fractions >= 0 (Monoloco: (1/3.5, 1/7)), got {margin}")
    dw, dh = mw * boxes[:, 2], mh * boxes[:, 3]
    x0 = np.clip(boxes[:, 0] - dw, 0, width)
    y0 = np.clip(boxes[:, 1] - dh, 0, height)
    x1 = np.clip(boxes[:, 0] + boxes[:, 2] + dw, 0, width)
    y1 = np.clip(boxes[:, 1] + boxes[:, 3] + dh, 0, height)
    return np.stack([x0, y0, x1 - x0, y1 - y0], axis=1)


def box_iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """IoU of boxes a (G,4) and b (D,4), both x, y, w, h: (G, D)."""
    a, b = np.asarray(a, np.float64).reshape(-1, 4), np.asarray(b, np.float64).reshape(-1, 4)
    ax0, ay0, ax1, ay1 = a[:, 0:1], a[:, 1:2], a[:, 0:1] + a[:, 2:3], a[:, 1:2] + a[:, 3:4]
    bx0, by0, bx1, by1 = b[:, 0], b[:, 1], b[:, 0] + b[:, 2], b[:, 1] + b[:, 3]
    iw = np.clip(np.minimum(ax1, bx1) - np.maximum(ax0, bx0), 0, None)
    ih = np.clip(np.minimum(ay1, by1) - np.maximum(ay0, by0), 0, None)
    inter = iw * ih
    union = a[:, 2:3] * a[:, 3:4] + b[:, 2] * b[:, 3] - inter
    return np.where(union > 0, inter / np.where(union > 0, union, 1.0), 0.0)


def match_boxes(gt: np.ndarray, det: np.ndarray, min_iou: float = MIN_IOU) -> list[tuple[int, int]]:
    """Greedy one-to-one matching by decreasing IoU, pairs with IoU >= min_iou: [(g, d), ...]."""
    iou = box_iou(gt, det)
    if iou.size == 0:
        return []
    order = np.argsort(-iou, axis=None, kind="stable")
    used_g, used_d, pairs = set(), set(), []
    for flat in order:
        g, d = divmod(int(flat), iou.shape[1])
        if iou[g, d] < min_iou:
            break
        if g in used_g or d in used_d:
            continue
        used_g.add(g)
        used_d.add(d)
        pairs.append((g, d))
    return pairs


def _index_prediction_files(predictions_dir: Path) -> dict[str, Path]:
    index: dict[str, Path] = {}
    for path in predictions_dir.rglob("*.json"):
        if path.name in index:
            raise ValueError(f"prediction file name {path.name} appears twice under {predictions_dir}: {index[path.name]} and {path}")
        index[path.name] = path
    return index


# --------------------------------------------------------------------------- records
def load_nuscenes_records(
    root: str | os.PathLike,
    predictions_dir: str | os.PathLike,
    noise: Noise,
    version: str = "v1.0-mini",
    cameras: Iterable[str] = DEFAULT_CAMERAS,
    min_iou: float = MIN_IOU,
    box_margin: tuple[float, float] | None = MONOLOCO_BOX_MARGIN,
) -> dict[str, np.ndarray]:
    """Pedestrian records (``drfkit.data.records``) from nuScenes + PifPaf at salt-and-pepper ``noise``.

    Every keyframe image of ``cameras`` must have a prediction file in ``predictions_dir``
    (names: ``prediction_file_candidates``), and every one of them is read and checked (also
    for images without a ground-truth pedestrian); extra files are ignored. PifPaf boxes are
    enlarged by ``enlarge_boxes(..., box_margin)`` for the matching only (None: the raw box).
    Returns one row per detection matched to a ground-truth pedestrian box (IoU >= min_iou),
    sorted by (scene_id, track_id, timestamp); position/depth/distance come from the
    annotation, box (PifPaf's raw box) and keypoints from PifPaf.
    """
    p = check_noise(noise, "salt_and_pepper", "the nuScenes reader").level
    predictions_dir = Path(predictions_dir)
    if not predictions_dir.is_dir():
        raise FileNotFoundError(
            f"PifPaf predictions folder {predictions_dir} not found; write noisy images with "
            f"`python -m drfkit.data.nuscenes noisify --p {p:g}`, then `mkdir -p {predictions_dir}` "
            f"(openpifpaf takes a missing folder as a file name) and run "
            f"`python -m openpifpaf.predict ... --json-output {predictions_dir}` on them"
        )
    if box_margin is not None:
        enlarge_boxes(np.zeros((0, 4)), 1, 1, box_margin)  # a bad margin fails before any file is read
    tables = read_tables(root, version)
    cameras = tuple(cameras)
    images = camera_images(tables, cameras)
    files = _index_prediction_files(predictions_dir)
    found, missing = [], []
    for image in images:
        match = next((files[n] for n in prediction_file_candidates(image["filename"]) if n in files), None)
        (found if match is not None else missing).append(match if match is not None else image["filename"])
    if missing:
        expected = expected_prediction_file(missing[0])
        others = [n for n in prediction_file_candidates(missing[0]) if n != expected]
        raise ValueError(
            f"{predictions_dir} holds prediction files for {len(found)} of the {len(images)} keyframe images "
            f"of {cameras} ({len(missing)} missing, e.g. {missing[0]} -> expected {expected}, what "
            f"openpifpaf.predict writes for its noisy PNG copy; also accepted: {', '.join(others)}); "
            "run PifPaf on every image of this noise level"
        )
    gt = project_annotations(tables, cameras)
    rows: list[tuple[int, np.ndarray, np.ndarray]] = []  # (gt row, keypoints, box)
    gt_rows_of_image: dict[int, list[int]] = {}
    for g, index in enumerate(gt["image_index"]):
        gt_rows_of_image.setdefault(int(index), []).append(g)
    for index, path in enumerate(found):
        keypoints, boxes, _ = read_predictions(path)  # every file, so a broken one never passes unnoticed
        g_rows = gt_rows_of_image.get(index)
        if not g_rows:
            continue
        image = images[index]
        match_on = boxes if box_margin is None else enlarge_boxes(boxes, image["width"], image["height"], box_margin)
        for g, d in match_boxes(gt["box"][g_rows], match_on, min_iou):
            rows.append((g_rows[g], keypoints[d], boxes[d]))
    if not rows:
        raise ValueError(
            f"no PifPaf detection in {predictions_dir} matched a ground-truth pedestrian box (IoU >= {min_iou}); "
            "check that the predictions belong to these images"
        )
    rows.sort(key=lambda r: r[0])  # gt rows are already in (scene, track, time) order
    g_idx = np.array([r[0] for r in rows])
    position = gt["position"][g_idx].astype(np.float32)
    rec = {
        "keypoints": np.stack([r[1] for r in rows]).astype(np.float32),
        "intrinsics": gt["intrinsics"][g_idx].astype(np.float32),
        "position": position,
        "depth": position[:, 2].copy(),
        "distance": np.linalg.norm(position, axis=1).astype(np.float32),
        "box": np.stack([r[2] for r in rows]).astype(np.float32),
        "track_id": gt["track_id"][g_idx].astype(np.int64),
        "scene_id": gt["scene_id"][g_idx].astype(np.int64),
        "timestamp": gt["timestamp"][g_idx].astype(np.int64),
        "image_id": gt["image_id"][g_idx].astype(np.int64),
        "noise": np.full(len(rows), p, dtype=np.float32),
    }
    check_records(rec)
    return rec


# --------------------------------------------------------------------------- noisy images
def write_noisy_images(
    root: str | os.PathLike,
    out_dir: str | os.PathLike,
    noise: Noise,
    seed: int = 0,
    version: str = "v1.0-mini",
    cameras: Iterable[str] = DEFAULT_CAMERAS,
    image_format: str = "png",
) -> list[Path]:
    """Write copies of the keyframe images of ``cameras`` under salt-and-pepper ``noise``.

    Each image ``<root>/<filename>`` goes to ``<out_dir>/<filename>`` with the suffix
    replaced by ``.png`` (image_format='png', lossless: the noise is exact) or kept
    (image_format='jpg', quality 95: JPEG smears the noise, but the names stay). The noise
    of an image depends on (seed, its file name) only, not on the order of processing.
    Returns the written paths.
    """
    import cv2

    from drfkit.data.noise import salt_and_pepper

    p = check_noise(noise, "salt_and_pepper", "write_noisy_images").level
    if image_format not in ("png", "jpg"):
        raise ValueError(f"image_format must be 'png' (lossless) or 'jpg', got {image_format!r}")
    tables = read_tables(root, version)
    images = camera_images(tables, cameras)
    written = []
    for image in images:
        src = Path(root) / image["filename"]
        pixels = cv2.imread(str(src), cv2.IMREAD_COLOR)
        if pixels is None:
            raise FileNotFoundError(f"camera image {src} is missing or unreadable; download the nuScenes 'samples' blobs")
        rng = np.random.default_rng([seed, zlib.crc32(image["filename"].encode())])
        noisy = salt_and_pepper(pixels, p, rng, channels_last=True)
        rel = Path(image["filename"])
        dst = Path(out_dir) / (rel.with_suffix(".png") if image_format == "png" else rel)
        dst.parent.mkdir(parents=True, exist_ok=True)
        params = [cv2.IMWRITE_JPEG_QUALITY, 95] if image_format == "jpg" else [cv2.IMWRITE_PNG_COMPRESSION, 3]
        ok, buf = cv2.imencode(dst.suffix, noisy, params)
        if not ok:
            raise RuntimeError(f"could not encode {dst}")
        atomic_write_bytes(dst, buf.tobytes())
        written.append(dst)
    return written


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: ``python -m drfkit.data.nuscenes noisify --root R --out O --p 0.025``."""
    parser = argparse.ArgumentParser(prog="python -m drfkit.data.nuscenes", description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    noisify = sub.add_parser("noisify", help="write salt-and-pepper copies of the keyframe camera images")
    noisify.add_argument("--root", required=True, help="nuScenes folder holding '<version>/' and 'samples/'")
    noisify.add_argument("--out", required=True, help="output folder (same relative paths)")
    noisify.add_argument("--p", type=float, required=True, help="probability that a pixel is replaced")
    noisify.add_argument("--seed", type=int, default=0)
    noisify.add_argument("--version", default="v1.0-mini")
    noisify.add_argument("--cameras", nargs="+", default=list(DEFAULT_CAMERAS), choices=ALL_CAMERAS)
    noisify.add_argument("--format", default="png", choices=("png", "jpg"), dest="image_format")
    args = parser.parse_args(argv)
    written = write_noisy_images(args.root, args.out, Noise("salt_and_pepper", args.p), args.seed, args.version, args.cameras, args.image_format)
    print(f"wrote {len(written)} noisy images (p = {args.p:g}) under {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
