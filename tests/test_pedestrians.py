"""Simulated pedestrians and the shared record format (drfkit.data.sim_world, sim_detector, drawing, pedestrians, records)."""
import numpy as np
import pytest

from drfkit.data.noise import Noise
from drfkit.data.drawing import _background, draw_skeletons, render_frame
from drfkit.study.pedestrian_runs import load_pedestrians
from drfkit.data.sim_detector import DetectorConfig, detect, simulate_records
from drfkit.data.sim_world import CAM_FRONT_INTRINSICS, IMAGE_HEIGHT, IMAGE_WIDTH, simulate_truth
from drfkit.data.records import (
    RECORD_FIELDS,
    check_records,
    make_sequences,
    normalise_keypoints,
    split_by_scene,
)

SMALL = dict(n_scenes=30, frames_per_scene=20, seed=3)


@pytest.fixture(scope="module")
def truth():
    return simulate_truth(**SMALL)


@pytest.fixture(scope="module")
def recs(truth):
    return {p: simulate_records(truth, Noise("salt_and_pepper", p), seed=5) for p in (0.0, 0.01, 0.025, 0.05)}


def _keys(rec):
    """(track, timestamp) pairs identifying one pedestrian-keyframe."""
    return rec["track_id"] * 10**12 + (rec["timestamp"] % 10**12)


def _align(truth, rec):
    """Row of truth for every row of rec."""
    kt, kr = _keys(truth), _keys(rec)
    order = np.argsort(kt)
    pos = order[np.searchsorted(kt, kr, sorter=order)]
    assert np.array_equal(kt[pos], kr)
    return pos


# ---------------------------------------------------------------- simulated world


def test_default_size_is_near_the_papers():
    truth = simulate_truth()  # 165 scenes x 20 keyframes
    assert truth["n_images"][0] == 3300
    assert 3400 <= len(np.unique(truth["track_id"])) <= 4000
    rec = simulate_records(truth, Noise("salt_and_pepper", 0.01), seed=0)
    check_records(rec)
    assert 3400 <= len(np.unique(rec["track_id"])) <= 4000  # "about 3700 pedestrian instances"
    assert len(np.unique(rec["image_id"])) >= 3200  # nearly every image shows someone


def test_truth_geometry(truth):
    m = len(truth["depth"])
    assert m > 1000
    depth = truth["depth"]
    assert depth.min() > 1.0 and depth.max() <= 50.0
    assert np.percentile(depth, 10) < 12 and np.percentile(depth, 90) > 35  # spread over a few..50 m
    np.testing.assert_allclose(truth["distance"], np.linalg.norm(truth["position"], axis=1), rtol=1e-6)
    # Box centre projects inside the image (the recording rule).
    k = CAM_FRONT_INTRINSICS
    u = k[0, 0] * truth["position"][:, 0] / depth + k[0, 2]
    v = k[1, 1] * truth["position"][:, 1] / depth + k[1, 2]
    assert np.all((u >= 0) & (u < IMAGE_WIDTH) & (v >= 0) & (v < IMAGE_HEIGHT))
    # keypoints_px is the pinhole projection of the 3D skeleton.
    sk = truth["skeleton"].astype(np.float64)
    np.testing.assert_allclose(truth["keypoints_px"][..., 0], k[0, 0] * sk[..., 0] / sk[..., 2] + k[0, 2], atol=0.05)
    np.testing.assert_allclose(truth["keypoints_px"][..., 1], k[1, 1] * sk[..., 1] / sk[..., 2] + k[1, 2], atol=0.05)
    # Feet on the road 1.5 m below the camera, nose near the top of the body.
    ankle_lift = 1.5 - sk[:, 15:17, 1]  # height of the ankles above the road
    assert np.all(ankle_lift > 0)
    np.testing.assert_allclose(ankle_lift.min(axis=1), 0.035 * truth["height"], rtol=1e-4)  # stance foot
    assert np.mean(ankle_lift.max(axis=1) > 0.06 * truth["height"]) > 0.2  # swing foot lifted
    span = sk[..., 1].max(axis=1) - sk[..., 1].min(axis=1)
    assert np.all(span > 0.8 * truth["height"]) and np.all(span < truth["height"])
    # Box centre half a body height above the road.
    np.testing.assert_allclose(truth["position"][:, 1], 1.5 - truth["height"] / 2, atol=1e-5)


def test_people_are_realistic(truth):
    first = np.unique(truth["track_id"], return_index=True)[1]
    height, speed = truth["height"][first], truth["speed"][first]
    assert height.min() >= 1.5 and height.max() <= 1.95
    walking = speed > 0
    assert np.all((speed[walking] >= 1.0) & (speed[walking] <= 1.8))
    assert 0.05 < np.mean(~walking) < 0.3  # some stand still
    # Standing people keep their ankles side by side; walking people swing their legs.
    gap = np.abs(truth["skeleton"][:, 15, :] - truth["skeleton"][:, 16, :])  # (M, 3)
    gap = np.linalg.norm(gap, axis=1) / truth["height"]
    still = truth["speed"] == 0
    np.testing.assert_allclose(gap[still], 2 * 0.085, atol=1e-4)
    assert np.mean(gap[~still] > 0.25) > 0.2


def test_people_enter_and_leave_the_view(truth):
    starts = {}
    ends = {}
    frame = (truth["image_id"] % SMALL["frames_per_scene"])
    for t, f in zip(truth["track_id"], frame):
        starts[t] = min(starts.get(t, 99), f)
        ends[t] = max(ends.get(t, -1), f)
    starts, ends = np.array(list(starts.values())), np.array(list(ends.values()))
    assert np.mean(starts > 0) > 0.2  # entered after the scene began
    assert np.mean(ends < SMALL["frames_per_scene"] - 1) > 0.2  # left before it ended


def test_simulation_is_deterministic_and_seed_dependent():
    a = simulate_truth(n_scenes=4, frames_per_scene=10, seed=1)
    b = simulate_truth(n_scenes=4, frames_per_scene=10, seed=1)
    c = simulate_truth(n_scenes=4, frames_per_scene=10, seed=2)
    for key in a:
        np.testing.assert_array_equal(a[key], b[key])
    assert len(a["depth"]) != len(c["depth"]) or not np.array_equal(a["depth"], c["depth"])
    ra, rb = simulate_records(a, Noise("salt_and_pepper", 0.025), seed=9), simulate_records(b, Noise("salt_and_pepper", 0.025), seed=9)
    for key in ra:
        np.testing.assert_array_equal(ra[key], rb[key])
    rc = simulate_records(a, Noise("salt_and_pepper", 0.025), seed=10)
    assert not np.array_equal(ra["keypoints"][:5], rc["keypoints"][:5])


# ---------------------------------------------------------------- simulated detector


def test_records_pass_the_check_and_keypoints_lie_in_the_image(recs):
    for p, rec in recs.items():
        assert check_records(rec) == len(rec["depth"])
        np.testing.assert_array_equal(rec["noise"], np.float32(p))
        kp = rec["keypoints"]
        det = kp[..., 2] > 0
        assert np.all((kp[..., 0][det] >= 0) & (kp[..., 0][det] < IMAGE_WIDTH))
        assert np.all((kp[..., 1][det] >= 0) & (kp[..., 1][det] < IMAGE_HEIGHT))
        np.testing.assert_array_equal(kp[~det], 0.0)  # missed = (0, 0, 0), as PifPaf
        assert det.sum(axis=1).min() >= DetectorConfig().min_keypoints
        # The box holds every detected keypoint.
        x, y, w, h = rec["box"].T
        assert np.all(np.where(det, kp[..., 0] >= x[:, None] - 1e-3, True))
        assert np.all(np.where(det, kp[..., 0] <= (x + w)[:, None] + 1e-3, True))
        assert np.all(np.where(det, kp[..., 1] <= (y + h)[:, None] + 1e-3, True))


def test_same_people_across_noise_levels(truth, recs):
    low, high = recs[0.01], recs[0.05]
    # Coupled draws: a detection kept at high noise is kept at low noise too.
    assert set(_keys(high)) <= set(_keys(low))
    common = np.isin(_keys(low), _keys(high))
    for key in ("position", "intrinsics", "track_id", "scene_id", "image_id", "timestamp"):
        np.testing.assert_array_equal(low[key][common], high[key])
    # A keypoint detected at high noise is detected at low noise.
    det_low = low["keypoints"][common][..., 2] > 0
    det_high = high["keypoints"][..., 2] > 0
    assert np.all(det_low | ~det_high)
    # The ground truth behind the records is the shared truth.
    pos = _align(truth, high)
    np.testing.assert_array_equal(high["position"], truth["position"][pos])


def _relative_error(truth, rec):
    pos = _align(truth, rec)
    det = rec["keypoints"][..., 2] > 0
    err = np.linalg.norm(rec["keypoints"][..., :2] - truth["keypoints_px"][pos], axis=-1)
    return err / truth["height_px"][pos][:, None], det, truth["depth"][pos]


def test_detector_gets_worse_with_noise(truth, recs):
    medians, miss, conf, kept = [], [], [], []
    for p in (0.0, 0.01, 0.025, 0.05):
        rel, det, _ = _relative_error(truth, recs[p])
        medians.append(np.median(rel[det]))
        miss.append(1 - det.mean())
        conf.append(recs[p]["keypoints"][..., 2][det].mean())
        kept.append(len(recs[p]["depth"]))
    assert np.all(np.diff(medians) > 0), medians
    assert np.all(np.diff(miss) > 0), miss
    assert np.all(np.diff(conf) < 0), conf
    assert np.all(np.diff(kept) < 0), kept
    assert medians[3] > 1.5 * medians[1]  # the shift is large enough to matter


def test_detector_gets_worse_with_distance(truth, recs):
    rel, det, depth = _relative_error(truth, recs[0.025])
    near, far = depth < 15, depth > 30
    assert np.median(rel[near][det[near]]) < 0.8 * np.median(rel[far][det[far]])
    assert det[near].mean() > det[far].mean()
    # Whole detections are missed more often far away.
    rec = recs[0.025]
    rate = lambda sel_t, sel_r: sel_r.sum() / sel_t.sum()  # noqa: E731
    assert rate(truth["depth"] < 15, rec["depth"] < 15) > rate(truth["depth"] > 30, rec["depth"] > 30)


def test_detector_draws_gross_outliers(truth):
    cfg = DetectorConfig(outlier_base=0.2, outlier_scale=0.5)
    rec = simulate_records(truth, Noise("salt_and_pepper", 0.0), seed=1, config=cfg)
    rel, det, _ = _relative_error(truth, rec)
    clean_rel, clean_det, _ = _relative_error(truth, simulate_records(truth, Noise("salt_and_pepper", 0.0), seed=1))
    assert np.mean(rel[det] > 0.2) > 0.1
    assert np.mean(clean_rel[clean_det] > 0.2) < 0.03


def test_detect_validates_inputs(truth):
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="noise level of kind salt_and_pepper must lie in"):
        detect(truth, Noise("salt_and_pepper", 1.5), rng)
    with pytest.raises(TypeError, match="takes a Noise value"):
        detect(truth, 0.01, rng)  # a bare number: which kind?
    with pytest.raises(ValueError, match="no corruption of pedestrian data for rkn_uniform.*PEDESTRIAN_CORRUPTIONS"):
        detect(truth, Noise("rkn_uniform", 0.01), rng)
    with pytest.raises(TypeError, match="Generator"):
        detect(truth, Noise("salt_and_pepper", 0.01), 0)
    with pytest.raises(ValueError, match="keypoints_px"):
        detect({"depth": truth["depth"]}, Noise("salt_and_pepper", 0.01), rng)


def test_detector_config_validation():
    cfg = DetectorConfig.from_dict({"pixel_sigma": 2.0, "min_keypoints": 5})
    assert cfg.pixel_sigma == 2.0 and cfg.min_keypoints == 5
    assert DetectorConfig.from_dict(cfg.to_dict()) == cfg
    assert DetectorConfig.from_dict(None) == DetectorConfig()
    with pytest.raises(ValueError, match=r"unknown DetectorConfig key\(s\) \['pixel_sigm'\]"):
        DetectorConfig.from_dict({"pixel_sigm": 2.0})
    with pytest.raises(ValueError, match="rel_sigma must be a finite number >= 0"):
        DetectorConfig.from_dict({"rel_sigma": -0.1})
    with pytest.raises(ValueError, match="miss_max is a probability"):
        DetectorConfig.from_dict({"miss_max": 1.5})
    with pytest.raises(ValueError, match="min_keypoints"):
        DetectorConfig.from_dict({"min_keypoints": 0})
    with pytest.raises(TypeError, match="conf_sd must be a number"):
        DetectorConfig.from_dict({"conf_sd": "0.1"})
    with pytest.raises(ValueError, match="conf_min <= conf_base"):
        DetectorConfig.from_dict({"conf_min": 0.9, "conf_base": 0.5})
    with pytest.raises(ValueError, match="ref_height_px"):
        DetectorConfig(ref_height_px=0.0)
    with pytest.raises(TypeError, match="dict"):
        DetectorConfig.from_dict([1, 2])


def test_simulate_truth_validates_inputs():
    with pytest.raises(ValueError, match="n_scenes"):
        simulate_truth(n_scenes=0)
    with pytest.raises(TypeError, match="frames_per_scene"):
        simulate_truth(frames_per_scene=2.5)
    with pytest.raises(ValueError, match="spawn_depth_range"):
        simulate_truth(n_scenes=2, spawn_depth_range=(10.0, 5.0))


# ---------------------------------------------------------------- loader, cache, pictures


def test_load_pedestrians_caches_by_parameters(tmp_path):
    kw = dict(n_scenes=5, frames_per_scene=8, seed=2, detector={"pixel_sigma": 1.5})
    a = load_pedestrians(tmp_path, "simulated", Noise("salt_and_pepper", 0.025), **kw)
    files = sorted(tmp_path.glob("pedestrians-sim-*.npz"))
    assert len(files) == 1
    b = load_pedestrians(tmp_path, "simulated", Noise("salt_and_pepper", 0.025), **kw)
    for key in a:
        np.testing.assert_array_equal(a[key], b[key])
    truth = simulate_truth(5, 8, 2)
    direct = simulate_records(truth, Noise("salt_and_pepper", 0.025), 2, DetectorConfig(pixel_sigma=1.5))
    np.testing.assert_array_equal(a["keypoints"], direct["keypoints"])
    load_pedestrians(tmp_path, "simulated", Noise("salt_and_pepper", 0.05), **kw)
    load_pedestrians(tmp_path, "simulated", Noise("salt_and_pepper", 0.025), **{**kw, "detector": None})
    assert len(list(tmp_path.glob("pedestrians-sim-*.npz"))) == 3
    with pytest.raises(ValueError, match="source"):
        load_pedestrians(tmp_path, "kitti", Noise("salt_and_pepper", 0.01))
    with pytest.raises(ValueError, match="nuscenes_root"):
        load_pedestrians(tmp_path, "nuscenes", Noise("salt_and_pepper", 0.01))


def test_render_frame_and_skeletons(truth, recs):
    image_id = int(np.bincount(truth["image_id"]).argmax())
    clean = render_frame(truth, image_id, 0.0, seed=1)
    noisy = render_frame(truth, image_id, 0.05, seed=1)
    assert clean.shape == (900, 1600, 3) and clean.dtype == np.uint8
    changed = np.any(clean != noisy, axis=-1).mean()
    assert 0.04 < changed < 0.055  # salt and pepper at p = 0.05 (few pixels were already black/white)
    # A pedestrian is drawn where its box is.
    row = np.flatnonzero(truth["image_id"] == image_id)[0]
    u, v = (int(x) for x in truth["keypoints_px"][row, 5])  # left shoulder
    background = _background()
    assert np.any(clean[v - 3:v + 4, u - 3:u + 4] != background[v - 3:v + 4, u - 3:u + 4])
    far_from_people = np.ones((900, 1600), bool)
    for kp in truth["keypoints_px"][truth["image_id"] == image_id]:
        x0, y0 = np.maximum(kp.min(axis=0).astype(int) - 60, 0)
        x1, y1 = kp.max(axis=0).astype(int) + 60
        far_from_people[y0:y1, x0:x1] = False
    np.testing.assert_array_equal(clean[far_from_people], background[far_from_people])
    rec = recs[0.01]
    from_records = render_frame(rec, int(rec["image_id"][0]), 0.01, seed=1)
    assert from_records.shape == (900, 1600, 3)
    with pytest.raises(ValueError, match="image_id"):
        render_frame(truth, -5, 0.0)
    blank = np.zeros((100, 100, 3), np.uint8)
    kp = np.zeros((17, 3), np.float32)
    kp[5] = (20, 20, 0.9)
    kp[6] = (80, 20, 0.9)
    drawn = draw_skeletons(blank, kp, colour=(255, 0, 0))
    assert blank.sum() == 0  # the input is left alone
    assert drawn[20, 50, 0] > 0  # the shoulder line
    assert drawn[80, 50].sum() == 0  # nothing where there is no keypoint
    with pytest.raises(ValueError, match="keypoints"):
        draw_skeletons(blank, np.zeros((5, 3)))


# ---------------------------------------------------------------- record format


def _toy_records():
    """Two tracks in two scenes, rows deliberately out of time order."""
    t0 = 1_000_000_000
    # track 7 (scene 0): 7 keyframes; track 9 (scene 1): frames at 0, 0.5, 1.5, 2.0 s (a gap).
    times7 = t0 + 500_000 * np.arange(7)
    times9 = t0 + np.array([0, 500_000, 1_500_000, 2_000_000])
    track = np.array([7] * 7 + [9] * 4)
    time = np.concatenate([times7, times9])
    perm = np.array([3, 0, 6, 1, 5, 2, 4, 10, 8, 7, 9])
    m = len(track)
    depth = np.arange(m, dtype=np.float32) + 5.0
    position = np.stack([np.zeros(m), np.ones(m), depth], axis=1).astype(np.float32)
    kp = np.zeros((m, 17, 3), np.float32)
    kp[:, :, 0] = 900.0
    kp[:, :, 1] = 500.0
    kp[:, :, 2] = 0.8
    kp[:, 3] = 0.0  # a missed keypoint
    rec = {
        "keypoints": kp,
        "intrinsics": np.broadcast_to(np.array([[1000, 0, 800], [0, 1000, 450], [0, 0, 1]], np.float32), (m, 3, 3)).copy(),
        "position": position,
        "depth": depth,
        "distance": np.linalg.norm(position, axis=1).astype(np.float32),
        "box": np.tile(np.float32([880, 480, 40, 80]), (m, 1)),
        "track_id": track.astype(np.int64),
        "scene_id": (track == 9).astype(np.int64),
        "timestamp": time.astype(np.int64),
        "image_id": np.arange(m, dtype=np.int64),
        "noise": np.full(m, 0.01, np.float32),
    }
    return {k: v[perm] for k, v in rec.items()}


def test_record_fields_and_check_errors():
    rec = _toy_records()
    assert set(RECORD_FIELDS) == set(rec)
    assert check_records(rec) == 11
    bad = dict(rec)
    del bad["depth"]
    with pytest.raises(ValueError, match="miss field"):
        check_records(bad)
    old = {("noise_p" if k == "noise" else k): v for k, v in rec.items()}  # records from before the rename
    with pytest.raises(ValueError, match="'noise_p' was renamed 'noise'"):
        check_records(old)
    with pytest.raises(TypeError, match="dtype float32"):
        check_records({**rec, "depth": rec["depth"].astype(np.float64)})
    with pytest.raises(ValueError, match="trailing shape"):
        check_records({**rec, "keypoints": rec["keypoints"][:, :, :2]})
    with pytest.raises(ValueError, match="unequal lengths"):
        check_records({**rec, "noise": rec["noise"][:3]})
    with pytest.raises(ValueError, match="empty"):
        check_records({k: v[:0] for k, v in rec.items()})
    nan = rec["keypoints"].copy()
    nan[0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        check_records({**rec, "keypoints": nan})
    with pytest.raises(ValueError, match="position z"):
        check_records({**rec, "depth": rec["depth"] + 1})
    with pytest.raises(ValueError, match="unequal lengths"):
        check_records({**rec, "extra": np.zeros(2)})


def test_normalise_keypoints_known_answer():
    k = np.array([[1000.0, 0, 800], [0, 500.0, 450], [0, 0, 1]])
    kp = np.array([[1800.0, 450.0, 0.7], [800.0, 950.0, 0.2], [123.0, 456.0, 0.0]])
    kp = np.concatenate([kp, np.zeros((14, 3))])
    out = normalise_keypoints(kp, k)
    assert out.dtype == np.float32 and out.shape == (17, 3)
    np.testing.assert_allclose(out[0], [10.0, 0.0, 0.7], atol=1e-6)  # 10 * (1800 - 800) / 1000
    np.testing.assert_allclose(out[1], [0.0, 10.0, 0.2], atol=1e-6)  # 10 * (950 - 450) / 500
    # a missed keypoint is PifPaf's placeholder pixel (0, -3) back-projected, whatever its u, v
    np.testing.assert_allclose(out[2:, :2], np.broadcast_to([10 * (0 - 800) / 1000, 10 * (-3 - 450) / 500], (15, 2)),
                               atol=1e-5)
    np.testing.assert_array_equal(out[2:, 2], 0.0)
    k2 = k.copy()
    k2[0, 0] = 2000.0
    batch = normalise_keypoints(np.stack([kp, kp]), np.stack([k, k2]))  # one K per row
    np.testing.assert_allclose(batch[0], out)
    np.testing.assert_allclose(batch[1, 0], [5.0, 0.0, 0.7], atol=1e-6)
    shared = normalise_keypoints(np.stack([kp, kp]), k)  # one K broadcast over the batch
    np.testing.assert_allclose(shared[1], out)
    with pytest.raises(ValueError, match="NaN"):
        normalise_keypoints(np.full((17, 3), np.nan), k)
    with pytest.raises(ValueError, match=r"\(\.\.\., 17, 3\)"):
        normalise_keypoints(np.zeros((16, 3)), k)


def test_make_sequences_windows_masks_and_order():
    rec = _toy_records()
    bridged = make_sequences(rec, seq_len=3)  # default: one missed keyframe (a 1 s gap) is bridged
    np.testing.assert_array_equal(bridged["mask"].sum(axis=1), [3, 3, 1, 3, 1])
    seq = make_sequences(rec, seq_len=3, max_gap_s=0.75)
    # Track 7: 7 frames -> windows of 3, 3, 1; track 9 broken at the 1 s gap -> 2 + 2.
    assert seq["inputs"].shape == (5, 3, 17, 3) and seq["targets"].shape == (5, 3, 1)
    np.testing.assert_array_equal(seq["track_id"], [7, 7, 7, 9, 9])
    np.testing.assert_array_equal(seq["scene_id"], [0, 0, 0, 1, 1])
    np.testing.assert_array_equal(seq["mask"].sum(axis=1), [3, 3, 1, 2, 2])
    assert seq["mask"].dtype == bool
    np.testing.assert_array_equal(seq["mask"][2], [True, False, False])
    # Ordered by time within each window and across windows of a track.
    for times, mask in zip(seq["timestamp"], seq["mask"]):
        assert np.all(np.diff(times[mask]) > 0)
    assert np.all(np.diff(seq["timestamp"][:3, 0]) > 0)
    # Targets are the depths in time order (depth was assigned in time order before shuffling).
    np.testing.assert_array_equal(seq["targets"][0, :, 0], [5, 6, 7])
    np.testing.assert_array_equal(seq["targets"][2, :, 0], [11, 11, 11])  # padding repeats the last frame
    np.testing.assert_array_equal(seq["targets"][4, :, 0], [14, 15, 15])
    # Inputs are the normalised keypoints of those rows.
    rows = seq["record_index"]
    np.testing.assert_allclose(seq["inputs"], normalise_keypoints(rec["keypoints"][rows], rec["intrinsics"][rows]))
    np.testing.assert_allclose(seq["inputs"][0, 0, 0], [1.0, 0.5, 0.8], atol=1e-6)  # 10 * (900-800)/1000
    np.testing.assert_array_equal(seq["distance"], rec["distance"][rows])
    # Overlapping windows: stride 1 over 7 frames gives 5 full windows, no tail.
    over = make_sequences({k: v[rec["track_id"] == 7] for k, v in rec.items()}, seq_len=3, stride=1)
    assert over["mask"].all() and len(over["track_id"]) == 5
    # A wider gap tolerance joins track 9 again.
    joined = make_sequences(rec, seq_len=4, max_gap_s=1.1)
    assert joined["mask"][joined["track_id"] == 9].sum() == 4


def test_make_sequences_rejects_duplicate_times_and_bad_lengths():
    rec = _toy_records()
    dup = {k: np.concatenate([v, v[:1]]) for k, v in rec.items()}
    with pytest.raises(ValueError, match="same timestamp"):
        make_sequences(dup, 3)
    with pytest.raises(ValueError, match="seq_len"):
        make_sequences(rec, 0)
    with pytest.raises(ValueError, match="stride"):
        make_sequences(rec, 3, stride=0)


def test_split_by_scene_has_no_leakage(recs):
    rec = recs[0.01]
    splits = split_by_scene(rec, (0.7, 0.15, 0.15), seed=4)
    assert set(splits) == {"train", "val", "test"}
    scenes = {name: set(np.unique(part["scene_id"])) for name, part in splits.items()}
    assert not scenes["train"] & scenes["val"] and not scenes["train"] & scenes["test"]
    assert not scenes["val"] & scenes["test"]
    assert sum(len(part["depth"]) for part in splits.values()) == len(rec["depth"])
    assert sorted(len(s) for s in scenes.values()) == [4, 5, 21]  # 30 scenes, counted in scenes
    for part in splits.values():
        check_records(part)
    again = split_by_scene(rec, (0.7, 0.15, 0.15), seed=4)
    np.testing.assert_array_equal(again["test"]["scene_id"], splits["test"]["scene_id"])
    other = split_by_scene(rec, (0.7, 0.15, 0.15), seed=5)
    assert set(np.unique(other["test"]["scene_id"])) != scenes["test"]
    two = split_by_scene(rec, (0.8, 0.2), seed=0)
    assert set(two) == {"train", "test"}
    with pytest.raises(ValueError, match="sum to 1"):
        split_by_scene(rec, (0.5, 0.2, 0.2))
    one_scene = {k: v[rec["scene_id"] == rec["scene_id"][0]] for k, v in rec.items()}
    with pytest.raises(ValueError, match="cannot split 1 scene"):
        split_by_scene(one_scene)
