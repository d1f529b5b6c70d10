"""The pedestrian record format shared by the simulated and the real (nuScenes) source.

A *records* object is a plain ``dict[str, np.ndarray]`` with one row per detected
pedestrian per keyframe; every array has the same length M:

==============  =========  ==============  ================================================
field           dtype      trailing shape  meaning
==============  =========  ==============  ================================================
keypoints       float32    (17, 3)         pixel u, v and confidence, COCO order; a missed
                                           keypoint is u = v = 0, conf = 0 (as PifPaf)
intrinsics      float32    (3, 3)          camera matrix K of the image
position        float32    (3,)            box centre in the camera frame (m; x right,
                                           y down, z forward)
depth           float32    ()              position z (m), the paper's target
distance        float32    ()              ||position|| (m), Monoloco's target
box             float32    (4,)            x, y, w, h of the detection (pixels)
track_id        int64      ()              one pedestrian seen by one camera
scene_id        int64      ()              scene (never split across train/val/test)
timestamp       int64      ()              microseconds
image_id        int64      ()              camera image the detection came from
noise           float32    ()              noise level of that image (salt-and-pepper p)
==============  =========  ==============  ================================================

Extra fields are allowed (they must have length M too) and travel through
``split_by_scene``; ``check_records`` only checks their length.

NaN policy: every function here *rejects* NaN/inf keypoints with a ValueError. Missed
keypoints must already be encoded as (0, 0, 0), which is what PifPaf writes and what both
loaders produce.
"""
from __future__ import annotations

from typing import Mapping

import numpy as np

N_KEYPOINTS = 17
KEYFRAME_PERIOD_US = 500_000  # nuScenes keyframes come at 2 Hz
DEFAULT_MAX_GAP_S = 1.25  # up to one missed keyframe (2 Hz) bridges; a longer gap means the track was lost

RECORD_FIELDS: dict[str, tuple[type, tuple[int, ...]]] = {
    "keypoints": (np.float32, (N_KEYPOINTS, 3)),
    "intrinsics": (np.float32, (3, 3)),
    "position": (np.float32, (3,)),
    "depth": (np.float32, ()),
    "distance": (np.float32, ()),
    "box": (np.float32, (4,)),
    "track_id": (np.int64, ()),
    "scene_id": (np.int64, ()),
    "timestamp": (np.int64, ()),
    "image_id": (np.int64, ()),
    "noise": (np.float32, ()),
}

# COCO keypoint names, in the order PifPaf writes them.
COCO_KEYPOINTS = (
    "nose", "left_eye", "right_eye", "left_ear", "right_ear",
    "left_shoulder", "right_shoulder", "left_elbow", "right_elbow",
    "left_wrist", "right_wrist", "left_hip", "right_hip",
    "left_knee", "right_knee", "left_ankle", "right_ankle",
)


def check_records(rec: Mapping[str, np.ndarray]) -> int:
    """Raise a ValueError/TypeError naming the first problem of ``rec``; return M.

    Checks: every field of ``RECORD_FIELDS`` present with its dtype and trailing shape,
    all arrays (extra fields included) of the same length M >= 1, keypoints and the other
    float fields finite, confidences in [0, 1], depth == position z, distance ==
    ||position||, noise in [0, 1].
    """
    if not isinstance(rec, Mapping):
        raise TypeError(f"records must be a dict of numpy arrays, got {type(rec).__name__}")
    missing = [name for name in RECORD_FIELDS if name not in rec]
    if missing:
        # records written before the noise field got its one name carry 'noise_p'
        renamed = "; the field 'noise_p' was renamed 'noise': rebuild the records" if "noise_p" in rec else ""
        raise ValueError(
            f"records miss field(s) {missing}{renamed}; a pedestrian record needs {sorted(RECORD_FIELDS)}"
        )
    lengths = {}
    for name, value in rec.items():
        if not isinstance(value, np.ndarray):
            raise TypeError(f"records field {name!r} must be a numpy array, got {type(value).__name__}")
        if value.ndim == 0:
            raise ValueError(f"records field {name!r} is a scalar; every field needs one row per detection")
        lengths[name] = len(value)
    for name, (dtype, trailing) in RECORD_FIELDS.items():
        value = rec[name]
        if value.dtype != dtype:
            raise TypeError(
                f"records field {name!r} must have dtype {np.dtype(dtype).name}, got {value.dtype} "
                f"(convert with .astype(np.{np.dtype(dtype).name}))"
            )
        if value.shape[1:] != trailing:
            raise ValueError(
                f"records field {name!r} must have shape (M, {', '.join(map(str, trailing))}) "
                f"i.e. trailing shape {trailing}, got {value.shape}"
            )
    if len(set(lengths.values())) != 1:
        raise ValueError(f"records fields have unequal lengths: {lengths}")
    m = lengths["keypoints"]
    if m == 0:
        raise ValueError("records are empty (M = 0): no detection survived; check the source and noise level")
    for name, (dtype, _) in RECORD_FIELDS.items():
        if dtype == np.float32 and not np.all(np.isfinite(rec[name])):
            raise ValueError(
                f"records field {name!r} contains NaN or inf; missed keypoints must be encoded as "
                "u = v = 0, conf = 0 (as PifPaf does), not NaN"
            )
    conf = rec["keypoints"][..., 2]
    if np.any((conf < 0) | (conf > 1)):
        raise ValueError("keypoint confidences must lie in [0, 1]")
    if not np.allclose(rec["depth"], rec["position"][:, 2], atol=1e-4):
        raise ValueError("records field 'depth' must equal position z (column 2 of 'position')")
    if not np.allclose(rec["distance"], np.linalg.norm(rec["position"], axis=1), rtol=1e-5, atol=1e-4):
        raise ValueError("records field 'distance' must equal ||position||")
    noise = rec["noise"]
    if np.any((noise < 0) | (noise > 1)):
        raise ValueError("records field 'noise' must lie in [0, 1]")
    return m


def select(rec: Mapping[str, np.ndarray], index: np.ndarray) -> dict[str, np.ndarray]:
    """Rows ``index`` (boolean mask or integer indices) of every field."""
    return {name: value[index] for name, value in rec.items()}


def concatenate(parts: list[Mapping[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Concatenate records with the same fields (e.g. the same people at several noise levels).

    The ids are not renumbered: concatenating two noise levels of the same simulation keeps
    the shared track ids, so use ``noise`` (or separate calls) to tell them apart.
    """
    if not parts:
        raise ValueError("concatenate needs at least one records dict")
    keys = list(parts[0])
    for part in parts[1:]:
        if set(part) != set(keys):
            raise ValueError(f"records to concatenate have different fields: {sorted(keys)} vs {sorted(part)}")
    return {k: np.concatenate([part[k] for part in parts]) for k in keys}


def split_by_scene(
    rec: Mapping[str, np.ndarray],
    fractions: tuple[float, ...] = (0.7, 0.15, 0.15),
    seed: int = 0,
) -> dict[str, dict[str, np.ndarray]]:
    """Split records into 'train'/'val'/'test' (or 'train'/'test' for two fractions) by scene.

    Scenes are shuffled with ``seed`` and dealt out in proportion to ``fractions`` (counted
    in scenes, not rows), so no scene -- and hence no track -- appears in two splits. Every
    split with a positive fraction gets at least one scene. Returns split -> records.
    """
    check_records(rec)
    fractions = tuple(float(f) for f in fractions)
    if len(fractions) not in (2, 3):
        raise ValueError(f"fractions must have 2 (train, test) or 3 (train, val, test) entries, got {fractions}")
    if any(not f >= 0 for f in fractions) or not np.isclose(sum(fractions), 1.0):
        raise ValueError(f"fractions must be non-negative and sum to 1, got {fractions}")
    names = ("train", "test") if len(fractions) == 2 else ("train", "val", "test")
    scenes = np.unique(rec["scene_id"])
    n_needed = sum(f > 0 for f in fractions)
    if len(scenes) < n_needed:
        raise ValueError(
            f"cannot split {len(scenes)} scene(s) into {n_needed} non-empty splits; "
            "simulate or load more scenes"
        )
    counts = _allocate(len(scenes), fractions)
    order = np.random.default_rng(seed).permutation(scenes)
    bounds = np.concatenate([[0], np.cumsum(counts)])
    out = {}
    for name, lo, hi, frac in zip(names, bounds[:-1], bounds[1:], fractions):
        if frac == 0:
            continue
        out[name] = select(rec, np.isin(rec["scene_id"], order[lo:hi]))
    return out


def _allocate(n: int, fractions: tuple[float, ...]) -> np.ndarray:
    """Integer counts summing to n, close to n * fractions, >= 1 where the fraction is > 0."""
    raw = np.asarray(fractions) * n
    counts = np.floor(raw).astype(int)
    positive = np.asarray(fractions) > 0
    counts[positive & (counts == 0)] = 1
    # Hand out (or take back) the remainder by largest (smallest) rounding loss.
    while counts.sum() < n:
        counts[np.argmax(np.where(positive, raw - counts, -np.inf))] += 1
    while counts.sum() > n:
        candidates = np.where(counts > 1, counts - raw, -np.inf)
        counts[np.argmax(candidates)] -= 1
    return counts


# Where openpifpaf writes a keypoint it missed (u, v in pixels, confidence 0). Monoloco's
# network saw these placeholders back-projected like any keypoint, so the normalised input
# keeps them there; the DRF family's encoder ignores keypoints of confidence 0.
PIFPAF_MISSED_UV = (0.0, -3.0)


def normalise_keypoints(keypoints: np.ndarray, intrinsics: np.ndarray) -> np.ndarray:
    """Back-project pixel keypoints to normalised camera coordinates times 10 (as Monoloco).

    keypoints (..., 17, 3) pixel u, v, conf; intrinsics (..., 3, 3) with the same leading
    shape (or broadcastable to it). Returns float32 (..., 17, 3): x, y = 10 * (K^-1 [u, v, 1])
    [:2], confidence kept. A missed keypoint (conf == 0) becomes PifPaf's placeholder pixel
    ``PIFPAF_MISSED_UV`` back-projected, with conf 0, whatever its pixel values (as in
    Monoloco's input). NaN/inf is rejected.
    """
    kp = np.asarray(keypoints, dtype=np.float64)
    k = np.asarray(intrinsics, dtype=np.float64)
    if kp.ndim < 2 or kp.shape[-2:] != (N_KEYPOINTS, 3):
        raise ValueError(f"keypoints must have shape (..., 17, 3), got {kp.shape}")
    if k.ndim < 2 or k.shape[-2:] != (3, 3):
        raise ValueError(f"intrinsics must have shape (..., 3, 3), got {k.shape}")
    if not np.all(np.isfinite(kp)):
        raise ValueError("keypoints contain NaN or inf; encode missed keypoints as (0, 0, 0)")
    k_inv = np.linalg.inv(k)  # (..., 3, 3); K is upper triangular and well conditioned
    detected = kp[..., 2:3] > 0
    uv = np.where(detected, kp[..., :2], np.asarray(PIFPAF_MISSED_UV))
    homog = np.concatenate([uv, np.ones_like(kp[..., :1])], axis=-1)  # (..., 17, 3)
    rays = np.einsum("...ij,...kj->...ki", k_inv, homog)  # (..., 17, 3)
    xy = 10.0 * rays[..., :2] / rays[..., 2:3]
    return np.concatenate([xy, kp[..., 2:3]], axis=-1).astype(np.float32)


def make_sequences(
    rec: Mapping[str, np.ndarray],
    seq_len: int,
    stride: int | None = None,
    max_gap_s: float = DEFAULT_MAX_GAP_S,
) -> dict[str, np.ndarray]:
    """Cut every track into fixed-length windows of consecutive keyframes.

    Rows are grouped by track_id and ordered by timestamp; a track is broken into segments
    wherever two consecutive detections are more than ``max_gap_s`` apart (default 1.25 s:
    one missed keyframe is bridged, so a window may hold one 1 s step; two missed keyframes or
    the person leaving the view end the segment). Each segment
    is cut into windows of ``seq_len`` starting every ``stride`` rows (default seq_len, i.e.
    disjoint windows); a last, shorter window keeps the segment's tail. Short windows are
    padded by repeating their last valid frame with mask False.

    Returns (N windows, S = seq_len):
      'inputs' float32 (N, S, 17, 3) normalised keypoints (``normalise_keypoints``),
      'targets' float32 (N, S, 1) depth, 'distance' float32 (N, S), 'mask' bool (N, S),
      'timestamp' int64 (N, S), 'record_index' int64 (N, S) row of ``rec`` (padding repeats
      the last valid row), 'track_id' int64 (N,), 'scene_id' int64 (N,), 'noise' float32 (N,).
    """
    check_records(rec)
    if isinstance(seq_len, bool) or not isinstance(seq_len, (int, np.integer)) or seq_len < 1:
        raise ValueError(f"seq_len must be a positive integer, got {seq_len!r}")
    stride = seq_len if stride is None else stride
    if isinstance(stride, bool) or not isinstance(stride, (int, np.integer)) or stride < 1:
        raise ValueError(f"stride must be a positive integer, got {stride!r}")
    if not max_gap_s > 0:
        raise ValueError(f"max_gap_s must be positive, got {max_gap_s}")

    track, time = rec["track_id"], rec["timestamp"]
    order = np.lexsort((time, track))  # by track, then time
    track_sorted, time_sorted = track[order], time[order]
    same_track = track_sorted[1:] == track_sorted[:-1]
    if np.any(same_track & (time_sorted[1:] == time_sorted[:-1])):
        raise ValueError(
            "a track has two detections with the same timestamp; track_id must identify one "
            "pedestrian in one camera (and records of different noise levels must not be mixed)"
        )
    gap_us = max_gap_s * 1e6
    new_segment = np.ones(len(order), dtype=bool)
    new_segment[1:] = ~same_track | (np.diff(time_sorted) > gap_us)
    seg_start = np.flatnonzero(new_segment)
    seg_len = np.diff(np.append(seg_start, len(order)))

    # Window starts within each segment: full windows every `stride`, then one shorter tail.
    starts, lengths = [], []
    for s0, length in zip(seg_start, seg_len):
        offs = list(range(0, length - seq_len + 1, stride))
        nxt = offs[-1] + stride if offs else 0
        if (not offs or offs[-1] + seq_len < length) and nxt < length:
            offs.append(nxt)
        for off in offs:
            starts.append(s0 + off)
            lengths.append(min(seq_len, length - off))
    starts = np.asarray(starts, dtype=np.int64)
    lengths = np.asarray(lengths, dtype=np.int64)

    steps = np.arange(seq_len)
    mask = steps[None, :] < lengths[:, None]  # (N, S)
    pos = starts[:, None] + np.minimum(steps[None, :], lengths[:, None] - 1)  # pad = last valid
    rows = order[pos]  # (N, S) rows of rec

    inputs = normalise_keypoints(rec["keypoints"][rows], rec["intrinsics"][rows])
    first = rows[:, 0]
    return {
        "inputs": inputs,
        "targets": rec["depth"][rows][..., None].astype(np.float32),
        "distance": rec["distance"][rows].astype(np.float32),
        "mask": mask,
        "timestamp": rec["timestamp"][rows],
        "record_index": rows.astype(np.int64),
        "track_id": rec["track_id"][first],
        "scene_id": rec["scene_id"][first],
        "noise": rec["noise"][first],
    }
