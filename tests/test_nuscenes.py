"""The real-data path (drfkit.data.nuscenes, nuscenes_tables, pifpaf) on a tiny fixture in the official nuScenes schema.

The fixture (written by ``_nusc_write_fixture``) has two scenes with known poses, so the
camera-frame box centres are known analytically:

* scene-0001: ego at (2k, 0, 0) with identity rotation, keyframes k = 0, 1, 2;
  pedestrian A (adult) at camera (x, y, z) = (-1.0, 0.6, 10), (-0.8, 0.6, 12), (-0.6, 0.6, 14);
  pedestrian B (adult) at (3.0, 0.6, 20), (3.2, 0.6, 22), then behind the camera (z = -5);
  a car at (0.0, 0.5, 15) in every keyframe (not a pedestrian).
* scene-0002: ego yawed by 90 degrees at (100, 50 + k, 0), k = 0, 1, its own intrinsics;
  pedestrian C (child) at (0.5, 0.7, 8), (0.4, 0.7, 9).

CAM_FRONT sits 1.5 m ahead of and 1.5 m above the ego origin with the usual nuScenes
rotation (w, x, y, z) = (0.5, -0.5, 0.5, -0.5), so camera (x, y, z) is ego (z + 1.5, -x, 1.5 - y).
PifPaf predictions: one file per CAM_FRONT keyframe, a detection near each visible
pedestrian's box except pedestrian B at k = 1 (missed), plus a far-away detection and one on
the car in every image.
"""
import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from drfkit.data.noise import Noise
from drfkit.data import nuscenes_tables
from drfkit.data.nuscenes import load_nuscenes_records, write_noisy_images
from drfkit.data.nuscenes_tables import (
    box_in_image_any,
    camera_images,
    project_annotations,
    quaternion_to_rotation,
    read_tables,
)
from drfkit.data.pifpaf import box_iou, enlarge_boxes, match_boxes, prediction_file_candidates, read_predictions
from drfkit.study.pedestrian_runs import load_pedestrians
from drfkit.data.sim_detector import simulate_records
from drfkit.data.sim_world import simulate_truth
from drfkit.data.records import RECORD_FIELDS, check_records
from drfkit.cli import main as cli

REPO = Path(__file__).resolve().parents[1]
VERSION = "v1.0-mini"
K_FRONT_A = [[1266.417, 0.0, 816.267], [0.0, 1266.417, 491.507], [0.0, 0.0, 1.0]]
K_FRONT_B = [[1260.0, 0.0, 800.0], [0.0, 1260.0, 450.0], [0.0, 0.0, 1.0]]
Q_FRONT = [0.5, -0.5, 0.5, -0.5]
Q_BACK = [0.5, -0.5, -0.5, 0.5]  # CAM_FRONT turned by 180 degrees about the vertical
Q_YAW90 = [np.cos(np.pi / 4), 0.0, 0.0, np.sin(np.pi / 4)]
PED_SIZE = (0.6, 0.7, 1.8)  # w, l, h
T0 = 1_533_151_603_512_404

# camera-frame positions per scene per keyframe (None: not annotated in that keyframe)
TRUTH = {
    "scene-0001": {
        "ped_a": ("human.pedestrian.adult", [(-1.0, 0.6, 10.0), (-0.8, 0.6, 12.0), (-0.6, 0.6, 14.0)]),
        "ped_b": ("human.pedestrian.adult", [(3.0, 0.6, 20.0), (3.2, 0.6, 22.0), (3.0, 0.6, -5.0)]),
        "car": ("vehicle.car", [(0.0, 0.5, 15.0)] * 3),
    },
    "scene-0002": {
        "ped_c": ("human.pedestrian.child", [(0.5, 0.7, 8.0), (0.4, 0.7, 9.0)]),
    },
}
MISSED = {("ped_b", 1)}  # PifPaf misses pedestrian B in scene-0001 keyframe 1


def _nusc_tok(*parts) -> str:
    return hashlib.md5("/".join(map(str, parts)).encode()).hexdigest()


def _nusc_ego(scene: str, k: int):
    """Ego pose (translation, rotation quaternion, rotation matrix) of a keyframe."""
    if scene == "scene-0001":
        return [2.0 * k, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0], np.eye(3)
    return [100.0, 50.0 + k, 0.0], Q_YAW90, np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def _nusc_cam_to_global(scene: str, k: int, cam_xyz) -> list[float]:
    x, y, z = cam_xyz
    ego = np.array([z + 1.5, -x, 1.5 - y])  # CAM_FRONT -> ego, by construction
    t, _, rot = _nusc_ego(scene, k)
    return list(rot @ ego + np.asarray(t))


def _nusc_expected_box(cam_xyz, k_matrix):
    """2D box of a pedestrian box whose length runs along the ego's forward axis."""
    x, y, z = cam_xyz
    w, l, h = PED_SIZE
    # box x (length) = ego forward -> camera z, box y (width) -> camera -x, box z (height) -> camera -y
    corners = np.array([(x + sx * w / 2, y + sy * h / 2, z + sz * l / 2)
                        for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    k = np.asarray(k_matrix)
    u = k[0, 0] * corners[:, 0] / corners[:, 2] + k[0, 2]
    v = k[1, 1] * corners[:, 1] / corners[:, 2] + k[1, 2]
    return np.array([u.min(), v.min(), u.max() - u.min(), v.max() - v.min()])


def _nusc_write_fixture(root: Path, *, with_images: bool = False) -> dict:
    """Write the fixture tables (and optionally tiny camera images); return helpful facts."""
    rng = np.random.default_rng(0)
    tables = {name: [] for name in nuscenes_tables.TABLES}
    sensors = {"CAM_FRONT": "camera", "CAM_BACK": "camera", "LIDAR_TOP": "lidar"}
    for channel, modality in sensors.items():
        tables["sensor"].append({"token": _nusc_tok("sensor", channel), "channel": channel, "modality": modality})
    categories = sorted({cat for scene in TRUTH.values() for cat, _ in scene.values()})
    for cat in categories:
        tables["category"].append({"token": _nusc_tok("cat", cat), "name": cat, "description": cat})
    images = []  # (scene, k, filename, intrinsics) of CAM_FRONT keyframes
    time = T0
    for s_idx, (scene, objects) in enumerate(TRUTH.items()):
        n_keyframes = len(next(iter(objects.values()))[1])
        sample_tokens = [_nusc_tok("sample", scene, k) for k in range(n_keyframes)]
        tables["scene"].append({
            "token": _nusc_tok("scene", scene), "log_token": _nusc_tok("log", scene), "nbr_samples": n_keyframes,
            "first_sample_token": sample_tokens[0], "last_sample_token": sample_tokens[-1],
            "name": scene, "description": "fixture",
        })
        k_front = K_FRONT_A if scene == "scene-0001" else K_FRONT_B
        cs = {
            "CAM_FRONT": {"translation": [1.5, 0.0, 1.5], "rotation": Q_FRONT, "camera_intrinsic": k_front},
            "CAM_BACK": {"translation": [-1.0, 0.0, 1.5], "rotation": Q_BACK, "camera_intrinsic": K_FRONT_A},
            "LIDAR_TOP": {"translation": [0.9, 0.0, 1.8], "rotation": [1.0, 0.0, 0.0, 0.0], "camera_intrinsic": []},
        }
        for channel, c in cs.items():
            tables["calibrated_sensor"].append({
                "token": _nusc_tok("cs", scene, channel), "sensor_token": _nusc_tok("sensor", channel), **c,
            })
        for name, (cat, _) in objects.items():
            n_ann = len(objects[name][1])
            tables["instance"].append({
                "token": _nusc_tok("instance", scene, name), "category_token": _nusc_tok("cat", cat),
                "nbr_annotations": n_ann, "first_annotation_token": _nusc_tok("ann", scene, name, 0),
                "last_annotation_token": _nusc_tok("ann", scene, name, n_ann - 1),
            })
        for k in range(n_keyframes):
            time += 500_000
            tables["sample"].append({
                "token": sample_tokens[k], "timestamp": time, "scene_token": _nusc_tok("scene", scene),
                "prev": sample_tokens[k - 1] if k else "", "next": sample_tokens[k + 1] if k + 1 < n_keyframes else "",
            })
            t_ego, q_ego, _ = _nusc_ego(scene, k)
            for channel, key_frame, dt in [(c, True, 0) for c in sensors] + [("CAM_FRONT", False, 250_000)]:
                sd_time = time + dt + (10_000 if channel == "CAM_BACK" else 0)
                sd_token = _nusc_tok("sd", scene, k, channel, key_frame)
                folder = "samples" if key_frame else "sweeps"
                ext = "pcd.bin" if channel == "LIDAR_TOP" else "jpg"
                filename = f"{folder}/{channel}/n008-2018-08-01-{scene}__{channel}__{sd_time}.{ext}"
                tables["ego_pose"].append({"token": sd_token, "timestamp": sd_time, "rotation": q_ego, "translation": t_ego})
                tables["sample_data"].append({
                    "token": sd_token, "sample_token": sample_tokens[k], "ego_pose_token": sd_token,
                    "calibrated_sensor_token": _nusc_tok("cs", scene, channel), "timestamp": sd_time,
                    "fileformat": ext.split(".")[-1], "is_key_frame": key_frame,
                    "height": 900 if ext == "jpg" else 0, "width": 1600 if ext == "jpg" else 0,
                    "filename": filename, "prev": "", "next": "",
                })
                if channel == "CAM_FRONT" and key_frame:
                    images.append((scene, k, filename, k_front))
                if with_images and ext == "jpg" and key_frame:
                    path = root / filename
                    path.parent.mkdir(parents=True, exist_ok=True)
                    pixels = np.full((45, 80, 3), 120, np.uint8)
                    pixels[:, :40] = (60, 140, 200)
                    cv2.imwrite(str(path), pixels)
            for name, (cat, positions) in objects.items():
                tables["sample_annotation"].append({
                    "token": _nusc_tok("ann", scene, name, k), "sample_token": sample_tokens[k],
                    "instance_token": _nusc_tok("instance", scene, name), "visibility_token": "4",
                    "attribute_tokens": [], "translation": _nusc_cam_to_global(scene, k, positions[k]),
                    "size": list(PED_SIZE) if cat.startswith("human") else [1.9, 4.5, 1.6],
                    # turned with the ego, so the box axes align with the camera's in both scenes
                    "rotation": q_ego, "prev": "", "next": "",
                    "num_lidar_pts": 10, "num_radar_pts": 0,
                })
    # Shuffle the rows: the loader must order by timestamp itself.
    for name in ("sample_data", "sample_annotation", "sample", "instance", "scene"):
        order = rng.permutation(len(tables[name]))
        tables[name] = [tables[name][i] for i in order]
    folder = root / VERSION
    folder.mkdir(parents=True, exist_ok=True)
    for name, rows in tables.items():
        (folder / f"{name}.json").write_text(json.dumps(rows, indent=1))
    return {"images": images}


def _nusc_detection(box, conf=0.6):
    x, y, w, h = box
    kp = np.zeros((17, 3))
    kp[:, 0] = x + w * np.linspace(0.2, 0.8, 17)
    kp[:, 1] = y + h * np.linspace(0.1, 0.95, 17)
    kp[:, 2] = conf
    kp[4] = (55.0, 66.0, 0.0)  # a missed keypoint with stray coordinates: loader zeroes it
    return {"keypoints": kp.ravel().tolist(), "bbox": [float(v) for v in box], "score": 0.7}


PREDICTION_NAME_STYLES = {  # image samples/CAM_FRONT/X.jpg -> prediction file name
    "predictions": lambda base, stem: f"{base}.predictions.json",  # openpifpaf >= 0.11 on the jpg
    "png": lambda base, stem: f"{stem}.png.json",
    "pifpaf": lambda base, stem: f"{base}.pifpaf.json",  # openpifpaf <= 0.10 on the jpg
    "png.pifpaf": lambda base, stem: f"{stem}.png.pifpaf.json",  # openpifpaf <= 0.10 on the noisy png
}


def _nusc_write_predictions(pred_dir: Path, facts: dict, name_style: str = "predictions") -> None:
    pred_dir.mkdir(parents=True, exist_ok=True)
    for scene, k, filename, k_matrix in facts["images"]:
        dets = []
        for name, (cat, positions) in TRUTH[scene].items():
            pos = positions[k]
            if pos[2] <= 0 or (name, k) in MISSED:
                continue
            box = _nusc_expected_box(pos, k_matrix) if cat.startswith("human") else \
                np.array([700.0, 420.0, 230.0, 120.0])  # something on the car
            shifted = box + np.array([0.08 * box[2], -0.05 * box[3], 0.0, 0.0])  # IoU ~ 0.8
            dets.append(_nusc_detection(shifted))
        dets.append(_nusc_detection([1450.0, 30.0, 60.0, 150.0]))  # far from everyone
        out = PREDICTION_NAME_STYLES[name_style](Path(filename).name, Path(filename).stem)
        (pred_dir / out).write_text(json.dumps(dets))


@pytest.fixture()
def fixture(tmp_path):
    root = tmp_path / "nuscenes"
    facts = _nusc_write_fixture(root, with_images=True)
    pred = tmp_path / "predictions" / "p0.025"
    _nusc_write_predictions(pred, facts)
    return root, pred, facts


# ---------------------------------------------------------------- geometry


def test_quaternion_to_rotation_known_answers():
    np.testing.assert_allclose(quaternion_to_rotation([1, 0, 0, 0]), np.eye(3))
    # nuScenes CAM_FRONT: camera z = ego x, camera x = -ego y, camera y = -ego z.
    np.testing.assert_allclose(quaternion_to_rotation(Q_FRONT), [[0, 0, 1], [-1, 0, 0], [0, -1, 0]], atol=1e-12)
    np.testing.assert_allclose(quaternion_to_rotation(Q_BACK), [[0, 0, -1], [1, 0, 0], [0, -1, 0]], atol=1e-12)
    np.testing.assert_allclose(quaternion_to_rotation(Q_YAW90), [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12)
    np.testing.assert_allclose(quaternion_to_rotation([2, 0, 0, 0]), np.eye(3))  # normalised
    batch = quaternion_to_rotation(np.array([Q_FRONT, Q_YAW90]))
    assert batch.shape == (2, 3, 3)
    rng = np.random.default_rng(0)
    r = quaternion_to_rotation(rng.normal(size=(10, 4)))
    np.testing.assert_allclose(r @ np.swapaxes(r, 1, 2), np.broadcast_to(np.eye(3), (10, 3, 3)), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(r), 1.0)
    with pytest.raises(ValueError, match="non-zero"):
        quaternion_to_rotation([0, 0, 0, 0])


def test_box_iou_and_greedy_matching():
    gt = np.array([[0, 0, 10, 10], [100, 100, 10, 20]], float)
    det = np.array([[5, 0, 10, 10], [0, 0, 10, 10], [500, 500, 5, 5], [100, 105, 10, 20]], float)
    iou = box_iou(gt, det)
    np.testing.assert_allclose(iou[0, :3], [50 / 150, 1.0, 0.0])
    np.testing.assert_allclose(iou[1, 3], 150 / 250)
    # Greedy by IoU, one-to-one: gt 0 takes the exact box, the half-overlap box is left over.
    assert sorted(match_boxes(gt, det)) == [(0, 1), (1, 3)]
    assert match_boxes(gt[:1], det[[0, 2]]) == [(0, 0)]  # IoU 1/3 >= 0.3 still matches
    assert match_boxes(gt[:1], det[[0, 2]], min_iou=0.4) == []
    assert match_boxes(gt[:0], det) == []


def test_project_annotations_depth_boxes_and_tracks(fixture):
    root, _, _ = fixture
    tables = read_tables(root, VERSION)
    gt = project_annotations(tables)
    # Pedestrians only (no car), B's keyframe behind the camera dropped: 3 + 2 + 2 rows.
    assert len(gt["position"]) == 7
    assert set(gt["channel"]) == {"CAM_FRONT"}
    tracks = {}
    for t, ts, pos in zip(gt["track_id"], gt["timestamp"], gt["position"]):
        tracks.setdefault(int(t), []).append((ts, pos))
    depth_lists = sorted([[p[2] for _, p in rows] for rows in tracks.values()], key=len)
    assert [len(d) for d in depth_lists] == [2, 2, 3]
    for rows in tracks.values():
        assert [ts for ts, _ in rows] == sorted(ts for ts, _ in rows)  # ordered by time
    expected = {
        (-1.0, 0.6, 10.0), (-0.8, 0.6, 12.0), (-0.6, 0.6, 14.0), (3.0, 0.6, 20.0), (3.2, 0.6, 22.0),
        (0.5, 0.7, 8.0), (0.4, 0.7, 9.0),
    }
    got = {tuple(np.round(p, 6)) for p in gt["position"]}
    assert got == expected  # the analytic camera-frame centres, through ego pose and calibration
    # Projected boxes equal the analytic projection of the 8 corners; each sample's own K.
    for pos, box, k in zip(gt["position"], gt["box"], gt["intrinsics"]):
        k_expected = K_FRONT_B if np.isclose(pos[2], 8.0) or np.isclose(pos[2], 9.0) else K_FRONT_A
        np.testing.assert_allclose(k, k_expected)
        np.testing.assert_allclose(box, _nusc_expected_box(pos, k_expected), atol=1e-6)
    scenes = {round(float(p[2])): s for p, s in zip(gt["position"], gt["scene_id"])}
    assert scenes[10] == 0 and scenes[8] == 1  # scene ids by scene name
    # Both cameras: the back camera sees nobody (everyone is ahead), same rows.
    both = project_annotations(tables, ("CAM_FRONT", "CAM_BACK"))
    assert len(both["position"]) == 7
    assert len(camera_images(tables, ("CAM_FRONT", "CAM_BACK"))) == 10


def test_load_nuscenes_records(fixture):
    root, pred, _ = fixture
    rec = load_nuscenes_records(root, pred, Noise("salt_and_pepper", 0.025), version=VERSION)
    assert check_records(rec) == 6  # 7 visible pedestrian boxes, B missed once
    np.testing.assert_array_equal(rec["noise"], np.float32(0.025))
    by_track = {}
    for i, t in enumerate(rec["track_id"]):
        by_track.setdefault(int(t), []).append(i)
    depths = sorted(([float(rec["depth"][i]) for i in rows] for rows in by_track.values()), key=lambda d: d[0])
    np.testing.assert_allclose(depths[0], [8.0, 9.0], atol=1e-5)
    np.testing.assert_allclose(depths[1], [10.0, 12.0, 14.0], atol=1e-5)
    np.testing.assert_allclose(depths[2], [20.0], atol=1e-5)  # 22 m keyframe missed by PifPaf
    for rows in by_track.values():  # each track ordered by timestamp
        assert np.all(np.diff(rec["timestamp"][rows]) > 0)
    np.testing.assert_allclose(rec["distance"], np.linalg.norm(rec["position"], axis=1), rtol=1e-6)
    child = np.isclose(rec["depth"], 8.0)
    np.testing.assert_allclose(rec["intrinsics"][child][0], K_FRONT_B, atol=1e-3)
    np.testing.assert_allclose(rec["intrinsics"][~child & ~np.isclose(rec["depth"], 9.0)][0], K_FRONT_A, atol=1e-3)
    # Keypoints and box come from the matched PifPaf detection; missed keypoints zeroed.
    np.testing.assert_array_equal(rec["keypoints"][:, 4], 0.0)
    assert np.all(rec["keypoints"][:, 0, 2] == np.float32(0.6))
    row = np.flatnonzero(np.isclose(rec["depth"], 10.0))[0]
    expected_box = _nusc_expected_box((-1.0, 0.6, 10.0), K_FRONT_A)
    expected_box[:2] += [0.08 * expected_box[2], -0.05 * expected_box[3]]
    np.testing.assert_allclose(rec["box"][row], expected_box, rtol=1e-5)
    # The far-away detection and the one on the car matched nothing.
    assert not np.any(np.isclose(rec["box"][:, 0], 1450.0))
    assert not np.any(np.isclose(rec["box"][:, 0], 700.0 + 0.08 * 230.0))


def test_other_prediction_file_names_are_accepted(tmp_path):
    root = tmp_path / "nuscenes"
    facts = _nusc_write_fixture(root)
    pred = tmp_path / "pred"
    _nusc_write_predictions(pred / "nested", facts, name_style="png")
    rec = load_nuscenes_records(root, pred, Noise("salt_and_pepper", 0.05), version=VERSION)
    assert len(rec["depth"]) == 6


def test_clear_errors(fixture, tmp_path):
    root, pred, facts = fixture
    with pytest.raises(FileNotFoundError, match="predictions folder .*nowhere"):
        load_nuscenes_records(root, tmp_path / "nowhere", Noise("salt_and_pepper", 0.025), version=VERSION)
    first = Path(facts["images"][0][2]).name + ".predictions.json"
    (pred / first).unlink()
    with pytest.raises(ValueError, match=r"holds prediction files for 4 of the 5 keyframe images") as info:
        load_nuscenes_records(root, pred, Noise("salt_and_pepper", 0.025), version=VERSION)
    assert str(pred) in str(info.value)
    (root / VERSION / "scene.json").unlink()
    with pytest.raises(FileNotFoundError, match=r"nuScenes table .*scene\.json not found"):
        read_tables(root, VERSION)
    with pytest.raises(FileNotFoundError, match="v1.0-trainval"):
        read_tables(root, "v1.0-trainval")
    (root / VERSION / "scene.json").write_text("{not json")
    with pytest.raises(ValueError, match="not valid JSON"):
        read_tables(root, VERSION)
    with pytest.raises(ValueError, match="cameras"):
        camera_images({name: [] for name in nuscenes_tables.TABLES}, ("CAM_SIDEWAYS",))


def test_bad_prediction_files_are_rejected(fixture):
    root, pred, facts = fixture
    path = pred / (Path(facts["images"][0][2]).name + ".predictions.json")
    dets = json.loads(path.read_text())
    dets[0]["keypoints"] = dets[0]["keypoints"][:50]
    path.write_text(json.dumps(dets))
    with pytest.raises(ValueError, match="51 numbers"):
        load_nuscenes_records(root, pred, Noise("salt_and_pepper", 0.025), version=VERSION)
    path.write_text('[{"keypoints": [NaN' + ", 0" * 50 + '], "bbox": [0, 0, 1, 1], "score": 0.5}]')
    with pytest.raises(ValueError, match="NaN"):
        load_nuscenes_records(root, pred, Noise("salt_and_pepper", 0.025), version=VERSION)


def test_both_sources_give_identical_record_structures(fixture, tmp_path):
    root, pred, _ = fixture
    real = load_pedestrians(tmp_path / "cache", "nuscenes", Noise("salt_and_pepper", 0.025), nuscenes_root=root,
                            predictions_root=pred.parent, nuscenes_version=VERSION)
    sim = simulate_records(simulate_truth(n_scenes=3, frames_per_scene=5, seed=0), Noise("salt_and_pepper", 0.025), seed=0)
    assert set(real) == set(sim) == set(RECORD_FIELDS)
    for name in RECORD_FIELDS:
        assert real[name].dtype == sim[name].dtype, name
        assert real[name].shape[1:] == sim[name].shape[1:], name
    check_records(real)
    check_records(sim)


# ---------------------------------------------------------------- the devkit's keep rule


def _cube(z_near: float, z_far: float, x=(-0.3, 0.3), y=(-0.9, 0.9)) -> np.ndarray:
    """8 corners (8,3) of a camera-aligned box spanning x, y and [z_near, z_far]."""
    return np.array([(xx, yy, zz) for xx in x for yy in y for zz in (z_near, z_far)], float)


def test_box_in_image_any_is_the_devkits_rule():
    k = np.array([[1000.0, 0, 800], [0, 1000.0, 450], [0, 0, 1]])

    def keep(corners):
        return bool(box_in_image_any(corners, k, 1600, 900))

    assert keep(_cube(9.5, 10.5))
    assert not keep(_cube(0.7, 0.9, y=(-0.3, 0.3)))  # 0.8 m in front: in the image but no corner beyond 1 m
    assert not keep(_cube(0.7, 1.2))  # beyond 1 m only outside the image (v = 450 +- 750)
    assert keep(_cube(0.7, 1.2, y=(-0.3, 0.3)))  # the far corners are visible
    one_behind = _cube(3.0, 3.5)
    one_behind[0, 2] = 0.05  # a single corner 0.05 m in front, the others visible
    assert not keep(one_behind)
    one_behind[0, 2] = 0.11
    assert keep(one_behind)
    # Only one corner projects inside the image (x = -2.3 at z = 3: u = 33), and it is visible.
    one_visible = np.array([(-4.0, 0.0, 3.0)] * 8)
    one_visible[3] = (-2.3, 0.0, 3.0)
    assert keep(one_visible)
    one_visible[3] = (-0.7, 0.0, 0.9)  # inside the image, but not more than 1 m in front
    assert not keep(one_visible)
    on_edge = np.array([(-4.0, 0.0, 3.0)] * 8)
    on_edge[5] = (-2.0, 0.0, 2.5)  # u = 0 exactly: the devkit wants 0 < u
    assert not keep(on_edge)
    batch = np.stack([_cube(9.5, 10.5), _cube(0.7, 0.9)])
    np.testing.assert_array_equal(box_in_image_any(batch, k, 1600, 900), [True, False])
    with pytest.raises(ValueError, match=r"\(\.\.\., 8, 3\)"):
        box_in_image_any(np.zeros((4, 3)), k, 1600, 900)


def _add_pedestrian(tables: dict, name: str, cam_xyz, size=PED_SIZE, scene="scene-0001", k=0) -> str:
    """Add an adult pedestrian at camera position cam_xyz to keyframe k (in memory): its instance token."""
    instance = _nusc_tok("instance", scene, name)
    tables["instance"].append({
        "token": instance, "category_token": _nusc_tok("cat", "human.pedestrian.adult"), "nbr_annotations": 1,
        "first_annotation_token": _nusc_tok("ann", scene, name, k), "last_annotation_token": _nusc_tok("ann", scene, name, k),
    })
    tables["sample_annotation"].append({
        "token": _nusc_tok("ann", scene, name, k), "sample_token": _nusc_tok("sample", scene, k),
        "instance_token": instance, "visibility_token": "4", "attribute_tokens": [],
        "translation": _nusc_cam_to_global(scene, k, cam_xyz), "size": list(size),
        "rotation": _nusc_ego(scene, k)[1], "prev": "", "next": "", "num_lidar_pts": 5, "num_radar_pts": 0,
    })
    return instance


def test_project_annotations_keeps_what_the_devkit_keeps(fixture):
    root, _, _ = fixture
    tables = read_tables(root, VERSION)
    # Whole box 0.7-0.9 m in front and inside the image: the devkit drops it (no corner beyond 1 m).
    near = _add_pedestrian(tables, "near", (0.0, 0.6, 0.8), size=(0.6, 0.2, 1.8))
    # Near face 0.05 m in front (not beyond 0.1 m), far face 2.05 m and in the image: dropped.
    straddling = _add_pedestrian(tables, "straddling", (0.0, 0.6, 1.05), size=(0.6, 2.0, 1.8))
    # Partly left of the image, some corners visible at z ~ 10: kept, box clipped at u = 0.
    edge = _add_pedestrian(tables, "edge", (-6.5, 0.6, 10.0))
    gt = project_annotations(tables)
    tokens = set(gt["instance_token"])
    assert near not in tokens
    assert straddling not in tokens
    assert edge in tokens
    assert len(gt["position"]) == 8  # the fixture's 7 + the edge pedestrian
    box = gt["box"][list(gt["instance_token"]).index(edge)]
    expected = _nusc_expected_box((-6.5, 0.6, 10.0), K_FRONT_A)
    assert expected[0] < 0 < expected[0] + expected[2]  # really partly outside
    np.testing.assert_allclose(box, [0.0, expected[1], expected[0] + expected[2], expected[3]], atol=1e-6)


def test_dangling_tokens_name_the_table(fixture):
    root, _, facts = fixture
    tables = read_tables(root, VERSION)

    def without(table: str, token: str) -> dict:
        out = {name: list(rows) for name, rows in tables.items()}
        out[table] = [r for r in out[table] if r["token"] != token]
        assert len(out[table]) == len(tables[table]) - 1
        return out

    scene, sample = _nusc_tok("scene", "scene-0002"), _nusc_tok("sample", "scene-0002", 0)
    with pytest.raises(ValueError, match=rf"sample {sample} refers to scene {scene}, which has no row in scene\.json"):
        project_annotations(without("scene", scene))
    with pytest.raises(ValueError, match=rf"refers to sample {sample}, which has no row in sample\.json"):
        camera_images(without("sample", sample))
    cs = _nusc_tok("cs", "scene-0001", "CAM_FRONT")
    with pytest.raises(ValueError, match=rf"sample_data .* refers to calibrated_sensor {cs}, .*calibrated_sensor\.json"):
        camera_images(without("calibrated_sensor", cs))
    sensor = _nusc_tok("sensor", "CAM_FRONT")
    with pytest.raises(ValueError, match=rf"calibrated_sensor .* refers to sensor {sensor}, .*incomplete or from"):
        camera_images(without("sensor", sensor))
    pose = _nusc_tok("sd", "scene-0001", 1, "CAM_FRONT", True)
    with pytest.raises(ValueError, match=rf"sample_data {pose} refers to ego_pose {pose}, .*ego_pose\.json"):
        camera_images(without("ego_pose", pose))
    # Through the loader, from the files on disk.
    (root / VERSION / "scene.json").write_text(json.dumps([r for r in tables["scene"] if r["token"] != scene]))
    with pytest.raises(ValueError, match=r"no row in scene\.json"):
        load_nuscenes_records(root, fixture[1], Noise("salt_and_pepper", 0.025), version=VERSION)


# ---------------------------------------------------------------- prediction files


def test_openpifpaf_0_10_file_names_and_detections(tmp_path):
    """openpifpaf <= 0.10 (Monoloco's) writes <image>.pifpaf.json, detections without category_id."""
    assert {"X.jpg.pifpaf.json", "X.png.pifpaf.json", "X.png.predictions.json"} <= set(
        prediction_file_candidates("samples/CAM_FRONT/X.jpg"))
    root = tmp_path / "nuscenes"
    facts = _nusc_write_fixture(root)
    reference = load_nuscenes_records(root, _write_predictions(tmp_path / "new", facts, "predictions"), Noise("salt_and_pepper", 0.05),
                                      version=VERSION)
    for style in ("pifpaf", "png.pifpaf"):
        pred = _write_predictions(tmp_path / style, facts, style)
        assert all("category_id" not in d for f in pred.glob("*.json") for d in json.loads(f.read_text()))
        rec = load_nuscenes_records(root, pred, Noise("salt_and_pepper", 0.05), version=VERSION)
        for name in reference:
            np.testing.assert_array_equal(rec[name], reference[name], err_msg=f"{style}: {name}")


def _write_predictions(pred: Path, facts: dict, style: str) -> Path:
    _nusc_write_predictions(pred, facts, name_style=style)
    return pred


def test_category_id_person_kept_other_classes_skipped(tmp_path):
    person = _nusc_detection([10.0, 20.0, 30.0, 60.0])
    path = tmp_path / "X.png.predictions.json"
    path.write_text(json.dumps([
        {**person, "category_id": 1},
        person,  # openpifpaf <= 0.10: no category_id
        {"bbox": [5.0, 5.0, 50.0, 40.0], "score": 0.9, "category_id": 3},  # a car from a detection head
        {**_nusc_detection([300.0, 20.0, 30.0, 60.0]), "category_id": 2},
    ]))
    keypoints, boxes, scores = read_predictions(path)
    assert keypoints.shape == (2, 17, 3)
    np.testing.assert_array_equal(boxes, [[10.0, 20.0, 30.0, 60.0]] * 2)
    np.testing.assert_array_equal(scores, [0.7, 0.7])


def test_missing_file_hint_names_what_the_workflow_writes(fixture):
    root, pred, facts = fixture
    image = Path(facts["images"][0][2])
    (pred / (image.name + ".predictions.json")).unlink()
    with pytest.raises(ValueError) as info:
        load_nuscenes_records(root, pred, Noise("salt_and_pepper", 0.025), version=VERSION)
    message = str(info.value)
    assert f"-> expected {image.stem}.png.predictions.json" in message
    assert f"{image.name}.predictions.json" in message and f"{image.stem}.png.pifpaf.json" in message  # the others


def test_every_prediction_file_is_checked(fixture):
    """A broken file of an image without any ground-truth pedestrian (CAM_BACK sees nobody) is an error."""
    root, pred, _ = fixture
    back = camera_images(read_tables(root, VERSION), ("CAM_BACK",))
    for image in back:
        (pred / (Path(image["filename"]).stem + ".png.predictions.json")).write_text("[]")
    rec = load_nuscenes_records(root, pred, Noise("salt_and_pepper", 0.025), version=VERSION, cameras=("CAM_FRONT", "CAM_BACK"))
    assert len(rec["depth"]) == 6
    broken = pred / (Path(back[2]["filename"]).stem + ".png.predictions.json")
    broken.write_text('[{"keypoints": [1, 2, 3], "bbox": [0, 0, 1, 1]}]')
    with pytest.raises(ValueError, match=rf"{broken.name}: keypoints must be 51 numbers"):
        load_nuscenes_records(root, pred, Noise("salt_and_pepper", 0.025), version=VERSION, cameras=("CAM_FRONT", "CAM_BACK"))
    broken.write_text("[{not json")
    with pytest.raises(ValueError, match=rf"{broken.name} is not valid JSON"):
        load_nuscenes_records(root, pred, Noise("salt_and_pepper", 0.025), version=VERSION, cameras=("CAM_FRONT", "CAM_BACK"))


def test_enlarge_boxes_is_monolocos():
    boxes = np.array([[100.0, 200.0, 35.0, 70.0], [5.0, 5.0, 35.0, 70.0], [1580.0, 850.0, 35.0, 70.0]])
    out = enlarge_boxes(boxes, 1600, 900)  # w/3.5 = 10 px each side, h/7 = 10 px above and below
    np.testing.assert_allclose(out, [[90, 190, 55, 90], [0, 0, 50, 85], [1570, 840, 30, 60]])
    np.testing.assert_allclose(enlarge_boxes(boxes[:1], 1600, 900, (0, 0)), boxes[:1])
    assert enlarge_boxes(np.zeros((0, 4)), 1600, 900).shape == (0, 4)
    with pytest.raises(ValueError, match="margin"):
        enlarge_boxes(boxes, 1600, 900, (-0.1, 0.0))


def test_matching_uses_the_enlarged_box_and_records_keep_the_raw_one(fixture):
    """A tight keypoint box (0.45 w x 0.6 h inside the ground-truth box, IoU 0.27) matches only after
    Monoloco's enlargement (IoU 0.55); the record keeps PifPaf's box."""
    root, pred, facts = fixture
    scene, k, filename, k_matrix = facts["images"][0]
    name = next(n for n, (_, pos) in TRUTH[scene].items() if n.startswith("ped_") and pos[k][2] > 0)
    gt_box = _nusc_expected_box(TRUTH[scene][name][1][k], k_matrix)
    tight = np.array([gt_box[0] + 0.275 * gt_box[2], gt_box[1] + 0.2 * gt_box[3], 0.45 * gt_box[2], 0.6 * gt_box[3]])
    assert box_iou(gt_box, tight)[0, 0] < 0.3 <= box_iou(gt_box, enlarge_boxes(tight, 1600, 900))[0, 0]
    path = pred / (Path(filename).name + ".predictions.json")
    dets = json.loads(path.read_text())
    ious = box_iou(gt_box, np.array([d["bbox"] for d in dets]))[0]
    dets[int(np.argmax(ious))] = _nusc_detection(tight)
    path.write_text(json.dumps(dets))
    depth = TRUTH[scene][name][1][k][2]
    rec = load_nuscenes_records(root, pred, Noise("salt_and_pepper", 0.025), version=VERSION)
    assert len(rec["depth"]) == 6
    row = np.flatnonzero(np.isclose(rec["depth"], depth))
    assert len(row) == 1
    np.testing.assert_allclose(rec["box"][row[0]], tight, rtol=1e-6)
    raw = load_nuscenes_records(root, pred, Noise("salt_and_pepper", 0.025), version=VERSION, box_margin=None)
    assert len(raw["depth"]) == 5 and not np.any(np.isclose(raw["depth"], depth))


# ---------------------------------------------------------------- noisy images


def _changed_fraction(root: Path, out: Path, facts: dict):
    changed, white, black, total = 0, 0, 0, 0
    for _, _, filename, _ in facts["images"]:
        original = cv2.imread(str(root / filename))
        noisy = cv2.imread(str((out / filename).with_suffix(".png")))
        assert noisy is not None and noisy.shape == original.shape
        diff = np.any(noisy != original, axis=-1)
        changed += diff.sum()
        white += np.all(noisy[diff] == 255, axis=-1).sum()
        black += np.all(noisy[diff] == 0, axis=-1).sum()
        total += diff.size
    return changed / total, white, black


@pytest.mark.slow
def test_noisify_cli_writes_salt_and_pepper_images(fixture, tmp_path):
    root, _, facts = fixture
    out = tmp_path / "noisy"
    assert cli(["nuscenes", "noisify", "--root", str(root), "--out", str(out), "--p", "0.2",
                          "--version", VERSION, "--seed", "3"]) == 0
    written = sorted(out.rglob("*.png"))
    assert len(written) == 5  # CAM_FRONT keyframes only (default cameras)
    frac, white, black = _changed_fraction(root, out, facts)
    assert abs(frac - 0.2) < 0.01  # 18000 pixels: sd 0.003
    assert white + black == round(frac * 18000) and abs(white - black) < 0.15 * (white + black)
    again = write_noisy_images(root, tmp_path / "again", Noise("salt_and_pepper", 0.2), seed=3, version=VERSION)
    for a in again:
        b = out / a.relative_to(tmp_path / "again")
        np.testing.assert_array_equal(cv2.imread(str(a)), cv2.imread(str(b)))  # deterministic per seed
    # The real command line, as a user would type it.
    env = {**os.environ, "PYTHONPATH": str(REPO), "OMP_NUM_THREADS": "1"}
    result = subprocess.run(
        [sys.executable, "-m", "drfkit", "nuscenes", "noisify", "--root", str(root), "--out",
         str(tmp_path / "cli"), "--p", "0.05", "--version", VERSION, "--cameras", "CAM_FRONT", "CAM_BACK"],
        capture_output=True, text=True, env=env, cwd=tmp_path, timeout=60,
    )
    assert result.returncode == 0, result.stderr
    assert "wrote 10 noisy images" in result.stdout
    assert len(list((tmp_path / "cli").rglob("*.png"))) == 10


def test_noisify_reports_missing_images(tmp_path):
    root = tmp_path / "nuscenes"
    _nusc_write_fixture(root, with_images=False)
    with pytest.raises(FileNotFoundError, match="camera image .*CAM_FRONT"):
        write_noisy_images(root, tmp_path / "out", Noise("salt_and_pepper", 0.01), version=VERSION)
