"""The dissection of a filter (drfkit.methods.dissection) and the calibrated-gain DRF, on cases with known
answers: a diagonal filter's gain is P/(P + r), a clamped r stops the update, the r fits recover a known law,
the calibration ratios of a known trace, the decision rule on each side of its thresholds."""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from drfkit.methods import dissection as dis
from drfkit.models import build_model, default_config
from drfkit.models.drf import frame_noise_statistic

torch.set_num_threads(1)


def images(b=3, t=8, seed=0):
    return torch.randint(0, 256, (b, t, 24, 24), dtype=torch.uint8, generator=torch.Generator().manual_seed(seed))


def paper_drf(latent=4, seed=0):
    torch.manual_seed(seed)
    return build_model(default_config("drf", "pendulum", 2, latent=latent)).eval()


# ------------------------------------------------------------------ the model's internals
def test_an_untrained_drf_is_diagonal_so_its_gain_is_the_prior_over_prior_plus_r():
    # F = I at the start (the head's residual is zero) and P_0, Q, r diagonal: P stays diagonal and
    # K_ii = P_prior_ii / (P_prior_ii + r_ii) exactly, with P_prior = P + q (q inside the prior's variance)
    model = paper_drf()
    w, r = model.observe(images())
    with torch.no_grad():
        out = model.filter_internals(w, r)
    expected = out["p_prior"] / (out["p_prior"] + r[:, 1:])
    assert torch.allclose(out["gain"][:, 1:], expected, atol=1e-5)
    assert torch.all(out["gain"][:, 0] == 1.0)
    assert torch.allclose(out["prior"], out["h"][:, :-1, :4], atol=1e-6)  # F = I: the prior is the last posterior
    assert torch.all(out["q"] > 0) and torch.all(out["p_prior"] > out["q"])


def test_a_clamped_r_stops_the_update_and_the_state_coasts():
    model = paper_drf()
    w, r = model.observe(images(t=10))
    clamp = dis.clamp_frames((*r.shape[:2], 4), 4, 8)
    r_new = dis.override_r(r, clamp, 4)
    assert torch.all(r_new[:, 4:8] == dis.R_CLAMP) and torch.equal(r_new[:, :4], r[:, :4])
    with torch.no_grad():
        out = model.filter_internals(w, r_new)
    z = out["h"][..., :4]
    assert out["gain"][:, 4:8].max() < 1e-4
    assert torch.allclose(z[:, 4:8], z[:, 3:4].expand(-1, 4, -1), atol=1e-3)  # F = I: the state stays put
    assert out["gain"][:, 8].min() > 0.3                                      # and the next frame is read again


def test_q_scale_scales_q_and_the_prior_variance():
    model = paper_drf()
    w, r = model.observe(images())
    with torch.no_grad():
        one, tenth = model.filter_internals(w, r), model.filter_internals(w, r, q_scale=0.1)
    # the first step reads the same z_0 = w_0 (later ones read states that q has moved)
    assert torch.allclose(tenth["q"][:, 0], 0.1 * one["q"][:, 0], rtol=1e-5)
    assert torch.all(tenth["p_prior"][:, 0] < one["p_prior"][:, 0]) and torch.all(tenth["gain"][:, 1] < one["gain"][:, 1])


def test_override_r_keeps_nan_entries_and_names_a_wrong_shape():
    r = torch.ones(2, 3, 5)
    new = np.full((2, 3, 2), np.nan)
    new[0, 1] = 7.0
    out = dis.override_r(r, new, 2)
    assert out[0, 1, :2].tolist() == [7.0, 7.0] and out[0, 1, 2:].tolist() == [1.0] * 3
    assert float(out.sum()) == 30 + 2 * 6.0
    with pytest.raises(ValueError, match=r"\(N, T, k\)"):
        dis.override_r(r, np.ones((2, 3, 5)), 2)


def test_known_dynamics_internals_live_in_the_observation_space():
    torch.manual_seed(0)
    model = build_model(default_config("known_dynamics", "pendulum", 2)).eval()
    w, r = model.observe(images())
    with torch.no_grad():
        out = model.filter_internals(w, r)
        big = model.filter_internals(w, r * 100.0)
    assert out["prior"].shape == (3, 7, 2) and torch.allclose(out["prior"].norm(dim=-1), torch.ones(3, 7), atol=1e-5)
    assert torch.all(out["gain"][:, 1:] >= -1e-6) and torch.all(out["gain"][:, 1:].sum(-1) <= 1 + 1e-5)
    assert big["gain"][:, 1:].sum(-1).mean() < out["gain"][:, 1:].sum(-1).mean()


# ------------------------------------------------------------------ the pure functions
def test_filter_pass_measures_errors_against_the_truth_and_decodes_dropout_off():
    model = paper_drf()
    x = images()
    w, r = model.observe(x)
    truth = w[..., :4].detach() + 0.5
    targets = np.zeros((3, 8, 2))
    trace = dis.filter_pass(model, w.detach(), r.detach(), truth, targets)
    assert np.allclose(trace["obs_err2"], 4 * 0.25) and np.allclose(trace["obs_err2_dims"], 0.25)
    with torch.no_grad():
        mean, _ = model(x)
    assert np.allclose(trace["mean"], mean.numpy(), atol=1e-5)
    assert np.allclose(trace["abs_err"], np.abs(mean.numpy()).mean(-1), atol=1e-5)
    assert trace["p_prior"].shape == (3, 7) and trace["gain"].shape == (3, 8)


def test_filter_pass_in_float64_is_the_same_pass_on_a_copy():
    """The clamped-gain intervention runs in float64 (a diverging transition's P outgrows float32 beside
    r = R_CLAMP): the same numbers as float32 up to rounding, and the model itself stays float32."""
    model = paper_drf()
    w, r = model.observe(images(t=10))
    w, r = w.detach(), dis.override_r(r.detach(), dis.clamp_frames((3, 10, 4), 4, 8), 4)
    truth, targets = w[..., :4] + 0.1, np.zeros((3, 10, 2))
    single = dis.filter_pass(model, w, r, truth, targets)
    double = dis.filter_pass(model, w, r, truth, targets, float64=True)
    assert next(model.parameters()).dtype == torch.float32 and w.dtype == torch.float32
    assert np.allclose(single["abs_err"], double["abs_err"], atol=1e-5)
    assert np.allclose(single["gain"], double["gain"], atol=1e-5) and double["gain"][:, 4:8].max() < 1e-4


def test_level_bins_keep_pure_noise_apart():
    bins = dis.level_bins(np.array([[0.0, 0.049, 0.05, 0.51, 1.0]]))
    assert bins[0, :4].tolist() == [0, 0, 1, 10] and bins[0, 4] > 1000


def test_calibration_ratios_of_a_known_trace():
    n, t = 4, 6
    noise = np.tile(np.array([0.0, 0.0, 0.2, 0.2, 1.0, 1.0]), (n, 1))
    trace = {"r": np.full((n, t), 2.0), "obs_err2": np.where(noise >= 1.0, 200.0, 2.0) * np.ones((n, t)),
             "gain": np.full((n, t), 0.5), "abs_err": np.full((n, t), 0.1),
             "p_prior": np.full((n, t - 1), 4.0), "q": np.full((n, t - 1), 1.0), "prior_err2": np.full((n, t - 1), 1.0)}
    rows = {row["level_lo"]: row for row in dis.calibration_table(trace, noise)}
    assert set(rows) == {0.0, 0.2, 1.0}
    assert rows[0.0]["frames"] == n  # t >= 1 only: frame 0 has no prior
    assert rows[0.2]["err2_over_r"] == pytest.approx(1.0) and rows[1.0]["err2_over_r"] == pytest.approx(100.0)
    assert rows[0.2]["e2_over_p"] == pytest.approx(0.25)


def test_the_log_linear_fit_recovers_a_known_law_and_extrapolates():
    rng = np.random.default_rng(0)
    noise = rng.uniform(0, 1.0, size=(400, 50))
    law = np.exp(np.log(0.01) + np.array([4.0, 6.0]) * noise[..., None])           # (N, T, 2)
    err2 = law * rng.chisquare(1, size=law.shape)
    log_a, b = dis.fit_log_linear_r(err2, noise, max_level=0.5)
    assert b == pytest.approx([4.0, 6.0], abs=0.3) and np.exp(log_a) == pytest.approx([0.01, 0.01], rel=0.15)
    r = dis.r_from_fit(noise, log_a, b)
    high = noise > 0.9
    assert np.median(r[high] / law[high]) == pytest.approx(1.0, abs=0.35)  # beyond the fitted levels too
    oracle = dis.r_from_levels(err2, noise)
    assert np.median(oracle[high] / law[high]) == pytest.approx(1.0, abs=0.2)
    with pytest.raises(ValueError, match="two bins"):
        dis.fit_log_linear_r(err2, np.full_like(noise, 0.01), max_level=0.5)


def test_r_scale_is_the_error_over_r_per_dim():
    trace = {"obs_err2_dims": np.stack([np.full((2, 3), 1.0), np.full((2, 3), 8.0)], -1)}
    r = torch.stack([torch.full((2, 3), 4.0), torch.full((2, 3), 2.0), torch.full((2, 3), 9.0)], -1)
    assert dis.r_scale(trace, r).tolist() == pytest.approx([0.25, 4.0])


@pytest.mark.parametrize("clamped,oracle,oracle_q,expected", [
    (0.10, 0.05, math.nan, "gain"),           # both on their boundary
    (0.1001, 0.05, math.nan, "transition"),   # does not coast
    (0.10, 0.0501, math.nan, "transition"),   # a competent r is not enough ...
    (0.10, 0.0501, 0.05, "prior variance"),   # ... but with q calibrated it is
    (0.11, 0.0501, 0.01, "transition"),       # q does not rescue a transition that cannot coast
    (math.nan, 0.01, 0.01, "not measured"),
])
def test_the_failure_verdict_on_each_side_of_its_thresholds(clamped, oracle, oracle_q, expected):
    assert dis.failure_verdict(clamped, oracle, 0.1, oracle_q) == expected


def test_calibrate_q_scale_picks_the_scale_whose_prior_variance_matches_its_error():
    model = paper_drf()
    w, r = model.observe(images(b=4, t=10))
    w, r = w.detach(), r.detach()
    truth = w[..., :4].clone()
    scale, ratio = dis.calibrate_q_scale(model, w, r, truth, np.zeros((4, 10, 2)))
    ratios = {}
    for s in dis.Q_SCALES:
        t = dis.filter_pass(model, w, r, truth, np.zeros((4, 10, 2)), q_scale=s)
        ratios[s] = t["prior_err2"].mean() / t["p_prior"].mean()
    assert scale == min(ratios, key=lambda s: abs(math.log(ratios[s])))
    assert ratio == pytest.approx(ratios[scale])


# ------------------------------------------------------------------ the calibrated-gain DRF
def test_the_frame_statistic_rises_linearly_with_the_benchmark_noise():
    from drfkit.data.noise import blend_uniform_noise
    clean = np.zeros((1, 200, 24, 24), np.uint8)
    rng = np.random.default_rng(0)
    levels = np.linspace(0, 1, 200)[None]
    s = frame_noise_statistic(torch.from_numpy(blend_uniform_noise(clean, levels, rng)))[0, :, 0].numpy()
    # black background: s ~ the level, up to pure noise (576 pixels: a frame's sd is about 0.024 l)
    assert np.allclose(s, levels[0], atol=0.1)
    assert np.polyfit(levels[0], s, 1)[0] == pytest.approx(1.0, abs=0.03)


def test_the_calibrated_drf_reads_r_from_the_frame_monotonically_and_rebuilds_from_its_config():
    torch.manual_seed(0)
    model = build_model(default_config("drf_calibrated", "pendulum", 2, latent=4)).eval()
    assert model.config["kind"] == "drf_calibrated" and build_model(model.config).config == model.config
    x = torch.zeros(1, 3, 24, 24, dtype=torch.uint8)
    x[0, 1], x[0, 2] = 100, 255
    with torch.no_grad():
        w, r = model.observe(x)
    assert torch.all(r[0, 1] > r[0, 0]) and torch.all(r[0, 2] > r[0, 1])  # beyond any training level too
    assert torch.allclose(r[0, 0], torch.ones(4) + 1e-4)                  # log r0 = 0 at the start
    with pytest.raises(ValueError, match="pendulum"):
        build_model(default_config("drf", "keypoints", 1) | {"kind": "drf_calibrated"})


def test_the_observation_loss_gradient_reaches_the_calibrated_link():
    torch.manual_seed(0)
    model = build_model(default_config("drf_calibrated", "pendulum", 2, latent=4))
    mean, sigma = model(images(b=2, t=5))
    mean.square().sum().add(sigma.sum()).backward()
    assert model.log_r0.grad is not None and model.log_r0.grad.abs().sum() > 0
    assert model.r_slope.grad.abs().sum() > 0


def test_an_intervened_filter_is_decoded_with_the_variance_it_is_given():
    model = paper_drf()
    x = images(t=10)
    w, r = (t.detach() for t in model.observe(x))
    truth = w[..., :4].clone()
    base = dis.filter_pass(model, w, r, truth, np.zeros((3, 10, 2)))
    assert np.allclose(model.belief_variance(model.with_belief_variance(torch.zeros(3, 10, 8), torch.ones(3, 10, 4))), 1)
    held = dis.held_variance(base["log_var"], 4, 8)
    assert np.array_equal(held[:, 4:8], np.repeat(base["log_var"][:, 3:4], 4, 1)) and np.array_equal(held[:, 8:], base["log_var"][:, 8:])
    # the same filter decoded with its own variances is the same output; with other variances another
    same = dis.filter_pass(model, w, r, truth, np.zeros((3, 10, 2)), log_var=base["log_var"])
    assert np.allclose(same["mean"], base["mean"], atol=1e-6)
    other = dis.filter_pass(model, w, r, truth, np.zeros((3, 10, 2)), log_var=base["log_var"] + 3.0)
    assert not np.allclose(other["mean"], base["mean"], atol=1e-3)


def test_the_in_distribution_screen_reads_only_levels_up_to_the_training_noise():
    n, t = 50, 6
    rng = np.random.default_rng(1)
    noise = rng.uniform(0, 0.5, size=(n, t))
    noise[:, -1] = 1.0                                            # pure noise: must be left out
    trace = {"r": np.exp(2.0 * noise), "gain": 0.8 - 0.6 * noise, "abs_err": np.full((n, t), 0.01)}
    trace["abs_err"][:, -1] = 5.0
    out = dis.in_distribution_screen(trace, noise, max_level=0.5)
    assert out["r_level_spearman"] == pytest.approx(1.0) and out["r_log_slope"] == pytest.approx(2.0, abs=1e-6)
    assert out["gain_slope"] == pytest.approx(-0.6, abs=1e-6) and out["mae"] == pytest.approx(0.01)


def test_the_screen_rule_picks_the_most_accurate_eligible_variant_and_breaks_ties_by_the_gain_slope():
    import pandas as pd
    from drfkit.study.dissection import screen_choice

    means = pd.DataFrame({"r_level_spearman": [0.95, 0.79, 0.9, 0.85], "gain_slope": [-0.1, -0.9, -0.5, 0.1],
                          "mae": [0.0100, 0.0050, 0.0104, 0.0060]}, index=["a", "b", "c", "d"])
    out = screen_choice(means)
    assert out["eligible"].tolist() == [True, False, True, False]  # b: rho < 0.8; d: the gain rises
    assert out.index[out["chosen"]].tolist() == ["c"]               # a and c tie within 5 %: the steeper slope
    assert not screen_choice(means.assign(gain_slope=0.2))["chosen"].any()


def test_the_screen_command_judges_trained_variants_on_validation_only(tmp_path, capsys):
    from drfkit.cli import main as cli

    out = tmp_path / "screen.csv"
    assert cli(["screen", "--budget", "fit_tiny", "--variants", "fit_calibrated_wide", "--seeds", "0",
                "--out", str(tmp_path), "--csv", str(out)]) == 0
    import pandas as pd
    table = pd.read_csv(out)
    assert table["variant"].tolist() == ["fit_calibrated_wide"] and {"eligible", "chosen", "gain_slope"} <= set(table)
    assert not list(tmp_path.glob("data/*test*"))      # the screen never builds a test split
    assert cli(["screen", "--variants", "nope"]) == 2 and "unknown variant" in capsys.readouterr().err
    capsys.readouterr()
    assert cli(["screen", "--budget", "fit_tiny", "--variants", "fit_calibrated_wide", "--seeds", "0",
                "--out", str(tmp_path), "--per-seed"]) == 0
    import re
    printed = capsys.readouterr().out
    assert re.search(r"fit_calibrated_wide: [01] of 1 seeds fail", printed) and "failed" in printed
    rows = pd.read_csv(out)  # the first call's table is untouched by a call without --csv
    assert len(rows) == 1


def test_the_gating_study_gates_the_papers_drf_only():
    from drfkit.study.gating_study import gated_models

    torch.manual_seed(0)
    models = {("drf", 0): build_model(default_config("drf", "pendulum", 2, latent=4)),
              ("drf_calibrated", 0): build_model(default_config("drf_calibrated", "pendulum", 2, latent=4))}
    assert list(gated_models(models)) == [0] and gated_models(models)[0] is models[("drf", 0)]
