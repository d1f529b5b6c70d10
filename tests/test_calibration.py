"""The calibration table's pieces on predictions whose sigma is known: intervals five times too wide cover
everything and are recalibrated to nominal coverage by one scalar fitted on other (validation) draws."""
from __future__ import annotations

import numpy as np
import pytest

from drfkit.methods import calibration as cal


def draws(n=200_000, true_sigma=0.01, seed=0):
    rng = np.random.default_rng(seed)
    mu = rng.uniform(-1, 1, n)
    sigma_true = true_sigma * rng.uniform(0.5, 2.0, n)          # heteroscedastic, and the model knows its shape
    return mu + sigma_true * rng.standard_normal(n), mu, sigma_true


def test_a_calibrated_model_covers_its_nominal_levels():
    y, mu, sigma = draws()
    out = cal.calibration_summary(y, mu, sigma)
    assert out["picp_68"] == pytest.approx(0.6827, abs=0.005) and out["picp_95"] == pytest.approx(0.95, abs=0.003)
    assert out["z_rms"] == pytest.approx(1.0, abs=0.01) and out["cal_error"] < 1e-4


def test_sigma_five_times_too_wide_is_found_and_repaired_on_validation_draws():
    y_val, mu_val, sigma_val = draws(seed=1)
    y, mu, sigma = draws(seed=2)
    wide = 5.0 * sigma                                          # the model's intervals: 5x too wide
    before = cal.calibration_summary(y, mu, wide)
    assert before["picp_68"] > 0.99 and before["z_rms"] == pytest.approx(0.2, abs=0.005)
    s = cal.sigma_scale(y_val, mu_val, 5.0 * sigma_val)         # fitted on validation, not on the scored draws
    assert s == pytest.approx(0.2, rel=0.01)
    after = cal.calibration_summary(y, mu, wide, scale=s)
    for p in (68, 90, 95):
        assert after[f"picp_{p}"] == pytest.approx(p / 100, abs=0.005)
    assert after["nll"] < before["nll"] - 1.0 and after["cal_error"] < before["cal_error"] / 100
    assert after["mpiw_95"] == pytest.approx(before["mpiw_95"] * s)


def test_the_mask_counts_only_real_values_and_bad_input_is_named():
    y, mu, sigma = (a.reshape(100, 20, 1) for a in draws(n=2000))
    mask = np.zeros((100, 20), bool)
    mask[:, :10] = True
    y_bad = y.copy()
    y_bad[:, 10:] = 1e6                                         # padding: must not count
    assert cal.sigma_scale(y_bad, mu, sigma, mask) == pytest.approx(cal.sigma_scale(y[:, :10], mu[:, :10], sigma[:, :10]))
    with pytest.raises(ValueError, match="sigma must be > 0"):
        cal.sigma_scale(y, mu, np.zeros_like(sigma))
    with pytest.raises(ValueError, match="share one shape"):
        cal.calibration_summary(y, mu[:, :5], sigma)
    with pytest.raises(ValueError, match="nothing to calibrate"):
        cal.sigma_scale(y, mu, sigma, np.zeros((100, 20), bool))
