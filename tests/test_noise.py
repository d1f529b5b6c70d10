import numpy as np
import pytest

from drfkit.data.noise import blend_uniform_noise, rkn_noise_factors, salt_and_pepper


# ---------------------------------------------------------------- RKN noise factors


def test_noise_factors_shape_range_and_clean_start():
    f = rkn_noise_factors(500, 75, np.random.default_rng(0))
    assert f.shape == (500, 75) and f.dtype == np.float64
    assert f.min() >= 0.0 and f.max() <= 1.0
    np.testing.assert_array_equal(f[:, :5], 1.0)
    # The rescaling by (t2 - t1) >= 0.5 at most doubles the random-walk step of 0.2.
    assert np.abs(np.diff(f[:, 5:], axis=1)).max() <= 0.4 + 1e-12
    # The thresholds make stretches of pure noise and of clean frames after frame 5.
    assert (f[:, 5:] == 0.0).mean() > 0.05
    assert (f[:, 5:] == 1.0).mean() > 0.05
    assert 0.0 < f[:, 5:].mean() < 1.0


def test_noise_factors_deterministic_and_seed_dependent():
    a = rkn_noise_factors(20, 30, np.random.default_rng(4))
    b = rkn_noise_factors(20, 30, np.random.default_rng(4))
    c = rkn_noise_factors(20, 30, np.random.default_rng(5))
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_noise_factors_single_frame_is_clean():
    np.testing.assert_array_equal(rkn_noise_factors(3, 1, np.random.default_rng(0)), 1.0)


@pytest.mark.parametrize("n, t, name", [(0, 5, "n_sequences"), (5, 0, "seq_len"), (2.5, 5, "n_sequences")])
def test_noise_factors_validate(n, t, name):
    with pytest.raises((ValueError, TypeError), match=name):
        rkn_noise_factors(n, t, np.random.default_rng(0))


def test_noise_factors_need_a_generator():
    with pytest.raises(TypeError, match="Generator"):
        rkn_noise_factors(2, 2, 0)


# ---------------------------------------------------------------- uniform blend


def _images(shape, seed=0):
    return np.random.default_rng(seed).integers(0, 256, size=shape, dtype=np.uint8)


def test_blend_level_zero_is_identity():
    images = _images((3, 4, 24, 24))
    out = blend_uniform_noise(images, np.zeros((3, 4)), np.random.default_rng(1))
    assert out.dtype == np.uint8 and out.shape == images.shape
    np.testing.assert_array_equal(out, images)


def test_blend_level_one_is_independent_of_the_image():
    a = blend_uniform_noise(_images((2, 24, 24), 0), np.ones(2), np.random.default_rng(7))
    b = blend_uniform_noise(np.zeros((2, 24, 24), np.uint8), np.ones(2), np.random.default_rng(7))
    np.testing.assert_array_equal(a, b)
    # ... and is uniform on 0..255: mean 127.5, both extremes reached.
    big = blend_uniform_noise(np.zeros((50, 24, 24), np.uint8), np.ones(50), np.random.default_rng(3))
    assert abs(big.mean() - 127.5) < 1.0
    assert big.min() == 0 and big.max() == 255


def test_blend_is_convex_with_per_image_levels():
    images = np.full((4, 64, 64), 200, np.uint8)
    levels = np.array([0.0, 0.25, 0.5, 1.0])
    out = blend_uniform_noise(images, levels, np.random.default_rng(2)).astype(np.float64)
    # E[(1 - n) 200 + n U(0, 255)] = 200 - n (200 - 127.5)
    expected_means = 200.0 - levels * 72.5
    np.testing.assert_allclose(out.mean(axis=(1, 2)), expected_means, atol=1.5)
    # Each pixel lies in [(1 - n) 200, (1 - n) 200 + 255 n] up to rounding.
    low = ((1 - levels) * 200)[:, None, None] - 0.5
    high = ((1 - levels) * 200 + 255 * levels)[:, None, None] + 0.5
    assert np.all(out >= low) and np.all(out <= high)


def test_blend_validates():
    rng = np.random.default_rng(0)
    with pytest.raises(TypeError, match="uint8"):
        blend_uniform_noise(np.zeros((2, 8, 8), np.float32), np.zeros(2), rng)
    with pytest.raises(ValueError, match="one value per image"):
        blend_uniform_noise(np.zeros((2, 8, 8), np.uint8), np.zeros(3), rng)
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        blend_uniform_noise(np.zeros((2, 8, 8), np.uint8), np.array([0.0, 1.5]), rng)
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        blend_uniform_noise(np.zeros((2, 8, 8), np.uint8), np.array([0.0, np.nan]), rng)


# ---------------------------------------------------------------- salt and pepper


def test_salt_and_pepper_fraction_and_balance():
    image = np.full((500, 500), 128, np.uint8)
    out = salt_and_pepper(image, 0.1, np.random.default_rng(0))
    white = (out == 255).mean()
    black = (out == 0).mean()
    untouched = (out == 128).mean()
    assert white + black + untouched == pytest.approx(1.0)
    # 250 000 pixels: the standard error of each fraction is below 0.001.
    assert white + black == pytest.approx(0.1, abs=0.003)
    assert white == pytest.approx(0.05, abs=0.002)
    assert black == pytest.approx(0.05, abs=0.002)


def test_salt_and_pepper_p_zero_is_identity_and_p_one_replaces_all():
    image = _images((40, 30))
    out = salt_and_pepper(image, 0.0, np.random.default_rng(0))
    np.testing.assert_array_equal(out, image)
    assert out is not image
    full = salt_and_pepper(image, 1.0, np.random.default_rng(0))
    assert np.all((full == 0) | (full == 255))


def test_salt_and_pepper_does_not_modify_input():
    image = np.full((50, 50), 100, np.uint8)
    salt_and_pepper(image, 0.5, np.random.default_rng(0))
    assert np.all(image == 100)


def test_salt_and_pepper_replaces_whole_colour_pixels():
    image = np.zeros((300, 300, 3), np.uint8)
    image[..., 0], image[..., 1], image[..., 2] = 10, 100, 200
    out = salt_and_pepper(image, 0.2, np.random.default_rng(1))
    replaced = np.any(out != image, axis=-1)
    # A replaced pixel is black or white in every channel; the others are untouched.
    assert np.all((out[replaced] == 0).all(axis=-1) | (out[replaced] == 255).all(axis=-1))
    np.testing.assert_array_equal(out[~replaced], image[~replaced])
    assert replaced.mean() == pytest.approx(0.2, abs=0.005)


def test_salt_and_pepper_channels_last_override():
    # A grey batch whose width is 3 would be taken for colour; channels_last=False says otherwise.
    batch = np.full((2000, 10, 3), 128, np.uint8)
    out = salt_and_pepper(batch, 0.5, np.random.default_rng(0), channels_last=False)
    changed = out != batch
    # Per-element replacement: the three entries of a row are not always replaced together.
    assert np.any(changed.any(axis=-1) & ~changed.all(axis=-1))


def test_salt_and_pepper_seeded():
    image = _images((64, 64, 3))
    a = salt_and_pepper(image, 0.05, np.random.default_rng(9))
    b = salt_and_pepper(image, 0.05, np.random.default_rng(9))
    np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("p", [-0.1, 1.5, float("nan")])
def test_salt_and_pepper_rejects_out_of_range_p(p):
    with pytest.raises(ValueError, match="p must lie"):
        salt_and_pepper(np.zeros((8, 8), np.uint8), p, np.random.default_rng(0))


@pytest.mark.parametrize("p", ["0.1", True, None, [0.1]])
def test_salt_and_pepper_rejects_non_numeric_p(p):
    with pytest.raises(TypeError, match="p must be"):
        salt_and_pepper(np.zeros((8, 8), np.uint8), p, np.random.default_rng(0))


def test_salt_and_pepper_rejects_non_uint8():
    with pytest.raises(TypeError, match="uint8"):
        salt_and_pepper(np.zeros((8, 8), np.float32), 0.1, np.random.default_rng(0))
