"""The dissection of a filter (drfkit.methods.dissection) and the calibrated-gain DRF, on cases with known
answers: a diagonal filter's gain is P/(P + r); a forced gain of 0 is read back as exactly 0 and the state follows
F alone, even where F expands 8x per frame; the open-loop error of a rotating linear system with a known
transition error; the oracle gain of known errors; the calibration ratios of a known trace; the verdict rule on
each side of its thresholds."""
from __future__ import annotations

import math
import re

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


def test_q_scale_scales_q_and_the_prior_variance():
    model = paper_drf()
    w, r = model.observe(images())
    with torch.no_grad():
        one, tenth = model.filter_internals(w, r), model.filter_internals(w, r, q_scale=0.1)
    # the first step reads the same z_0 = w_0 (later ones read states that q has moved)
    assert torch.allclose(tenth["q"][:, 0], 0.1 * one["q"][:, 0], rtol=1e-5)
    assert torch.all(tenth["p_prior"][:, 0] < one["p_prior"][:, 0]) and torch.all(tenth["gain"][:, 1] < one["gain"][:, 1])


def expanding_drf(radius=8.0, latent=4):
    """A DRF whose transition is F = radius * I on every frame (the basis transition with every matrix set)."""
    torch.manual_seed(0)
    model = build_model(default_config("drf", "pendulum", 2, latent=latent, transition_kind="basis")).eval()
    with torch.no_grad():
        model.transition.basis.copy_(radius * torch.eye(latent).expand_as(model.transition.basis))
    return model


def test_a_forced_zero_gain_reads_back_as_exactly_zero_over_15_frames_where_f_expands_8x():
    model = expanding_drf()
    w, r = (t.detach() for t in model.observe(images(t=20)))
    gain = dis.forced_gain((3, 20), 3, 18)
    with torch.no_grad():
        tr = model.double().filter_steps(w.double(), r.double(), return_gains=True, return_prior=True, gain=gain)
    model.float()
    assert torch.all(tr["gains"][:, 3:18] == 0)                                   # the whole K, exactly
    z = tr["z"]
    for h in range(1, 16):                                                        # z = F^h z, nothing read
        assert torch.allclose(z[:, 2 + h], 8.0 ** h * z[:, 2], rtol=1e-9)
    assert torch.equal(tr["p_diag"][:, 3:18], tr["p_prior"][:, 2:17].double())    # P = F P F^T + Q, no update
    assert torch.all(tr["gains"][:, 18].diagonal(dim1=-2, dim2=-1) > 0.99)        # the next frame is read again
    truth = w[..., :4]
    trace = dis.filter_pass(model, w, r, truth, np.zeros((3, 20, 2)), float64=True, gain=gain)
    assert dis.check_clamped(trace, gain) == 0.0 and next(model.parameters()).dtype == torch.float32


def test_a_large_r_is_no_clamp_where_f_expands():
    """What the former intervention did (r = 1e6 on the gap): P grows 64x a frame until P / (P + r) reads the
    frames again, so the 'clamped' filter is not; ``check_clamped`` would refuse such a trace."""
    model = expanding_drf()
    w, r = (t.detach().double() for t in model.observe(images(t=20)))
    r[:, 3:18] = 1e6
    with torch.no_grad():
        tr = model.double().filter_steps(w, r, return_gains=True)
    assert tr["gains"][:, 17].diagonal(dim1=-2, dim2=-1).min() > 0.5
    fake = {"gain_abs_max": tr["gains"].diagonal(dim1=-2, dim2=-1).abs().amax(-1).numpy()}
    with pytest.raises(ValueError, match="did not skip"):
        dis.check_clamped(fake, dis.forced_gain((3, 20), 3, 18))


def test_forced_gain_names_a_span_that_touches_the_start():
    assert torch.isnan(dis.forced_gain((2, 6), 1, 3)[:, [0, 3, 4, 5]]).all()
    with pytest.raises(ValueError, match="frame 0"):
        dis.forced_gain((2, 6), 0, 3)


def test_the_known_dynamics_filter_clamped_follows_the_pendulum_alone():
    from drfkit.models.known_dynamics import pendulum_step

    torch.manual_seed(0)
    model = build_model(default_config("known_dynamics", "pendulum", 2)).eval()
    w, r = (t.detach() for t in model.observe(images(t=12)))
    gain = dis.forced_gain((3, 12), 4, 12)
    with torch.no_grad():
        tr = model.filter_steps(w, r, return_gains=True, gain=gain.float())
        internals = model.filter_internals(w, r, gain=gain.float())
    assert torch.all(tr["gains"][:, 4:] == 0) and torch.all(internals["gain"][:, 4:] == 0)
    x = tr["x"]
    for t in range(4, 12):
        theta, omega, _ = pendulum_step(x[:, t - 1, 0], x[:, t - 1, 1])
        assert torch.allclose(x[:, t], torch.stack([theta, omega], -1), atol=1e-6)


def rotating_case(model_step: float, true_step: float = 0.2, t: int = 25, start: int = 5):
    """A 2-d DRF in the output's units (readout identity) whose transition rotates by ``model_step`` per frame,
    fed exact observations of a point rotating by ``true_step``, its gain clamped on [start, start + 15)."""
    torch.manual_seed(0)
    model = build_model(default_config("drf", "pendulum", 2, latent=2, transition_kind="basis", readout="identity",
                                       noise_head="log")).eval()
    c, s = math.cos(model_step), math.sin(model_step)
    with torch.no_grad():
        model.transition.basis.copy_(torch.tensor([[c, -s], [s, c]]).expand_as(model.transition.basis))
        model.transition.log_q.fill_(math.log(1e-6))
    theta = true_step * np.arange(t)[None].repeat(2, 0) + np.array([[0.0], [1.0]])
    targets = np.stack([np.cos(theta), np.sin(theta)], -1)
    w = torch.from_numpy(targets)
    r = torch.full_like(w, 1e-12)                     # exact observations: the posterior is the truth
    gain = dis.forced_gain((2, t), start, start + dis.HORIZON)
    trace = dis.filter_pass(model, w, r, w, targets, float64=True, gain=gain)
    return trace, targets, theta, start


def test_the_open_loop_error_of_a_rotating_system_is_its_known_answer():
    trace, targets, theta, start = rotating_case(model_step=0.25)
    h = np.arange(1, dis.HORIZON + 1)
    last = theta[:, start - 1:start]                                                # (2, 1): the last read angle
    expected = np.abs(np.stack([np.cos(last + 0.25 * h), np.sin(last + 0.25 * h)], -1) - targets[:, start:start + 15])
    clamped = dis.per_horizon(trace["abs_err"], start)
    assert clamped == pytest.approx(expected.mean(-1).mean(0), abs=1e-6)
    angle = dis.per_horizon(dis.angle_error(trace["mean"], targets), start)
    assert angle == pytest.approx(np.minimum(0.05 * h, 2 * np.pi - 0.05 * h), abs=1e-6)  # 0.05 rad per frame
    held = dis.per_horizon(np.abs(dis.hold(targets, start, start + 15) - targets).mean(-1), start)
    H = dis.open_loop_horizon(clamped, held)
    ok = (clamped < held) & (clamped <= dis.OPEN_LOOP_MAX)
    assert 0 < H < dis.HORIZON and ok[:H].all() and not ok[H]
    exact, *_ = rotating_case(model_step=0.2)
    assert dis.open_loop_horizon(dis.per_horizon(exact["abs_err"], start), held) == dis.HORIZON


def test_open_loop_horizon_and_the_verdicts_on_each_side_of_their_edges():
    held = np.array([0.1, 0.2, 0.3, 0.4])
    assert dis.open_loop_horizon(np.array([0.05, 0.1, 0.09, 0.01]), held) == 4   # 0.10 itself still predicts
    assert dis.open_loop_horizon(np.array([0.05, 0.1001, 0.0, 0.0]), held) == 1  # above 0.10 it fails
    assert dis.open_loop_horizon(np.array([0.1, 0.0, 0.0, 0.0]), held) == 0      # equal to hold is not below it
    assert dis.open_loop_horizon(np.array([0.0, 0.0, 0.0, 0.0]), held) == 4
    assert dis.horizon_verdicts([0.1, 0.3, 0.3, 0.2], [0.2, 0.3, 0.2, 0.25], [0.5, 0.3, 0.5, 0.1]) == [
        "gain", "transition", "filtering", "gain"]


def test_the_oracle_gain_weighs_the_prior_and_the_observation_by_their_errors():
    noise = np.array([[0.0, 0.1, 0.1, 1.0, 1.0]] * 2)
    prior_err2 = np.array([[1.0, 1.0, 4.0, 4.0]] * 2)
    obs_err2 = np.array([[1.0, 1.0, 100.0, 100.0]] * 2)
    rows = {r["level_lo"]: r for r in dis.oracle_gain_table(prior_err2, obs_err2, noise)}
    assert rows[0.1]["gain"] == pytest.approx(0.5) and rows[1.0]["gain"] == pytest.approx(4 / 104)
    gain = dis.oracle_gain(noise, list(rows.values()))
    assert torch.isnan(gain[:, 0]).all() and gain[0, 1:].tolist() == pytest.approx([0.5, 0.5, 4 / 104, 4 / 104])


def test_the_oracle_gain_of_an_ideal_observation_is_the_observation():
    """K* = 1 where the observation is exact and the prior is not: the forced update returns w."""
    trace, targets, _, _ = rotating_case(model_step=0.25)
    torch.manual_seed(0)
    model = build_model(default_config("drf", "pendulum", 2, latent=2, transition_kind="basis", readout="identity",
                                       noise_head="log")).eval()
    w = torch.from_numpy(targets).float()
    out = dis.filter_pass(model, w, torch.full_like(w, 1e-3), w, targets, gain=torch.ones(2, 25))
    assert np.abs(out["mean"] - targets).max() < 1e-6


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
    assert {"open_loop_horizon", "mae_open_loop", "mae_open_loop_hold"} <= set(rows)   # the open loop on validation
    # the fifth round's rule: its yardstick must be a row of the profile's calibrated-gain screen
    assert cli(["screen", "--budget", "fit_tiny", "--variants", "fit_calibrated_basis_skip_wide", "--seeds", "0",
                "--out", str(tmp_path), "--rule", "both_halves", "--reference", "nope"]) == 2
    assert "pendulum_calibrated_screen.csv" in capsys.readouterr().out
    assert cli(["screen", "--budget", "fit_tiny", "--variants", "fit_calibrated_basis_skip_wide", "--seeds", "0",
                "--out", str(tmp_path), "--rule", "both_halves", "--reference", "fit_calibrated_prior_wide",
                "--csv", str(out)]) == 0
    both = pd.read_csv(out)
    assert both["variant"].tolist() == ["fit_calibrated_basis_skip_wide"] and {"mae_bound", "eligible"} <= set(both)


def test_the_gating_study_gates_the_papers_drf_only():
    from drfkit.study.gating_study import gated_models

    torch.manual_seed(0)
    models = {("drf", 0): build_model(default_config("drf", "pendulum", 2, latent=4)),
              ("drf_calibrated", 0): build_model(default_config("drf_calibrated", "pendulum", 2, latent=4))}
    assert list(gated_models(models)) == [0] and gated_models(models)[0] is models[("drf", 0)]


def test_the_both_halves_rule_needs_a_calibrated_gain_an_accurate_fit_and_then_the_longest_open_loop():
    import pandas as pd
    from drfkit.study.dissection import screen_both_halves

    means = pd.DataFrame({"r_level_spearman": [0.99, 0.99, 0.5, 0.99],
                          "gain_slope": [-0.2, -0.2, -0.5, 0.1],
                          "mae": [0.015, 0.0151, 0.009, 0.009],
                          "open_loop_horizon": [9.0, 15.0, 15.0, 15.0]}, index=["a", "b", "c", "d"])
    out = screen_both_halves(means, reference_mae=0.010)
    # b: MAE above 1.5x the yardstick's; c: r does not follow the noise; d: the gain rises with it
    assert out["eligible"].tolist() == [True, False, False, False]
    assert out.index[out["chosen"]].tolist() == ["a"]
    tie = screen_both_halves(means.assign(mae=[0.015, 0.012, 0.009, 0.009], open_loop_horizon=[14.0, 15.0, 15, 15]),
                             0.010)
    assert tie.index[tie["chosen"]].tolist() == ["b"]              # the longest; a within a frame, less accurate
    tie = screen_both_halves(means.assign(mae=[0.011, 0.012, 0.009, 0.009], open_loop_horizon=[14.0, 15.0, 15, 15]),
                             0.010)
    assert tie.index[tie["chosen"]].tolist() == ["a"]              # a tie on H goes to the lower MAE
    longer = screen_both_halves(means.assign(mae=[0.011, 0.015, 0.009, 0.009], open_loop_horizon=[13.9, 15.0, 15, 15]),
                                0.010)
    assert longer.index[longer["chosen"]].tolist() == ["b"]        # more than a frame longer wins over accuracy
    assert not screen_both_halves(means.assign(gain_slope=0.2), 0.010)["chosen"].any()


def test_the_both_halves_targets_flip_at_their_bounds():
    """The fifth round's targets on seed means: each flips when the model's number crosses its bound, a bound
    relative to a comparator follows the comparator's seed mean, and a model without rows is refused."""
    import pandas as pd

    from drfkit.study.dissection import both_halves_targets

    def protocols(steep):
        rows = [{"model": "no_dynamics", "seed": s, "mae_0.5": 0.006, "mae_0.75": 0.08, "mae_after_blackout": 0.01,
                 "mae_blackout": 0.6, "gain_ratio_blackout": math.nan} for s in range(3)]
        rows += [{"model": "lstm", "seed": s, "mae_0.5": 0.007, "mae_0.75": 0.06} for s in range(3)]
        rows += [{"model": "steep", "seed": s, **steep} for s in range(3)]
        return pd.DataFrame(rows)
    good = {"mae_0.5": 0.0047, "mae_0.75": 0.014, "mae_blackout": 0.10, "gain_ratio_blackout": 0.25,
            "mae_after_blackout": 0.009}
    dis_rows = pd.DataFrame([{"model": "steep", "seed": s, "open_loop_horizon": 15} for s in range(3)])
    table = both_halves_targets(protocols(good), dis_rows, "steep").set_index("target")
    assert table["met"].all(), table
    assert table.loc["MAE at 0.75 <= 0.5 x no_dynamics'", "bound"] == pytest.approx(0.04)
    assert table.loc["MAE after the gap <= 1.5 x no_dynamics' MAE at 0.5", "bound"] == pytest.approx(0.009)
    flips = {"mae_blackout": (0.1001, "blackout MAE <= 0.10"), "gain_ratio_blackout": (0.2501,
             "gain on pure noise <= 0.25 of clean"), "mae_after_blackout": (0.0091,
             "MAE after the gap <= 1.5 x no_dynamics' MAE at 0.5"), "mae_0.5": (0.0061, "MAE at 0.5 <= no_dynamics'")}
    for column, (value, target) in flips.items():
        bad = both_halves_targets(protocols({**good, column: value}), dis_rows, "steep").set_index("target")
        assert not bad.loc[target, "met"] and bad["met"].sum() >= len(bad) - 2, (column, bad)
    short = both_halves_targets(protocols(good), dis_rows.assign(open_loop_horizon=[15, 15, 14]), "steep")
    assert not short.set_index("target").loc["open-loop horizon H >= 15 at 0.5", "met"]
    with pytest.raises(ValueError, match="no rows of 'absent'"):
        both_halves_targets(protocols(good), dis_rows, "absent")


def test_the_dissection_encodes_the_noiseless_frames_once_per_model_with_the_same_numbers(monkeypatch):
    """The three sets show the same motions, so their noiseless frames are encoded once per filter (four encoder
    passes, not six), and the rows are those of encoding them once per set, byte for byte."""
    from drfkit.study import dissection, studies
    from drfkit.study.params import for_notebook, load_profile

    P = for_notebook("02_pendulum_dynamics", load_profile("quick"))
    torch.manual_seed(0)
    models = {(kind, 0): build_model(studies.model_config("pendulum", kind, P)).eval()
              for kind in ("no_dynamics", "drf_calibrated")}
    encoded = []
    real = dis.observations
    monkeypatch.setattr(dis, "observations", lambda model, images, **kw: encoded.append(images.shape) or real(model, images, **kw))
    once = [t.to_csv(index=False) for t in dissection.dissect_filters(P, models)]
    assert len(encoded) == 4

    def once_per_set(model, arrays, codes):
        w, r = real(model, torch.from_numpy(arrays["images"]))
        w_clean, _ = real(model, torch.from_numpy(arrays["clean"]))
        return w, r, model.observed_truth(w_clean, torch.from_numpy(arrays["targets"]))

    monkeypatch.setattr(dissection, "_prepared", once_per_set)
    assert [t.to_csv(index=False) for t in dissection.dissect_filters(P, models)] == once


def test_the_encoder_tool_counts_fewer_frames_in_one_block_with_the_same_rows(load_tool, capsys):
    """tools/dissection_encodes.py (docs/rerun_time.md's measurement) on a random model of the quick profile: with the
    dissection's passes in one block the encoder runs on fewer frames than with a block per call, the same rows."""
    assert load_tool("dissection_encodes").main(["--profile", "quick", "--untrained", "--kind", "drf_calibrated",
                                                "--sequences", "3", "--rounds", "1"]) == 0
    out = capsys.readouterr().out
    counts = {m[0]: int(m[1]) for m in re.findall(r"\| (one block per filter|a block per call) \| (\d+) \|", out)}
    per_set = int(re.search(r"one set is (\d+) frames", out)[1])
    # one block: the training noise set and the highest noise set (their distinct frames), the blackout's gap, the
    # noiseless frames' distinct ones; a block per call: those again for every pass
    assert 2 * per_set * 0.5 < counts["one block per filter"] < 3 * per_set < counts["a block per call"]
    assert "rows byte for byte the same: True" in out
