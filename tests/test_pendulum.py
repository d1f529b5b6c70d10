import numpy as np
import pytest

from drfkit.data.noise import Noise
from drfkit.data import pendulum
from drfkit.data.pendulum import (
    check_images,
    estimate_angle,
    generate_pendulum,
    load_pendulum,
    render_pendulum,
)

C = 3.0 * 9.81  # the benchmark's c = g l m / I with I = m l^2 / 3, l = m = 1


def _wrap(angle):
    return np.angle(np.exp(1j * angle))


# ---------------------------------------------------------------- physics


def test_small_angle_period_matches_the_benchmark_constant():
    # theta'' = -(3 g / l) theta  ->  period 2 pi sqrt(l / (3 g)) = 1.158 s (a physical rod
    # about its end would give 2 pi sqrt(2 l / (3 g)) = 1.638 s; the benchmark uses c = 3 g / l).
    theta, _ = pendulum._simulate(np.array([0.02]), 100, None, friction=0.0, transition_noise_std=0.0)
    x = theta[0]
    t = np.arange(x.size) * pendulum.FRAME_DT
    up = np.flatnonzero((x[:-1] < 0) & (x[1:] >= 0))
    crossings = t[up] + pendulum.FRAME_DT * (-x[up]) / (x[up + 1] - x[up])
    period = np.diff(crossings).mean()
    assert len(crossings) >= 4
    assert period == pytest.approx(2 * np.pi * np.sqrt(1.0 / C), rel=2e-3)
    # Amplitude is kept without friction (semi-implicit Euler does not pump or drain energy).
    assert np.abs(x).max() == pytest.approx(0.02, rel=0.01)


def test_energy_conserved_without_friction_and_lost_with_it():
    theta0 = np.array([2.0, -2.5, 0.5])
    energy = lambda th, v: 0.5 * v**2 - C * np.cos(th)  # noqa: E731  (per unit inertia)
    theta, vel = pendulum._simulate(theta0, 40, None, friction=0.0, transition_noise_std=0.0)
    e = energy(theta, vel)
    assert np.abs(e - e[:, :1]).max() < 1e-3 * C
    theta_f, vel_f = pendulum._simulate(theta0, 40, None, friction=0.1, transition_noise_std=0.0)
    height_f = energy(theta_f, vel_f) + C  # energy above the resting state
    assert np.all(height_f[:, -1] < 0.9 * height_f[:, 0])


def test_hanging_pendulum_stays_and_upright_one_falls():
    theta, vel = pendulum._simulate(np.array([0.0, np.pi - 1e-3]), 30, None, transition_noise_std=0.0)
    assert np.abs(theta[0]).max() < 1e-9 and np.abs(vel[0]).max() < 1e-9
    assert np.abs(_wrap(theta[1] - np.pi)).max() > 1.0  # falls from the top


def test_transition_noise_is_on_velocity_with_std_0_1():
    # From rest at the bottom without friction, the velocity after one frame is the noise.
    theta, vel = pendulum._simulate(np.zeros(4000), 2, np.random.default_rng(0), friction=0.0)
    assert vel[:, 1].std() == pytest.approx(0.1, rel=0.05)
    assert abs(vel[:, 1].mean()) < 0.01
    np.testing.assert_array_equal(theta[:, 0], 0.0)


def test_theta_wrapped_to_minus_pi_pi():
    data = generate_pendulum(10, 30, Noise("rkn_uniform", 0.5), seed=11)
    assert data["theta"].min() >= -np.pi and data["theta"].max() < np.pi + 1e-6


# ---------------------------------------------------------------- rendering


def test_theta_zero_is_drawn_below_the_pivot_and_positive_to_the_right():
    down = render_pendulum(np.array(0.0)).astype(float)
    assert down.shape == (24, 24)
    assert down[12:].sum() > 10 * down[:12].sum()  # the width and Lanczos' support poke behind the pivot
    right = render_pendulum(np.array(np.pi / 2)).astype(float)
    assert right[:, 12:].sum() > 10 * right[:, :12].sum()
    up = render_pendulum(np.array(np.pi)).astype(float)
    assert up[:12].sum() > 10 * up[12:].sum()


def test_frames_carry_the_benchmarks_ink_not_an_anti_aliased_lines():
    """The RKN recipe (PIL float canvas, hard 8-px line, Lanczos to 24 x 24, clip, x255, truncate)
    gives a mean intensity sum of 4040 over random angles; the former OpenCV anti-aliased line
    with round caps gave 5192. A renderer that drifts from the recipe moves this by far more than 1 %."""
    theta = np.random.default_rng(0).uniform(-np.pi, np.pi, 500)
    ink = render_pendulum(theta).reshape(500, -1).astype(np.float64).sum(axis=1)
    assert abs(ink.mean() - 4040) < 0.01 * 4040
    assert ink.std() < 0.05 * ink.mean()  # a rod has about the same ink at every angle


def test_the_pivot_sits_at_the_image_centre():
    """Hanging straight down, the rod's ink is centred on canvas pixel 64 (PIL fills the pixels
    around index 64, centre 64.5), i.e. column 64.5 * 24 / 128 - 0.5 = 11.59 of the small image,
    and starts at the pivot row."""
    down = render_pendulum(np.array(0.0)).astype(np.float64)
    columns = down.sum(axis=0)
    centre = (columns * np.arange(24)).sum() / columns.sum()
    assert abs(centre - 11.59) < 0.03
    rows = down.sum(axis=1)
    assert rows[:10].sum() < 0.02 * rows.sum() and rows[12:22].min() > 0.5 * rows.max()


def test_truncation_not_rounding_and_the_full_range():
    image = render_pendulum(np.array(0.3))
    assert image.dtype == np.uint8
    assert image.max() > 200
    # Lanczos leaves intermediate grey levels along the edges.
    assert np.count_nonzero((image > 20) & (image < 200)) >= 10


def test_estimate_angle_recovers_the_rendered_angle():
    """The hard-edged rod is not symmetric about its axis: its centroid is within 2.5 degrees."""
    theta = np.linspace(-np.pi, np.pi, 360, endpoint=False)
    error = np.degrees(np.abs(_wrap(estimate_angle(render_pendulum(theta)) - theta)))
    assert error.max() < 2.5 and error.mean() < 1.0


def test_estimate_angle_agrees_with_targets_on_generated_data():
    data = generate_pendulum(8, 20, Noise("rkn_uniform", 0.5), seed=3)
    estimate = estimate_angle(data["clean"])
    target_angle = np.arctan2(data["targets"][..., 1], data["targets"][..., 0])
    assert np.degrees(np.abs(_wrap(estimate - target_angle))).max() < 2.5


def test_estimate_angle_black_image_is_nan_and_checks_input():
    assert np.isnan(estimate_angle(np.zeros((24, 24), np.uint8)))
    with pytest.raises(TypeError, match="uint8"):
        estimate_angle(np.zeros((24, 24), np.float32))
    with pytest.raises(ValueError, match="24"):
        estimate_angle(np.zeros((28, 28), np.uint8))


# ---------------------------------------------------------------- generation


def test_shapes_dtypes_and_targets():
    data = generate_pendulum(4, 12, Noise("rkn_uniform", 0.5), seed=0)
    assert set(data) == {"images", "clean", "targets", "noise", "theta"}
    assert data["images"].shape == data["clean"].shape == (4, 12, 24, 24)
    assert data["images"].dtype == data["clean"].dtype == np.uint8
    assert data["targets"].shape == (4, 12, 2) and data["targets"].dtype == np.float32
    assert data["noise"].shape == (4, 12) and data["noise"].dtype == np.float32
    assert data["theta"].shape == (4, 12) and data["theta"].dtype == np.float32
    # (cos theta, sin theta), in this order.
    np.testing.assert_allclose(data["targets"][..., 0], np.cos(data["theta"]), atol=1e-6)
    np.testing.assert_allclose(data["targets"][..., 1], np.sin(data["theta"]), atol=1e-6)
    check_images(data["images"])


def test_deterministic_for_a_seed_and_seed_dependent():
    a = generate_pendulum(5, 15, Noise("rkn_uniform", 0.5), seed=1)
    b = generate_pendulum(5, 15, Noise("rkn_uniform", 0.5), seed=1)
    c = generate_pendulum(5, 15, Noise("rkn_uniform", 0.5), seed=2)
    for key in a:
        np.testing.assert_array_equal(a[key], b[key])
    assert not np.allclose(a["theta"], c["theta"])
    assert not np.array_equal(a["images"], c["images"])


def test_same_seed_different_max_noise_same_motion_and_factor():
    low = generate_pendulum(6, 25, Noise("rkn_uniform", 0.5), seed=5)
    high = generate_pendulum(6, 25, Noise("rkn_uniform", 0.75), seed=5)
    for key in ("theta", "targets", "clean"):
        np.testing.assert_array_equal(low[key], high[key])
    # Same underlying factor f: n' / max_noise = 1 - f agrees.
    np.testing.assert_allclose(low["noise"] / 0.5, high["noise"] / 0.75, atol=1e-6)
    assert high["noise"].max() > low["noise"].max()
    assert not np.array_equal(low["images"], high["images"])


def test_noise_level_range_and_clean_first_frames():
    max_noise = 0.75
    data = generate_pendulum(20, 30, Noise("rkn_uniform", max_noise), seed=8)
    noise = data["noise"]
    assert noise.min() >= 0.0 and noise.max() <= max_noise + 1e-7
    np.testing.assert_array_equal(noise[:, :5], 0.0)
    np.testing.assert_array_equal(data["images"][:, :5], data["clean"][:, :5])
    # Frames at full noise exist and differ from the clean ones.
    noisy = np.isclose(noise, max_noise)
    assert noisy.any()
    assert np.any(data["images"][noisy] != data["clean"][noisy])
    # Noisy frames are further from the clean image than clean-ish ones.
    distance = np.abs(data["images"].astype(float) - data["clean"]).mean(axis=(-2, -1))
    assert distance[noise > 0.5].mean() > 5 * distance[noise < 0.05].mean()


def test_max_noise_zero_is_clean():
    data = generate_pendulum(3, 10, Noise("rkn_uniform", 0.0), seed=4)
    np.testing.assert_array_equal(data["images"], data["clean"])
    np.testing.assert_array_equal(data["noise"], 0.0)


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(n_sequences=0), "n_sequences"),
        (dict(n_sequences=2.0), "n_sequences"),
        (dict(seq_len=0), "seq_len"),
        (dict(noise=0.5), "takes a Noise value"),
        (dict(noise=Noise("salt_and_pepper", 0.5)), "no corruption of pendulum frames for salt_and_pepper"),
        (dict(seed=-1), "seed"),
        (dict(seed=1.5), "seed"),
    ],
)
def test_generate_validates_arguments(kwargs, name):
    args = dict(n_sequences=2, seq_len=3, noise=Noise("rkn_uniform", 0.5), seed=0) | kwargs
    with pytest.raises((ValueError, TypeError), match=name):
        generate_pendulum(**args)


# ---------------------------------------------------------------- caching


def test_cache_returns_identical_arrays_without_rebuilding(tmp_path, monkeypatch):
    first = load_pendulum(tmp_path, "train", 3, 8, Noise("rkn_uniform", 0.5), seed=0)
    files = sorted(tmp_path.glob("pendulum-train-*.npz"))
    assert len(files) == 1

    def fail(*args, **kwargs):
        raise AssertionError("the cached file should have been used")

    monkeypatch.setattr(pendulum, "generate_pendulum", fail)
    second = load_pendulum(tmp_path, "train", 3, 8, Noise("rkn_uniform", 0.5), seed=0)
    assert set(second) == set(first)
    for key in first:
        assert second[key].dtype == first[key].dtype
        np.testing.assert_array_equal(second[key], first[key])


def test_cache_key_covers_split_and_parameters(tmp_path):
    load_pendulum(tmp_path, "train", 2, 6, Noise("rkn_uniform", 0.5), seed=0)
    load_pendulum(tmp_path, "test", 2, 6, Noise("rkn_uniform", 0.5), seed=0)
    load_pendulum(tmp_path, "test", 2, 6, Noise("rkn_uniform", 0.75), seed=0)
    assert len(list(tmp_path.glob("pendulum-train-*.npz"))) == 1
    assert len(list(tmp_path.glob("pendulum-test-*.npz"))) == 2


def test_corrupt_cache_file_is_rebuilt(tmp_path, capsys):
    first = load_pendulum(tmp_path, "val", 2, 6, Noise("rkn_uniform", 0.5), seed=1)
    (path,) = tmp_path.glob("pendulum-val-*.npz")
    path.write_bytes(path.read_bytes()[:100])  # truncated, as after a killed write
    again = load_pendulum(tmp_path, "val", 2, 6, Noise("rkn_uniform", 0.5), seed=1)
    for key in first:
        np.testing.assert_array_equal(again[key], first[key])
    assert "rebuilding" in capsys.readouterr().err
    # The rebuilt file is valid again.
    np.load(path)["images"]


@pytest.mark.parametrize("split", ["", "a/b", 3])
def test_load_rejects_bad_split(tmp_path, split):
    with pytest.raises(ValueError, match="split"):
        load_pendulum(tmp_path, split, 2, 6, Noise("rkn_uniform", 0.5), seed=0)


def test_load_validates_before_touching_disk(tmp_path):
    with pytest.raises(TypeError, match="takes a Noise value"):
        load_pendulum(tmp_path, "train", 2, 6, 0.5, seed=0)
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("kind, level, error", [
    ("rkn_uniform", 1.5, "must lie in"), ("rkn_uniform", -0.1, "must lie in"),
    ("rkn_uniform", float("nan"), "must lie in"), ("rkn_uniform", "0.5", "is a number"),
    ("rkn_uniform", True, "is a number"), ("gaussian", 0.1, "unknown noise kind"),
])
def test_noise_is_checked_when_made(kind, level, error):
    with pytest.raises((ValueError, TypeError), match=error):
        Noise(kind, level)


def test_noise_kind_is_in_the_cache_key(tmp_path):
    from drfkit.util.io import param_hash

    assert Noise("rkn_uniform", 0.5).key() != Noise("salt_and_pepper", 0.5).key()
    assert Noise("rkn_uniform", 1) == Noise("rkn_uniform", 1.0) and isinstance(Noise("rkn_uniform", 1).level, float)
    assert param_hash({"noise": Noise("rkn_uniform", 0.5).key()}) != param_hash({"noise": Noise("salt_and_pepper", 0.5).key()})


# ---------------------------------------------------------------- check_images


def test_check_images_accepts_valid_and_rejects_invalid():
    check_images(np.zeros((2, 3, 24, 24), np.uint8))
    with pytest.raises(TypeError, match="uint8"):
        check_images(np.zeros((2, 3, 24, 24), np.float32))
    with pytest.raises(TypeError, match="NaN"):
        check_images(np.full((2, 3, 24, 24), np.nan))
    with pytest.raises(TypeError, match="numpy array"):
        check_images([[0]])
    with pytest.raises(ValueError, match="shape"):
        check_images(np.zeros((3, 24, 24), np.uint8))
    with pytest.raises(ValueError, match="shape"):
        check_images(np.zeros((2, 3, 28, 28), np.uint8))
    with pytest.raises(ValueError, match="empty"):
        check_images(np.zeros((0, 3, 24, 24), np.uint8))
