"""The limit on pixels: the exact observation model of the benchmark's noise and the Bayes estimators on it."""
import math

import numpy as np
import torch

from drfkit.data.noise import Noise, blend_uniform_noise
from drfkit.data.pendulum import generate_pendulum
from drfkit.data.rod_bank import rod_bank
from drfkit.methods import pixel_bayes as pb


def test_pixel_likelihood_is_a_distribution_and_matches_the_blend():
    k = torch.arange(256)[:, None]
    for level in (0.0, 0.13, 0.5, 1.0):
        for c in (0, 37, 200, 255):
            p = pb.pixel_log_prob(k, torch.tensor([[c]]), torch.tensor(level)).exp().squeeze()
            mass = float(p[p > 2 * pb.FLOOR / max(255 * level, 1)].sum())   # the floor is not mass
            assert abs(mass - 1.0) < 1e-9, (level, c, mass)
    # against the generator's own blend: the empirical distribution of one pixel
    rng = np.random.default_rng(0)
    img = np.full((20000, 1, 1), 90, np.uint8)
    noisy = blend_uniform_noise(img, np.full(20000, 0.3), rng).ravel()
    hist = np.bincount(noisy, minlength=256) / noisy.size
    p = pb.pixel_log_prob(torch.arange(256), torch.tensor(90), torch.tensor(0.3)).exp().numpy()
    assert np.abs(hist - np.where(p > 1e-3, p, 0)).max() < 0.01


def test_the_true_image_is_the_most_likely_on_clean_and_noisy_frames():
    bank = rod_bank()
    rng = np.random.default_rng(1)
    j = rng.integers(0, len(bank), 6)
    clean = bank.images[j]
    for level in (0.0, 0.5):
        frames = blend_uniform_noise(clean, np.full(6, level), rng)
        ll = pb.frame_log_likelihoods(frames, np.full(6, level))
        # at l > 0 a neighbouring image whose differing pixels all lie in range ties with the true one
        assert np.all(ll[np.arange(6), j] >= ll.max(1) - 1e-6)
        if level == 0.0:
            assert np.array_equal(ll.argmax(1), j)


def test_likelihood_equals_the_sum_over_every_pixel_of_every_bank_image():
    # the fast path sums only distinct (pixel, value) pairs of inked pixels; the definition sums all 576
    bank = rod_bank()
    rng = np.random.default_rng(3)
    frames = blend_uniform_noise(bank.images[rng.integers(0, len(bank), 5)], np.array([0.0, 0.1, 0.4, 0.7, 1.0]), rng)
    levels = np.array([0.0, 0.1, 0.4, 0.7, 1.0])
    x = torch.from_numpy(frames.reshape(5, 1, -1).astype(np.int64))
    c = torch.from_numpy(bank.images.reshape(1, len(bank), -1).astype(np.int64))
    dense = pb.pixel_log_prob(x, c, torch.from_numpy(levels)[:, None, None]).sum(-1).numpy()
    assert np.allclose(pb.frame_log_likelihoods(frames, levels), dense, rtol=0, atol=1e-6)
    # marginalised: every grid level's dense likelihood, log-mean-exp'd, on the levels the pruning keeps
    full = np.stack([pb.frame_log_likelihoods(frames, np.full(5, g)) for g in pb.LEVEL_GRID])  # (G, 5, J)
    brute = torch.logsumexp(torch.from_numpy(full), 0).numpy() - math.log(len(pb.LEVEL_GRID))
    # where the posterior has mass (the pruning drops levels only where an image is far less likely)
    near = brute >= brute.max(1, keepdims=True) - 20.0
    assert np.abs(pb.frame_log_likelihoods(frames) - brute)[near].max() < 0.01   # float32 tables


def test_marginal_over_levels_keeps_the_posterior_of_the_whole_grid():
    d = generate_pendulum(1, 30, Noise("rkn_uniform", 0.9), 5)
    frames = d["images"][0]
    ll = pb.frame_log_likelihoods(frames)
    full = np.stack([pb.frame_log_likelihoods(frames, np.full(len(frames), g)) for g in pb.LEVEL_GRID])
    brute = torch.logsumexp(torch.from_numpy(full), 0).numpy() - math.log(len(pb.LEVEL_GRID))
    assert np.abs(pb.per_frame_bayes(frames, loglik=ll) - pb.per_frame_bayes(frames, loglik=brute)).max() < 1e-3


def test_filter_on_pixels_beats_every_frame_alone_and_coasts():
    d = generate_pendulum(4, 40, Noise("rkn_uniform", 0.75), 11)
    images = d["images"].copy()
    images[:, 20:30] = blend_uniform_noise(images[:, 20:30], np.ones((4, 10)), np.random.default_rng(2))
    ll = pb.sequence_log_likelihoods(images)
    per_frame = pb.per_frame_bayes(images, loglik=ll.reshape(-1, ll.shape[-1]))
    filtered = pb.pixel_particle_filter(ll, n_particles=500, seed=0)
    err_pf = np.abs(filtered - d["targets"]).mean(axis=(0, 2))
    err_frame = np.abs(per_frame - d["targets"]).mean(axis=(0, 2))
    assert err_pf[20:30].mean() < 0.25 < err_frame[20:30].mean()   # the state coasts where a frame alone knows nothing
    assert err_pf[:20].mean() < 0.01 and err_frame[:20].mean() < 0.02


def test_every_clean_value_at_every_level_gives_a_distribution_over_the_256_values():
    k = torch.arange(256, dtype=torch.float64)[:, None, None]          # (256, 1, 1)
    c = torch.arange(256, dtype=torch.float64)[None, :, None]          # (1, 256, 1)
    levels = torch.tensor([0.0, 1 / 255, 0.01, 0.1, 0.25, 0.5, 0.75, 0.99, 1.0], dtype=torch.float64)
    p = pb.pixel_log_prob(k, c, levels[None, None, :]).exp()           # (256 k, 256 c, L)
    floor = 2 * pb.FLOOR / torch.clamp(255 * levels, min=1.0)
    mass = torch.where(p > floor, p, torch.zeros_like(p)).sum(0)       # (256 c, L): the floor is not mass
    assert torch.allclose(mass, torch.ones_like(mass), atol=1e-9)
    # and the mass sits where the blend can put it: [(1 - l) c, (1 - l) c + 255 l], rounded
    lo, hi = (1 - levels) * c[0] - 0.5, (1 - levels) * c[0] + 255 * levels + 0.5   # (256, L)
    inside = (k >= torch.floor(lo)) & (k <= torch.ceil(hi))
    assert torch.all(torch.where(inside, torch.zeros_like(p), p) <= floor)


def test_the_per_frame_posterior_mean_is_the_brute_force_sum_over_angles():
    # uniform angles: every angle of a fine grid draws an image, weighs it by the frame's exact likelihood;
    # the bank's images weighted by their arcs must give the same posterior mean
    from drfkit.data.pendulum import render_pendulum

    rng = np.random.default_rng(7)
    theta_true = rng.uniform(-np.pi, np.pi, 3)
    clean = render_pendulum(theta_true[:, None])[:, 0]                  # (3, 24, 24)
    levels = np.array([0.2, 0.5, 0.8])
    frames = blend_uniform_noise(clean, levels, rng)
    angles = -np.pi + 2 * np.pi * (np.arange(16384) + 0.5) / 16384
    images = torch.from_numpy(render_pendulum(angles[:, None])[:, 0].reshape(len(angles), -1).astype(np.float64))
    x = torch.from_numpy(frames.reshape(3, 1, -1).astype(np.float64))
    brute = []
    for i in range(3):
        ll = pb.pixel_log_prob(x[i], images, torch.tensor(levels[i], dtype=torch.float64)).sum(-1)   # (A,)
        w = torch.softmax(ll, 0).numpy()
        brute.append([w @ np.cos(angles), w @ np.sin(angles)])
    fast = pb.per_frame_bayes(frames, levels)
    assert np.abs(fast - np.array(brute)).max() < 2e-3


def test_the_truncating_likelihood_matches_the_truncating_blend_and_is_a_distribution():
    """The benchmark's code truncates the blend where the book's generator rounds: the 'truncate' likelihood is a
    distribution over the 256 values at every clean value and level, matches the truncating blend's empirical
    histogram, and differs from the rounding one (mass moved down by half a value); an unknown mode is refused."""
    k = torch.arange(256, dtype=torch.float64)[:, None, None]
    c = torch.arange(256, dtype=torch.float64)[None, :, None]
    levels = torch.tensor([0.0, 1 / 255, 0.1, 0.5, 0.75, 1.0], dtype=torch.float64)
    p = pb.pixel_log_prob(k, c, levels[None, None, :], "truncate").exp()
    floor = 2 * pb.FLOOR / torch.clamp(255 * levels, min=1.0)
    mass = torch.where(p > floor, p, torch.zeros_like(p)).sum(0)
    assert torch.allclose(mass, torch.ones_like(mass), atol=1e-9)
    rng = np.random.default_rng(0)
    noisy = blend_uniform_noise(np.full((20000, 1, 1), 90, np.uint8), np.full(20000, 0.3), rng, "truncate").ravel()
    hist = np.bincount(noisy, minlength=256) / noisy.size
    p_t = pb.pixel_log_prob(torch.arange(256), torch.tensor(90), torch.tensor(0.3), "truncate").exp().numpy()
    p_r = pb.pixel_log_prob(torch.arange(256), torch.tensor(90), torch.tensor(0.3), "round").exp().numpy()
    assert np.abs(hist - np.where(p_t > 1e-3, p_t, 0)).max() < 0.01
    assert np.log(p_t[noisy]).sum() > np.log(p_r[noisy]).sum() + 50      # the sample is the truncating model's
    # the fast per-frame path under truncation is the dense sum over every pixel
    bank = rod_bank()
    lv = np.array([0.0, 0.2, 0.6])
    frames = blend_uniform_noise(bank.images[[3, 100, 250]], lv, np.random.default_rng(2), "truncate")
    x = torch.from_numpy(frames.reshape(3, 1, -1).astype(np.int64))
    cb = torch.from_numpy(bank.images.reshape(1, len(bank), -1).astype(np.int64))
    dense = pb.pixel_log_prob(x, cb, torch.from_numpy(lv)[:, None, None], "truncate").sum(-1).numpy()
    assert np.allclose(pb.frame_log_likelihoods(frames, lv, "truncate"), dense, rtol=0, atol=1e-6)
    assert np.argmax(pb.frame_log_likelihoods(frames, quantise="truncate"), 1).tolist() == [3, 100, 250]
    import pytest
    with pytest.raises(ValueError, match="quantise must be one of"):
        pb.pixel_log_prob(k, c, levels, "floor")
    with pytest.raises(ValueError, match="quantise must be one of"):
        blend_uniform_noise(np.zeros((1, 2, 2), np.uint8), np.zeros(1), rng, "ceil")
