"""Real pedestrian records from nuScenes annotations and PifPaf keypoints (no devkit).

This module builds the records, writes the noisy images and is the command line; reading the
tables and projecting the annotations is ``drfkit.data.nuscenes_tables``, reading and matching
PifPaf's predictions ``drfkit.data.pifpaf``.

What you need on disk
---------------------
* ``<root>/<version>/*.json``: the official nuScenes tables (sample, sample_data,
  sample_annotation, instance, category, calibrated_sensor, ego_pose, sensor, scene);
* ``<root>/samples/CAM_*/...jpg``: the keyframe camera images (only for ``write_noisy_images``);
* one folder of PifPaf predictions per noise level, e.g. ``predictions/p0.025/``.

Pipeline for one noise level p
------------------------------
1. ``python -m drfkit nuscenes noisify --root R --out NOISY --p 0.025`` writes
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

import os
import zlib
from pathlib import Path
from typing import Iterable

import numpy as np

from drfkit.data.noise import Noise, pedestrian_corruption
from drfkit.data.nuscenes_tables import DEFAULT_CAMERAS, camera_images, project_annotations, read_tables
from drfkit.data.pifpaf import (MIN_IOU, MONOLOCO_BOX_MARGIN, enlarge_boxes, expected_prediction_file,
                                index_prediction_files, match_boxes, prediction_file_candidates, read_predictions)
from drfkit.data.records import check_records
from drfkit.util.io import atomic_write_bytes


# --------------------------------------------------------------------------- records
def noise_dir_name(noise: Noise) -> str:
    """Folder name of one noise level's PifPaf predictions: 'p0.025' for salt-and-pepper 0.025 (the prefix
    is the kind's ``PedestrianCorruption.folder``, '<kind>_' when it names none)."""
    prefix = pedestrian_corruption(noise, "noise_dir_name").folder or f"{noise.kind}_"
    return f"{prefix}{noise.level:g}"


def load_nuscenes_records(
    root: str | os.PathLike,
    predictions_dir: str | os.PathLike,
    noise: Noise,
    version: str = "v1.0-mini",
    cameras: Iterable[str] = DEFAULT_CAMERAS,
    min_iou: float = MIN_IOU,
    box_margin: tuple[float, float] | None = MONOLOCO_BOX_MARGIN,
) -> dict[str, np.ndarray]:
    """Pedestrian records (``drfkit.data.records``) from nuScenes + PifPaf at ``noise`` (a kind with a
    pedestrian corruption: salt-and-pepper, or one registered in ``drfkit.data.noise.PEDESTRIAN_CORRUPTIONS``).

    Every keyframe image of ``cameras`` must have a prediction file in ``predictions_dir``
    (names: ``prediction_file_candidates``), and every one of them is read and checked (also
    for images without a ground-truth pedestrian); extra files are ignored. PifPaf boxes are
    enlarged by ``enlarge_boxes(..., box_margin)`` for the matching only (None: the raw box).
    Returns one row per detection matched to a ground-truth pedestrian box (IoU >= min_iou),
    sorted by (scene_id, track_id, timestamp); position/depth/distance come from the
    annotation, box (PifPaf's raw box) and keypoints from PifPaf.
    """
    pedestrian_corruption(noise, "the nuScenes reader")
    p = noise.level
    predictions_dir = Path(predictions_dir)
    if not predictions_dir.is_dir():
        raise FileNotFoundError(
            f"PifPaf predictions folder {predictions_dir} not found; write noisy images with "
            f"`python -m drfkit nuscenes noisify --p {p:g}`, then `mkdir -p {predictions_dir}` "
            f"(openpifpaf takes a missing folder as a file name) and run "
            f"`python -m openpifpaf.predict ... --json-output {predictions_dir}` on them"
        )
    if box_margin is not None:
        enlarge_boxes(np.zeros((0, 4)), 1, 1, box_margin)  # a bad margin fails before any file is read
    tables = read_tables(root, version)
    cameras = tuple(cameras)
    images = camera_images(tables, cameras)
    files = index_prediction_files(predictions_dir)
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
    """Write copies of the keyframe images of ``cameras`` under ``noise`` (salt-and-pepper, or a kind
    registered in ``drfkit.data.noise.PEDESTRIAN_CORRUPTIONS``).

    Each image ``<root>/<filename>`` goes to ``<out_dir>/<filename>`` with the suffix
    replaced by ``.png`` (image_format='png', lossless: the noise is exact) or kept
    (image_format='jpg', quality 95: JPEG smears the noise, but the names stay). The noise
    of an image depends on (seed, its file name) only, not on the order of processing.
    Returns the written paths.
    """
    import cv2

    corrupt = pedestrian_corruption(noise, "write_noisy_images").images
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
        noisy = corrupt(pixels, noise.level, rng)
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
