"""Statistics of the simulated pedestrian source, to set beside what is published for PifPaf on
nuScenes and for Monoloco (``docs/simulator.md``).

Pure functions of the simulator's ground truth (``drfkit.data.sim_world.simulate_truth``, M_t
rows, one per recorded pedestrian-keyframe) and of the records its detector produced from that
truth (``drfkit.data.sim_detector.simulate_records``, M rows, a subset of the truth's rows in
the same order; a row is identified by (track_id, timestamp)). Nothing here draws random numbers
or reads files; ``drfkit.study.sim_stats`` simulates a profile's data and prints the tables:

    python -m drfkit simstats --profile paper

Statistics, each per depth bin (``DEPTH_BINS``, metres of the box centre's z) and overall:

* ``detection_stats`` -- share of true pedestrian-keyframes with no detection (missed detection);
* ``keypoint_stats``  -- over detected rows: share of visible keypoints missed, pixel error of the
  detected keypoints (median, mean, relative to the person's pixel height), gross-error share;
* ``pinhole_stats``   -- the error of a naive per-frame depth from the keypoints' vertical extent
  (``pinhole_depth``: z = fy * span_m / (v_max - v_min)) with one body span for everybody;
* ``error_autocorrelation`` -- lag-k correlation, along a track, of the keypoint errors (the
  detector draws them independently per frame, so about 0) and of the pinhole depth's relative
  error (not 0: a person taller or shorter than ``span_m`` is biased in every frame).
"""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np
import pandas as pd

from drfkit.data.records import N_KEYPOINTS

DEPTH_BINS = (0.0, 10.0, 20.0, 30.0, 40.0, 50.0)
GROSS_ERROR_FRACTION = 0.25  # a keypoint off by more than this fraction of the body's pixel height


# ----------------------------------------------------------------------------- alignment
def _row_keys(d: Mapping[str, np.ndarray]) -> np.ndarray:
    """(n,) int64 keys identifying a pedestrian-keyframe: track id and timestamp."""
    track = np.asarray(d["track_id"], dtype=np.int64)
    time = np.asarray(d["timestamp"], dtype=np.int64)
    return track * np.int64(10**12) + (time % np.int64(10**12))


def align_to_truth(truth: Mapping[str, np.ndarray], rec: Mapping[str, np.ndarray]) -> np.ndarray:
    """Row of ``truth`` (M_t rows) for every row of ``rec`` (M rows): int64 (M,).

    Rows are matched on (track_id, timestamp); a record with no truth row is a ValueError (the
    records were not simulated from this truth)."""
    kt, kr = _row_keys(truth), _row_keys(rec)
    order = np.argsort(kt, kind="stable")
    pos = np.searchsorted(kt, kr, sorter=order)
    pos = np.minimum(pos, len(kt) - 1)
    rows = order[pos]
    if len(kr) and not np.array_equal(kt[rows], kr):
        raise ValueError("records contain rows (track_id, timestamp) absent from the truth; pass the truth the "
                         "records were simulated from")
    return rows.astype(np.int64)


def depth_bin(depth: np.ndarray, edges: tuple[float, ...] = DEPTH_BINS) -> np.ndarray:
    """Bin of each depth (n,) -> int (n,): i for edges[i] < depth <= edges[i+1], -1 outside."""
    depth = np.asarray(depth, dtype=np.float64)
    edges = np.asarray(edges, dtype=np.float64)
    if edges.ndim != 1 or len(edges) < 2 or np.any(np.diff(edges) <= 0):
        raise ValueError(f"edges must be increasing with at least two entries, got {edges}")
    idx = np.searchsorted(edges, depth, side="left") - 1
    return np.where((depth > edges[0]) & (depth <= edges[-1]), idx, -1)


def _bins(depth: np.ndarray, edges: tuple[float, ...]):
    """Yield (label, lo, hi, bool mask) for every bin, then ('all', lo, hi, mask of all rows)."""
    b = depth_bin(depth, edges)
    for i in range(len(edges) - 1):
        yield f"{edges[i]:g}-{edges[i + 1]:g}", float(edges[i]), float(edges[i + 1]), b == i
    yield "all", float(edges[0]), float(edges[-1]), np.ones(len(depth), dtype=bool)


def _nan_stat(fn, x: np.ndarray) -> float:
    x = np.asarray(x, dtype=np.float64)
    x = x[np.isfinite(x)]
    return float(fn(x)) if x.size else float("nan")


# ----------------------------------------------------------------------------- detections
def detection_stats(truth: Mapping[str, np.ndarray], rec: Mapping[str, np.ndarray],
                    edges: tuple[float, ...] = DEPTH_BINS) -> pd.DataFrame:
    """Missed detections by the true depth of the person.

    Rows: one per depth bin, then 'all'. Columns: bin, depth_lo, depth_hi, n_true (truth rows
    M_t in the bin), n_detected (of them, rows present in ``rec``), miss_rate = 1 - n_detected /
    n_true (NaN for an empty bin)."""
    detected = np.zeros(len(truth["depth"]), dtype=bool)
    detected[align_to_truth(truth, rec)] = True
    rows = []
    for name, lo, hi, where in _bins(truth["depth"], edges):
        n = int(where.sum())
        k = int(detected[where].sum())
        rows.append({"bin": name, "depth_lo": lo, "depth_hi": hi, "n_true": n, "n_detected": k,
                     "miss_rate": 1.0 - k / n if n else float("nan")})
    return pd.DataFrame(rows)


def dataset_size(truth: Mapping[str, np.ndarray], rec: Mapping[str, np.ndarray]) -> dict[str, int]:
    """Counts to set beside the paper's "about 3300 images with about 3700 pedestrian instances":
    images simulated, pedestrian tracks recorded in the truth, tracks with at least one
    detection, images with at least one detection, detections (rows of ``rec``)."""
    return {
        "images": int(truth["n_images"][0]) if "n_images" in truth else int(len(np.unique(truth["image_id"]))),
        "tracks_true": int(len(np.unique(truth["track_id"]))),
        "tracks_detected": int(len(np.unique(rec["track_id"]))),
        "images_with_detection": int(len(np.unique(rec["image_id"]))),
        "detections": int(len(rec["track_id"])),
    }


# ----------------------------------------------------------------------------- keypoints
def keypoint_errors(truth: Mapping[str, np.ndarray], rec: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Per-keypoint errors of the detections against the true projections.

    Returns, for the M rows of ``rec``:
      'signed' float64 (M, 17, 2) detected (u, v) minus true (u, v) in pixels, NaN where missed;
      'error_px' float64 (M, 17) Euclidean pixel error, NaN where missed;
      'detected' bool (M, 17) confidence > 0; 'visible' bool (M, 17) true projection in the image;
      'height_px' float64 (M,) true pixel height of the person; 'depth' float64 (M,) true depth;
      'truth_row' int64 (M,) the truth row (``align_to_truth``).
    """
    rows = align_to_truth(truth, rec)
    kp = np.asarray(rec["keypoints"], dtype=np.float64)  # (M,17,3)
    true_px = np.asarray(truth["keypoints_px"], dtype=np.float64)[rows]  # (M,17,2)
    detected = kp[..., 2] > 0
    signed = np.where(detected[..., None], kp[..., :2] - true_px, np.nan)
    return {
        "signed": signed,
        "error_px": np.sqrt(np.sum(signed**2, axis=-1)),
        "detected": detected,
        "visible": np.asarray(truth["in_image"], dtype=bool)[rows],
        "height_px": np.asarray(truth["height_px"], dtype=np.float64)[rows],
        "depth": np.asarray(truth["depth"], dtype=np.float64)[rows],
        "truth_row": rows,
    }


def keypoint_stats(truth: Mapping[str, np.ndarray], rec: Mapping[str, np.ndarray],
                   edges: tuple[float, ...] = DEPTH_BINS) -> pd.DataFrame:
    """Keypoint quality of the detections (rows of ``rec``) by true depth.

    Rows: one per depth bin, then 'all'. Columns: bin, n_detections, height_px (median true pixel
    height), kp_miss_rate (share of keypoints whose true projection lies in the image that the
    detector missed), err_px_median, err_px_mean (pixel error of detected keypoints),
    err_rel_median (pixel error / pixel height), gross_rate (share of detected keypoints off by
    more than ``GROSS_ERROR_FRACTION`` of the pixel height), conf_mean (mean confidence of the
    detected keypoints)."""
    e = keypoint_errors(truth, rec)
    conf = np.asarray(rec["keypoints"], dtype=np.float64)[..., 2]
    rel = e["error_px"] / e["height_px"][:, None]
    rows = []
    for name, lo, hi, where in _bins(e["depth"], edges):
        vis, det = e["visible"][where], e["detected"][where]
        n_vis = int(vis.sum())
        err, r = e["error_px"][where][det], rel[where][det]
        rows.append({
            "bin": name, "depth_lo": lo, "depth_hi": hi, "n_detections": int(where.sum()),
            "height_px": _nan_stat(np.median, e["height_px"][where]),
            "kp_miss_rate": float((vis & ~det).sum() / n_vis) if n_vis else float("nan"),
            "err_px_median": _nan_stat(np.median, err), "err_px_mean": _nan_stat(np.mean, err),
            "err_rel_median": _nan_stat(np.median, r),
            "gross_rate": float(np.mean(r > GROSS_ERROR_FRACTION)) if r.size else float("nan"),
            "conf_mean": _nan_stat(np.mean, conf[where][det]),
        })
    return pd.DataFrame(rows)


# ----------------------------------------------------------------------------- pinhole depth
def keypoint_extent_px(keypoints: np.ndarray) -> np.ndarray:
    """Vertical pixel extent v_max - v_min of the detected keypoints (conf > 0).

    keypoints (M, 17, 3) pixel u, v, conf -> float64 (M,), NaN where fewer than two keypoints
    were detected."""
    kp = np.asarray(keypoints, dtype=np.float64)
    if kp.ndim != 3 or kp.shape[1:] != (N_KEYPOINTS, 3):
        raise ValueError(f"keypoints must have shape (M, 17, 3), got {kp.shape}")
    det = kp[..., 2] > 0
    v = kp[..., 1]
    hi = np.where(det, v, -np.inf).max(axis=1)
    lo = np.where(det, v, np.inf).min(axis=1)
    return np.where(det.sum(axis=1) >= 2, hi - lo, np.nan)


def body_span_m(truth: Mapping[str, np.ndarray]) -> float:
    """The one body span (m) of the naive pinhole estimate: the median over truth rows of
    depth * (true keypoints' vertical pixel extent) / fy, keypoints in the image only. It is
    the constant that makes ``pinhole_depth`` unbiased in the median on noise-free keypoints."""
    kp = np.concatenate([np.asarray(truth["keypoints_px"], dtype=np.float64),
                         np.asarray(truth["in_image"], dtype=np.float64)[..., None]], axis=-1)
    extent = keypoint_extent_px(kp)
    fy = np.asarray(truth["intrinsics"], dtype=np.float64)[:, 1, 1]
    return _nan_stat(np.median, np.asarray(truth["depth"], dtype=np.float64) * extent / fy)


def pinhole_depth(keypoints: np.ndarray, intrinsics: np.ndarray, span_m: float) -> np.ndarray:
    """Naive per-frame depth from the keypoints' vertical extent: z = fy * span_m / extent.

    keypoints (M, 17, 3) pixel u, v, conf; intrinsics (M, 3, 3); span_m the assumed body span
    in metres. Returns float64 (M,), NaN where the extent is undefined or not positive (missed
    keypoints shrink the extent, so they bias the estimate far)."""
    if not span_m > 0:
        raise ValueError(f"span_m must be positive, got {span_m}")
    extent = keypoint_extent_px(keypoints)
    fy = np.asarray(intrinsics, dtype=np.float64)[:, 1, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(extent > 0, fy * span_m / extent, np.nan)


def pinhole_stats(truth: Mapping[str, np.ndarray], rec: Mapping[str, np.ndarray],
                  edges: tuple[float, ...] = DEPTH_BINS, span_m: float | None = None) -> pd.DataFrame:
    """Error of ``pinhole_depth`` on the detections, by true depth (rows per bin, then 'all').

    ``span_m`` defaults to ``body_span_m(truth)``. Columns: bin, depth_lo, depth_hi, n,
    mae_m (mean |z_hat - z|), median_ae_m, rel_mae (mean |z_hat - z| / z), bias_m (median of
    z_hat - z), span_m. Rows whose estimate is undefined are left out (n counts the rest)."""
    span = body_span_m(truth) if span_m is None else float(span_m)
    z_hat = pinhole_depth(rec["keypoints"], rec["intrinsics"], span)
    z = np.asarray(rec["depth"], dtype=np.float64)
    err = z_hat - z
    rows = []
    for name, lo, hi, where in _bins(z, edges):
        ok = where & np.isfinite(err)
        rows.append({"bin": name, "depth_lo": lo, "depth_hi": hi, "n": int(ok.sum()),
                     "mae_m": _nan_stat(np.mean, np.abs(err[ok])),
                     "median_ae_m": _nan_stat(np.median, np.abs(err[ok])),
                     "rel_mae": _nan_stat(np.mean, np.abs(err[ok]) / z[ok]),
                     "bias_m": _nan_stat(np.median, err[ok]), "span_m": span})
    return pd.DataFrame(rows)


# ----------------------------------------------------------------------------- across frames
def _lag_pairs(rec: Mapping[str, np.ndarray], lag: int, period_us: int) -> tuple[np.ndarray, np.ndarray]:
    """Rows (a, b) of ``rec`` of the same track, b exactly ``lag`` keyframes after a."""
    keys = _row_keys(rec)
    order = np.argsort(keys, kind="stable")
    wanted = keys + np.int64(lag * period_us)
    pos = np.minimum(np.searchsorted(keys, wanted, sorter=order), len(keys) - 1)
    b = order[pos]
    hit = keys[b] == wanted
    return np.flatnonzero(hit), b[hit]


def _corr(x: np.ndarray, y: np.ndarray) -> float:
    ok = np.isfinite(x) & np.isfinite(y)
    if ok.sum() < 3:
        return float("nan")
    return float(np.corrcoef(x[ok], y[ok])[0, 1])


def error_autocorrelation(truth: Mapping[str, np.ndarray], rec: Mapping[str, np.ndarray], lag: int = 1,
                          span_m: float | None = None, period_us: int = 500_000) -> dict[str, Any]:
    """Correlation of errors between detections of one track ``lag`` keyframes apart.

    'keypoint': Pearson correlation of the signed keypoint errors (u and v, each divided by the
    pixel height; same keypoint, detected in both frames) -- the detector draws them independently
    per frame, so it is about 0 up to the sampling error ~1 / sqrt(n_keypoint_pairs).
    'pinhole_rel': correlation of the pinhole depth's relative error (z_hat - z) / z -- not 0 even
    with independent keypoint errors, because a person's height differs from ``span_m`` in every
    frame. Also 'n_pairs' (detection pairs) and 'n_keypoint_pairs'."""
    if isinstance(lag, bool) or not isinstance(lag, (int, np.integer)) or lag < 1:
        raise ValueError(f"lag must be a positive integer, got {lag!r}")
    a, b = _lag_pairs(rec, int(lag), period_us)
    e = keypoint_errors(truth, rec)
    rel = e["signed"] / e["height_px"][:, None, None]  # (M,17,2)
    both = e["detected"][a] & e["detected"][b]  # (n,17)
    x, y = rel[a][both].ravel(), rel[b][both].ravel()
    span = body_span_m(truth) if span_m is None else float(span_m)
    z = np.asarray(rec["depth"], dtype=np.float64)
    zr = (pinhole_depth(rec["keypoints"], rec["intrinsics"], span) - z) / z
    return {"lag": int(lag), "n_pairs": int(len(a)), "n_keypoint_pairs": int(both.sum()),
            "keypoint": _corr(x, y), "pinhole_rel": _corr(zr[a], zr[b])}


# ----------------------------------------------------------------------------- one table
def simulator_table(truth: Mapping[str, np.ndarray], records: Mapping[float, Mapping[str, np.ndarray]],
                    edges: tuple[float, ...] = DEPTH_BINS) -> pd.DataFrame:
    """All per-bin statistics for every noise level: ``records`` maps p -> records simulated from
    ``truth``. Rows: (p, bin); columns of ``detection_stats``, ``keypoint_stats`` and
    ``pinhole_stats`` (the pinhole's 'mae_m' as 'pinhole_mae_m', 'bias_m' as 'pinhole_bias_m')."""
    span = body_span_m(truth)
    parts = []
    for p, rec in records.items():
        det = detection_stats(truth, rec, edges)[["bin", "depth_lo", "depth_hi", "n_true", "miss_rate"]]
        kp = keypoint_stats(truth, rec, edges).drop(columns=["depth_lo", "depth_hi"])
        ph = pinhole_stats(truth, rec, edges, span)[["bin", "mae_m", "bias_m"]].rename(
            columns={"mae_m": "pinhole_mae_m", "bias_m": "pinhole_bias_m"})
        parts.append(det.merge(kp, on="bin").merge(ph, on="bin").assign(p=float(p)))
    out = pd.concat(parts, ignore_index=True)
    return out[["p", *[c for c in out.columns if c != "p"]]]
