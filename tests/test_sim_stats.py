"""The simulator's statistics (drfkit.data.sim_stats): known answers on small synthetic inputs."""
import numpy as np
import pytest

from drfkit.data.noise import Noise
from drfkit.data.sim_detector import DetectorConfig, simulate_records
from drfkit.data.sim_stats import (
    align_to_truth,
    body_span_m,
    dataset_size,
    depth_bin,
    detection_stats,
    error_autocorrelation,
    keypoint_errors,
    keypoint_extent_px,
    keypoint_stats,
    pinhole_depth,
    pinhole_stats,
    simulator_table,
)
from drfkit.data.sim_world import simulate_truth

SMALL = dict(n_scenes=12, frames_per_scene=20, seed=4)
P01 = Noise("salt_and_pepper", 0.01)

# a detector that sees every keypoint exactly: no error, no miss, no outlier
PERFECT = dict(pixel_sigma=0.0, rel_sigma=0.0, noise_sigma_gain=0.0, miss_base=0.0, miss_far=0.0,
               miss_noise_gain=0.0, outlier_base=0.0, outlier_noise_gain=0.0, det_miss_base=0.0,
               det_miss_far=0.0, det_miss_noise_gain=0.0, min_keypoints=1)


@pytest.fixture(scope="module")
def truth():
    return simulate_truth(**SMALL)


def _detectable(truth, min_keypoints=1):
    return truth["in_image"].sum(axis=1) >= min_keypoints


def test_alignment_finds_every_record_and_rejects_strangers(truth):
    rec = simulate_records(truth, P01, seed=1)
    rows = align_to_truth(truth, rec)
    assert np.array_equal(truth["track_id"][rows], rec["track_id"])
    assert np.array_equal(truth["timestamp"][rows], rec["timestamp"])
    bad = dict(rec, track_id=rec["track_id"] + 10**6)
    with pytest.raises(ValueError, match="absent from the truth"):
        align_to_truth(truth, bad)


def test_depth_bins():
    assert depth_bin(np.array([0.0, 0.5, 10.0, 10.01, 50.0, 50.5])).tolist() == [-1, 0, 0, 1, 4, -1]
    with pytest.raises(ValueError):
        depth_bin(np.array([1.0]), (0.0, 0.0))


def test_perfect_detector_has_zero_keypoint_error_and_misses_nothing(truth):
    rec = simulate_records(truth, P01, seed=2, config=DetectorConfig(**PERFECT))
    e = keypoint_errors(truth, rec)
    # detected positions are clipped to [0, width - 1] x [0, height - 1]: exact except in the last pixel
    true_px = truth["keypoints_px"][e["truth_row"]]
    inner = e["detected"] & (true_px[..., 0] <= 1599) & (true_px[..., 1] <= 899)
    assert np.max(e["error_px"][inner]) < 1e-3  # float32 storage of pixel positions
    assert np.nanmax(e["error_px"]) < 1.0
    assert np.array_equal(e["detected"], e["visible"])
    kp = keypoint_stats(truth, rec)
    assert (kp["kp_miss_rate"] == 0).all() and (kp["gross_rate"] == 0).all()
    det = detection_stats(truth, rec)
    overall = det.set_index("bin").loc["all"]
    # only people with no keypoint inside the image go undetected
    assert overall["miss_rate"] == pytest.approx(1 - _detectable(truth).mean())


@pytest.mark.parametrize("p_miss", [0.1, 0.3])
def test_detection_miss_rate_within_binomial_tolerance(truth, p_miss):
    cfg = DetectorConfig(**(PERFECT | dict(det_miss_base=p_miss)))
    rec = simulate_records(truth, P01, seed=3, config=cfg)
    n = int(_detectable(truth).sum())
    rate = 1 - len(rec["track_id"]) / n
    assert abs(rate - p_miss) < 4 * np.sqrt(p_miss * (1 - p_miss) / n)
    det = detection_stats(truth, rec).set_index("bin")
    assert det.loc["all", "n_true"] == len(truth["depth"])
    assert det.loc["all", "n_detected"] == len(rec["track_id"])
    assert det.drop(index="all")["n_true"].sum() == det.loc["all", "n_true"]  # depths all lie in (0, 50]


def test_keypoint_miss_rate_within_binomial_tolerance(truth):
    cfg = DetectorConfig(**(PERFECT | dict(miss_base=0.2)))
    rec = simulate_records(truth, P01, seed=5, config=cfg)
    e = keypoint_errors(truth, rec)
    n = int(e["visible"].sum())
    rate = keypoint_stats(truth, rec).set_index("bin").loc["all", "kp_miss_rate"]
    # rows keep >= 1 keypoint, a negligible selection for people with ~17 visible keypoints
    assert abs(rate - 0.2) < 4 * np.sqrt(0.2 * 0.8 / n) + 0.002


def test_keypoint_error_scales_with_pixel_sigma(truth):
    sigma = 2.0
    rec = simulate_records(truth, P01, seed=6, config=DetectorConfig(**(PERFECT | dict(pixel_sigma=sigma))))
    e = keypoint_errors(truth, rec)
    inside = e["visible"] & (e["height_px"][:, None] < 400)  # away from the clipping at the image border
    err = e["error_px"][inside]
    # |N(0, s^2 I_2)| is Rayleigh: median s * sqrt(2 ln 2), mean s * sqrt(pi / 2)
    assert np.median(err) == pytest.approx(sigma * np.sqrt(2 * np.log(2)), rel=0.03)
    assert np.mean(err) == pytest.approx(sigma * np.sqrt(np.pi / 2), rel=0.03)


def test_independent_errors_have_no_autocorrelation(truth):
    rec = simulate_records(truth, P01, seed=7, config=DetectorConfig(**(PERFECT | dict(pixel_sigma=3.0))))
    ac = error_autocorrelation(truth, rec)
    assert ac["n_keypoint_pairs"] > 10_000
    assert abs(ac["keypoint"]) < 4 / np.sqrt(2 * ac["n_keypoint_pairs"])
    with pytest.raises(ValueError):
        error_autocorrelation(truth, rec, lag=0)


def test_pinhole_depth_known_answer():
    k = np.array([[[1000.0, 0, 800], [0, 1000.0, 450], [0, 0, 1]]])
    kp = np.zeros((1, 17, 3))
    kp[0, 0] = (800, 400, 0.9)
    kp[0, 16] = (800, 500, 0.9)  # extent 100 px
    kp[0, 5] = (810, 9999, 0.0)  # missed: ignored
    assert keypoint_extent_px(kp)[0] == pytest.approx(100.0)
    assert pinhole_depth(kp, k, 1.5)[0] == pytest.approx(15.0)  # 1000 * 1.5 / 100
    kp[0, 16, 2] = 0.0  # one keypoint left: undefined
    assert np.isnan(pinhole_depth(kp, k, 1.5)[0])
    with pytest.raises(ValueError):
        pinhole_depth(kp, k, 0.0)


def test_pinhole_on_perfect_keypoints_is_nearly_unbiased(truth):
    rec = simulate_records(truth, P01, seed=8, config=DetectorConfig(**PERFECT))
    span = body_span_m(truth)
    assert 1.3 < span < 1.8  # eyes to ankles of people 1.5-1.95 m tall
    ph = pinhole_stats(truth, rec, span_m=span).set_index("bin")
    assert abs(ph.loc["all", "bias_m"]) < 0.1
    # with exact keypoints the error comes from heights differing from one span: it persists along a track
    assert error_autocorrelation(truth, rec)["pinhole_rel"] > 0.5


def test_table_and_sizes(truth):
    recs = {p: simulate_records(truth, Noise("salt_and_pepper", p), seed=9) for p in (0.01, 0.05)}
    table = simulator_table(truth, recs)
    assert len(table) == 2 * 6 and set(table["p"]) == {0.01, 0.05}
    all_rows = table[table["bin"] == "all"].set_index("p")
    # the detector's coupling across p: more noise never detects more
    assert all_rows.loc[0.05, "miss_rate"] > all_rows.loc[0.01, "miss_rate"]
    assert all_rows.loc[0.05, "err_px_median"] > all_rows.loc[0.01, "err_px_median"]
    sizes = dataset_size(truth, recs[0.01])
    assert sizes["images"] == SMALL["n_scenes"] * SMALL["frames_per_scene"]
    assert sizes["tracks_detected"] <= sizes["tracks_true"]
    assert sizes["detections"] == len(recs[0.01]["track_id"])
