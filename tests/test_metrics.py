"""Tests of drfkit.core.metrics: known values, hand-made cases, masks, calibration, errors."""
import math
from statistics import NormalDist

import numpy as np
import pytest
import torch

from drfkit.core.metrics import (
    DEFAULT_CALIBRATION_LEVELS, calibration_curve, calibration_error, crps_gaussian, gaussian_interval,
    gaussian_nll, interval_score, mae, mpiw, normal_cdf, normal_ppf, picp,
)


# --------------------------------------------------------------------------- reference values (textbook definitions: Gneiting & Raftery 2007 for CRPS)

@pytest.mark.parametrize("mu", [0.0, -3.7, 12.5])
def test_crps_and_nll_reference_values(mu):
    assert crps_gaussian(mu, mu, 1.0) == pytest.approx(0.2336950, abs=1e-6)
    assert crps_gaussian(mu + 1.0, mu, 1.0) == pytest.approx(0.6024414, abs=1e-6)
    assert crps_gaussian(mu - 1.0, mu, 1.0) == pytest.approx(0.6024414, abs=1e-6)  # symmetric
    assert crps_gaussian(mu, mu, 2.0) == pytest.approx(0.4673900, abs=1e-6)
    assert gaussian_nll(mu, mu, 1.0) == pytest.approx(0.9189385, abs=1e-6)
    assert gaussian_nll(mu + 1.0, mu, 1.0) == pytest.approx(1.4189385, abs=1e-6)


def test_crps_matches_numerical_integral():
    # CRPS(F, y) = integral of (F(x) - 1[x >= y])^2 dx, done here by the trapezoid rule.
    nd = NormalDist(0.3, 1.7)
    for y in (-2.0, 0.3, 4.1):
        numeric = 0.0
        for a, b, step in ((-20.0, y, 0.0), (y, 20.0, 1.0)):  # split at the jump of the step function
            x = np.linspace(a, b, 100_001)
            integrand = (np.array([nd.cdf(v) for v in x]) - step) ** 2
            numeric += float(np.sum(0.5 * (integrand[1:] + integrand[:-1]) * np.diff(x)))
        assert crps_gaussian(y, 0.3, 1.7) == pytest.approx(numeric, abs=1e-7)


def test_normal_cdf_and_ppf_are_exact():
    x = np.linspace(-8, 8, 33)
    expected = np.array([NormalDist().cdf(v) for v in x])
    np.testing.assert_allclose(normal_cdf(x), expected, rtol=1e-12, atol=1e-15)
    assert normal_cdf(-30.0) > 0  # erfc keeps the far lower tail
    np.testing.assert_allclose(normal_cdf(normal_ppf([0.01, 0.5, 0.975])), [0.01, 0.5, 0.975], atol=1e-12)
    with pytest.raises(ValueError, match="strictly between 0 and 1"):
        normal_ppf([0.0, 0.5])


# --------------------------------------------------------------------------- hand-made cases

def test_mae_picp_mpiw_interval_score_by_hand():
    y = np.array([0.0, 1.0, 2.0, 5.0])
    mu = np.array([0.5, 1.0, 1.0, 3.0])
    assert mae(y, mu) == pytest.approx((0.5 + 0 + 1 + 2) / 4)

    lower = np.array([-1.0, 1.0, 2.5, 0.0])
    upper = np.array([1.0, 3.0, 3.0, 4.0])
    # inside, on the lower edge (counts), below, above
    assert picp(y, lower, upper) == pytest.approx(0.5)
    assert mpiw(lower, upper) == pytest.approx((2 + 2 + 0.5 + 4) / 4)
    alpha = 0.1
    scores = [2.0, 2.0, 0.5 + 2 / alpha * 0.5, 4.0 + 2 / alpha * 1.0]
    assert interval_score(y, lower, upper, alpha) == pytest.approx(np.mean(scores))


def test_nll_and_crps_vectorised_equal_means_of_scalars():
    rng = np.random.default_rng(0)
    y, mu, sigma = rng.normal(size=7), rng.normal(size=7), rng.uniform(0.2, 3, size=7)
    assert gaussian_nll(y, mu, sigma) == pytest.approx(np.mean([gaussian_nll(*a) for a in zip(y, mu, sigma)]))
    assert crps_gaussian(y, mu, sigma) == pytest.approx(np.mean([crps_gaussian(*a) for a in zip(y, mu, sigma)]))
    nll_direct = np.mean([-math.log(NormalDist(m, s).pdf(v)) for v, m, s in zip(y, mu, sigma)])
    assert gaussian_nll(y, mu, sigma) == pytest.approx(nll_direct, rel=1e-12)


def test_gaussian_interval_uses_z_1_959964():
    mu, sigma = np.array([0.0, 2.0]), np.array([1.0, 0.5])
    lower, upper = gaussian_interval(mu, sigma, 0.95)
    assert isinstance(lower, np.ndarray)
    np.testing.assert_allclose((upper - mu) / sigma, 1.959964, atol=1e-6)
    np.testing.assert_allclose((mu - lower) / sigma, 1.959964, atol=1e-6)
    lo68, hi68 = gaussian_interval(0.0, 1.0, 0.6826894921370859)
    assert hi68 == pytest.approx(1.0, abs=1e-9) and lo68 == pytest.approx(-1.0, abs=1e-9)


def test_gaussian_interval_keeps_torch_kind_and_gradient():
    mu = torch.tensor([0.0, 1.0], dtype=torch.float32, requires_grad=True)
    sigma = torch.tensor([1.0, 2.0], dtype=torch.float32)
    lower, upper = gaussian_interval(mu, sigma)
    assert isinstance(upper, torch.Tensor) and upper.dtype == torch.float32
    upper.sum().backward()
    assert torch.equal(mu.grad, torch.ones(2))


def test_interval_coverage_of_gaussian_samples():
    rng = np.random.default_rng(1)
    mu, sigma = rng.normal(size=100_000), rng.uniform(0.5, 2, size=100_000)
    y = rng.normal(mu, sigma)
    lower, upper = gaussian_interval(mu, sigma, 0.9)
    assert picp(y, lower, upper) == pytest.approx(0.9, abs=0.005)
    assert mpiw(lower, upper) == pytest.approx(2 * 1.6448536 * np.mean(sigma), rel=1e-6)


# --------------------------------------------------------------------------- kinds and masks

def test_numpy_and_torch_inputs_give_the_same_float():
    rng = np.random.default_rng(2)
    y, mu, sigma = rng.normal(size=(4, 5)), rng.normal(size=(4, 5)), rng.uniform(0.5, 2, (4, 5))
    lo, hi = mu - sigma, mu + sigma
    t = lambda a: torch.tensor(a, dtype=torch.float32, requires_grad=True)  # noqa: E731
    y32 = t(y).detach().double().numpy()  # what the float32 tensors hold exactly
    mu32, s32, lo32, hi32 = (t(a).detach().double().numpy() for a in (mu, sigma, lo, hi))
    pairs = [
        (mae(t(y), t(mu)), mae(y32, mu32)),
        (picp(t(y), t(lo), t(hi)), picp(y32, lo32, hi32)),
        (mpiw(t(lo), t(hi)), mpiw(lo32, hi32)),
        (gaussian_nll(t(y), t(mu), t(sigma)), gaussian_nll(y32, mu32, s32)),
        (crps_gaussian(t(y), t(mu), t(sigma)), crps_gaussian(y32, mu32, s32)),
        (interval_score(t(y), t(lo), t(hi), 0.32), interval_score(y32, lo32, hi32, 0.32)),
        (calibration_error(t(y), t(mu), t(sigma)), calibration_error(y32, mu32, s32)),
    ]
    for from_torch, from_numpy in pairs:
        assert type(from_torch) is float and from_torch == from_numpy
    assert gaussian_nll(torch.tensor(y), torch.tensor(mu), torch.tensor(sigma)) == gaussian_nll(y, mu, sigma)


def test_mask_excludes_elements():
    rng = np.random.default_rng(3)
    y, mu, sigma = rng.normal(size=(3, 6)), rng.normal(size=(3, 6)), rng.uniform(0.5, 2, (3, 6))
    mask = np.ones((3, 6), dtype=bool)
    mask[1, 4:] = False
    mask[2, 0] = False
    # garbage at the padded positions must not matter (nor raise)
    y_bad, sigma_bad = y.copy(), sigma.copy()
    y_bad[~mask], sigma_bad[~mask] = np.nan, 0.0
    lo, hi = mu - sigma, mu + sigma
    assert mae(y_bad, mu, mask=mask) == pytest.approx(np.mean(np.abs(y - mu)[mask]))
    assert gaussian_nll(y_bad, mu, sigma_bad, mask=mask) == pytest.approx(gaussian_nll(y[mask], mu[mask], sigma[mask]))
    assert crps_gaussian(y_bad, mu, sigma_bad, mask=torch.from_numpy(mask)) == pytest.approx(
        crps_gaussian(y[mask], mu[mask], sigma[mask]))
    assert picp(y_bad, lo, hi, mask=mask) == pytest.approx(picp(y[mask], lo[mask], hi[mask]))
    assert mpiw(lo, hi, mask=mask) == pytest.approx(mpiw(lo[mask], hi[mask]))
    assert interval_score(y_bad, lo, hi, 0.2, mask=mask) == pytest.approx(
        interval_score(y[mask], lo[mask], hi[mask], 0.2))
    e1, o1 = calibration_curve(y_bad, mu, sigma_bad, mask=mask)
    e2, o2 = calibration_curve(y[mask], mu[mask], sigma[mask])
    np.testing.assert_array_equal(o1, o2)
    # a mask that broadcasts (per-sequence) is fine too
    row_mask = np.array([[True], [False], [True]])
    assert mae(y, mu, mask=row_mask) == pytest.approx(np.mean(np.abs(y - mu)[[0, 2]]))


# --------------------------------------------------------------------------- calibration

def test_calibration_curve_of_well_specified_predictor_is_diagonal():
    rng = np.random.default_rng(4)
    n = 200_000
    mu, sigma = rng.normal(size=n) * 3, rng.uniform(0.1, 5, size=n)
    y = rng.normal(mu, sigma)
    expected, observed = calibration_curve(y, mu, sigma)
    assert expected.shape == observed.shape == (19,)
    np.testing.assert_allclose(expected, np.arange(1, 20) * 0.05, atol=1e-12)
    np.testing.assert_allclose(observed, expected, atol=0.006)
    assert calibration_error(y, mu, sigma) < 1e-5


def test_calibration_curve_of_overconfident_predictor():
    # sigma reported 3x too small: P(y <= mu + (s/3) z_p) = Phi(z_p / 3), far from p.
    rng = np.random.default_rng(5)
    n = 200_000
    mu, sigma = rng.normal(size=n), rng.uniform(0.5, 2, size=n)
    y = rng.normal(mu, sigma)
    expected, observed = calibration_curve(y, mu, sigma / 3)
    np.testing.assert_allclose(observed, normal_cdf(normal_ppf(expected) / 3), atol=0.006)
    assert observed[0] > 0.25 and observed[-1] < 0.75  # Phi(Phi^-1(0.05) / 3) = 0.29
    err = calibration_error(y, mu, sigma / 3)
    assert err == pytest.approx(np.mean((normal_cdf(normal_ppf(expected) / 3) - expected) ** 2), rel=0.05)
    assert err > 0.02


def test_calibration_custom_levels_and_small_exact_case():
    # standardised residuals -1, 0, 1, 2: below the median quantile (0) are -1 and 0.
    y, mu, sigma = np.array([-1.0, 0.0, 1.0, 2.0]), 0.0, 1.0
    expected, observed = calibration_curve(y, mu, sigma, levels=[0.5, 0.9])
    np.testing.assert_array_equal(expected, [0.5, 0.9])
    np.testing.assert_array_equal(observed, [0.5, 0.75])  # Phi^-1(0.9) = 1.28 > 1
    assert calibration_error(y, mu, sigma, levels=[0.5, 0.9]) == pytest.approx(0.15 ** 2 / 2)
    assert len(DEFAULT_CALIBRATION_LEVELS) == 19


# --------------------------------------------------------------------------- errors

@pytest.mark.parametrize("bad_sigma", [0.0, -1.0])
def test_nonpositive_sigma_raises(bad_sigma):
    sigma = np.array([1.0, bad_sigma])
    for fn in (gaussian_nll, crps_gaussian, calibration_curve, calibration_error):
        with pytest.raises(ValueError, match="sigma must be > 0"):
            fn(np.zeros(2), np.zeros(2), sigma)
    with pytest.raises(ValueError, match="sigma must be > 0"):
        gaussian_interval(np.zeros(2), sigma)
    with pytest.raises(ValueError, match="sigma must be > 0"):
        gaussian_interval(torch.zeros(2), torch.tensor(sigma))


def test_shape_mismatch_raises():
    with pytest.raises(ValueError, match="do not broadcast"):
        mae(np.zeros(5), np.zeros(4))
    with pytest.raises(ValueError, match="larger than every input"):
        gaussian_nll(np.zeros(5), np.zeros((5, 1)), 1.0)
    with pytest.raises(ValueError, match="do not broadcast"):
        gaussian_interval(torch.zeros(3), torch.ones(2))
    with pytest.raises(ValueError, match="mask has shape"):
        mae(np.zeros((2, 3)), np.zeros((2, 3)), mask=np.ones(2, dtype=bool))
    with pytest.raises(TypeError, match="mask must be boolean"):
        mae(np.zeros(3), np.zeros(3), mask=np.ones(3))


def test_other_bad_inputs_raise():
    with pytest.raises(ValueError, match="lower > upper"):
        picp(np.zeros(2), np.array([1.0, 0.0]), np.array([0.0, 1.0]))
    with pytest.raises(ValueError, match="alpha must lie strictly between 0 and 1"):
        interval_score(0.0, -1.0, 1.0, alpha=1.5)
    with pytest.raises(ValueError, match="level must lie strictly between 0 and 1"):
        gaussian_interval(0.0, 1.0, level=95)
    with pytest.raises(ValueError, match="levels must be"):
        calibration_curve(np.zeros(3), 0.0, 1.0, levels=[0.5, 1.0])
    with pytest.raises(ValueError, match="no element is counted"):
        mae(np.zeros(3), np.zeros(3), mask=np.zeros(3, dtype=bool))
    with pytest.raises(ValueError, match="NaN or inf"):
        mae(np.array([0.0, np.nan]), np.zeros(2))
    with pytest.raises(TypeError, match="numpy array, torch tensor or number"):
        mae("abc", 0.0)


def test_the_bootstrap_interval_covers_the_mean_and_narrows_with_more_units():
    from drfkit.core.metrics import bootstrap_interval
    rng = np.random.default_rng(0)
    small, large = rng.normal(1.0, 1.0, 20), rng.normal(1.0, 1.0, 2000)
    lo, hi = bootstrap_interval(small)
    assert lo < small.mean() < hi
    lo2, hi2 = bootstrap_interval(large)
    assert lo2 < 1.0 < hi2 and (hi2 - lo2) < (hi - lo) / 5
    assert (hi2 - lo2) == pytest.approx(2 * 1.96 / np.sqrt(2000), rel=0.15)  # the normal theory's width
    assert np.isnan(bootstrap_interval([1.0])[0])
