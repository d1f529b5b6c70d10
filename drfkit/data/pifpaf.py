"""PifPaf's predictions for the nuScenes images: the ``--json-output`` file names of each
openpifpaf version, reading and checking one file, and matching its boxes to the ground-truth
boxes (Monoloco's enlargement, IoU, greedy one-to-one). The choices: ``drfkit.data.nuscenes``."""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from drfkit.data.records import N_KEYPOINTS

MIN_IOU = 0.3
MONOLOCO_BOX_MARGIN = (1 / 3.5, 1 / 7)  # PifPaf box grown by w/3.5 on each side and h/7 above and below
PERSON_CATEGORY_ID = 1  # COCO 'person', what openpifpaf >= 0.11 writes for human poses


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


def index_prediction_files(predictions_dir: Path) -> dict[str, Path]:
    index: dict[str, Path] = {}
    for path in predictions_dir.rglob("*.json"):
        if path.name in index:
            raise ValueError(f"prediction file name {path.name} appears twice under {predictions_dir}: {index[path.name]} and {path}")
        index[path.name] = path
    return index
