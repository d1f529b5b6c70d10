"""Does the filter filter? The book's protocol options (basis transition, memory dims, log r),
the mechanism diagnostics and the true-physics references, on small cases with known answers."""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from drfkit.data.noise import Noise
from drfkit.methods import diagnostics, references
from drfkit.data import pendulum as pend
from drfkit.core.filter import kalman_predict, kalman_update
from drfkit.models import build_model, default_config
from drfkit.models.basis import BasisTransition
from drfkit.models.parts import LOG_R_RANGE
from drfkit.models.drf import MEMORY_VARIANCE

torch.set_num_threads(1)

BOOK = {"transition_kind": "basis", "memory_dims": 5, "noise_head": "log"}


def images(b=3, t=8, seed=0):
    return torch.randint(0, 256, (b, t, 24, 24), dtype=torch.uint8, generator=torch.Generator().manual_seed(seed))


# ----------------------------------------------------------------------------- model options
def test_paper_configs_are_unchanged_so_committed_checkpoint_names_hold():
    for kind in ("drf", "no_dynamics", "lstm"):
        cfg = default_config(kind, "pendulum", 2)
        assert not {"noise_head", "transition_kind", "n_basis", "memory_dims"} & set(cfg)
    cfg = default_config("drf", "pendulum", 2, **BOOK)
    assert cfg["transition_kind"] == "basis" and cfg["memory_dims"] == 5 and cfg["noise_head"] == "log"
    assert build_model(cfg).config == cfg


@pytest.mark.parametrize("bad", [{"transition_kind": "gru"}, {"memory_dims": 30}, {"memory_dims": -1},
                                 {"noise_head": "softplus"}, {"n_basis": 0, "transition_kind": "basis"}])
def test_bad_protocol_options_are_named(bad):
    with pytest.raises(ValueError, match=next(iter(bad)) if "n_basis" not in bad else "n_basis"):
        build_model(default_config("drf", "pendulum", 2) | bad)


def test_log_noise_head_spans_its_range_and_starts_at_one():
    torch.manual_seed(0)
    model = build_model(default_config("no_dynamics", "pendulum", 2, noise_head="log"))
    heads = model.heads
    with torch.no_grad():
        heads.linear2.weight.zero_(), heads.linear2.bias.zero_()
        _, r = heads(torch.randn(4, 64))
        assert torch.allclose(r, torch.ones_like(r))
        heads.linear2.bias.fill_(50.0)
        _, r = heads(torch.randn(4, 64))
        assert torch.allclose(r, torch.full_like(r, math.exp(LOG_R_RANGE[1])), rtol=1e-4)


def test_basis_transition_has_no_memory_and_starts_near_identity():
    torch.manual_seed(0)
    tr = BasisTransition(latent=6, hidden=8, n_basis=4)
    z = torch.randn(5, 6)
    F1, q1, state = tr(z, tr.initial_state(5, z))
    F2, _, _ = tr(z, state)
    assert state == () and torch.equal(F1, F2)   # F depends on z alone
    assert (F1 - torch.eye(6)).abs().max() < 0.1
    assert torch.allclose(q1, torch.full_like(q1, 0.1))
    with pytest.raises(ValueError, match="z must have shape"):
        tr(torch.randn(5, 7), ())


def test_memory_dims_are_unobserved_and_coast():
    torch.manual_seed(0)
    model = build_model(default_config("drf", "pendulum", 2, **BOOK)).eval()
    w, r = model.observe(images())
    assert torch.equal(w[..., -5:], torch.zeros_like(w[..., -5:]))
    assert torch.equal(r[:, 0, -5:], torch.ones_like(r[:, 0, -5:]))
    assert torch.equal(r[:, 1:, -5:], torch.full_like(r[:, 1:, -5:], MEMORY_VARIANCE))
    # F = I: a memory dim's mean keeps its value through every update, up to the ~1e-4 leak
    with torch.no_grad():
        model.transition.basis.copy_(torch.eye(30).expand_as(model.transition.basis))
    w[..., -5:] = 0.0
    z0 = torch.randn(3, 30)
    w2 = w.clone()
    w2[:, 0] = z0
    tr = model.filter_steps(w2, r, return_gains=True)
    gains = tr["gains"].diagonal(dim1=-2, dim2=-1)[:, 1:, -5:]
    assert gains.max() < 1e-3
    assert torch.allclose(tr["z"][:, -1, -5:], z0[:, -5:], rtol=1e-2, atol=1e-3)


def test_basis_drf_trains_and_trace_shapes():
    torch.manual_seed(0)
    model = build_model(default_config("drf", "pendulum", 2, **BOOK))
    x, y = images(), torch.randn(3, 8, 2)
    mean, sigma = model(x)
    model.loss(mean, sigma, y).backward()
    assert model.transition.basis.grad is not None and model.transition.basis.grad.abs().sum() > 0
    w, r = model.observe(x)
    tr = model.filter_steps(w, r, return_gains=True, return_transition=True)
    assert tr["F"].shape == (3, 7, 30, 30) and tr["z_prior"].shape == (3, 7, 30) and tr["gains"].shape == (3, 8, 30, 30)
    expected = (tr["F"][:, 0] @ tr["z"][:, 0].unsqueeze(-1)).squeeze(-1)
    assert torch.allclose(tr["z_prior"][:, 0], expected)


def _innovation_nll(F, Q, R, y):
    """Mean NLL per scalar of observations y (B, T, n) under a linear-Gaussian filter (H = I)."""
    b, steps, n = y.shape
    z, P = y[:, 0], torch.diag_embed(R.expand(b, n))
    total = 0.0
    for t in range(1, steps):
        z_pred, P_pred = kalman_predict(z, P, F.expand(b, n, n), Q.expand(b, n))
        L = torch.linalg.cholesky(P_pred + torch.diag_embed(R.expand(b, n)))
        white = torch.linalg.solve_triangular(L, (y[:, t] - z_pred).unsqueeze(-1), upper=False).squeeze(-1)
        log_det = 2 * torch.log(torch.diagonal(L, dim1=-2, dim2=-1)).sum(-1)
        total = total + (0.5 * white.square().sum(-1) + 0.5 * log_det + 0.5 * n * math.log(2 * math.pi)).mean()
        z, P, _ = kalman_update(z_pred, P_pred, y[:, t], R.expand(b, n))
    return total / ((steps - 1) * n)


@pytest.mark.slow  # trains to convergence: about 9 s
def test_learned_transition_approaches_the_exact_kalman_filter_on_a_linear_system():
    """A rotating 2-D latent system: the learned F, q (one basis matrix) must reach the exact
    filter's NLL and the true rotation, while a filter that ignores the dynamics (F = I) is far worse."""
    g = torch.Generator().manual_seed(0)
    angle = 0.3
    A = torch.tensor([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]], dtype=torch.float64)
    q_true, r_true = torch.full((2,), 0.01, dtype=torch.float64), torch.full((2,), 0.25, dtype=torch.float64)
    x = torch.randn(96, 2, generator=g, dtype=torch.float64) * 2
    xs = []
    for _ in range(20):
        xs.append(x)
        x = x @ A.T + torch.randn(96, 2, generator=g, dtype=torch.float64) * q_true.sqrt()
    y = torch.stack(xs, 1) + torch.randn(96, 20, 2, generator=g, dtype=torch.float64) * r_true.sqrt()
    exact = float(_innovation_nll(A, q_true, r_true, y))
    random_walk = float(_innovation_nll(torch.eye(2, dtype=torch.float64), torch.full((2,), 0.3, dtype=torch.float64),
                                        r_true, y))
    torch.manual_seed(0)
    tr = BasisTransition(latent=2, hidden=4, n_basis=1, q_init=0.05).double()
    opt = torch.optim.Adam(tr.parameters(), lr=0.1)
    for _ in range(150):
        F, q, _ = tr(y[:1, 0], ())
        loss = _innovation_nll(F[0], q[0], r_true, y)
        opt.zero_grad(), loss.backward(), opt.step()
    with torch.no_grad():
        F, q, _ = tr(y[:1, 0], ())
        learned = float(_innovation_nll(F[0], q[0], r_true, y))
    assert random_walk > exact + 0.3
    assert learned < exact + 0.01
    assert (F[0] - A).abs().max() < 0.03


# ----------------------------------------------------------------------------- diagnostics
def test_mechanism_summary_on_a_known_trace():
    noise = np.array([[0.0, 0.0, 0.5, 1.0, 0.0]])
    trace = {"r": np.exp(noise * 3), "gain": np.array([[1.0, 0.8, 0.3, 0.1, 0.8]]),
             "prior_err": np.array([[1.0, 2.0, 2.0, 1.0]]), "static_err": np.array([[2.0, 4.0, 4.0, 4.0]]),
             "spectral_radius": np.array([1.0, 1.0, 3.0])}
    s = diagnostics.mechanism_summary(trace, noise)
    assert s["r_noise_spearman"] == pytest.approx(1.0)
    assert s["gain_clean"] == pytest.approx(0.8) and s["gain_pure"] == pytest.approx(0.1)
    assert s["gain_noisy"] == pytest.approx(0.2) and s["gain_ratio"] == pytest.approx(0.125)
    assert s["prior_ratio"] == pytest.approx((1.0 + 1.0) / (2.0 + 4.0))   # clean next frames: t = 1 and 4
    assert s["spectral_radius_median"] == 1.0
    with pytest.raises(ValueError, match="one level per frame"):
        diagnostics.mechanism_summary(trace, noise[:, :3])


def test_filter_trace_of_an_identity_filter_has_unit_spectral_radius():
    torch.manual_seed(0)
    model = build_model(default_config("drf", "pendulum", 2, transition_kind="basis"))
    with torch.no_grad():
        model.transition.basis.copy_(torch.eye(30).expand_as(model.transition.basis))
    trace = diagnostics.filter_trace(model, images(b=4, t=6), batch_size=3)
    assert trace["r"].shape == trace["gain"].shape == (4, 6) and trace["mean"].shape == (4, 6, 2)
    assert np.allclose(trace["spectral_radius"], 1.0, atol=1e-5)
    assert np.allclose(trace["prior_err"], trace["static_err"], atol=1e-5)   # F = I predicts "no change"
    assert model.training  # mode restored
    base = diagnostics.filter_trace(build_model(default_config("lstm", "pendulum", 2)), images(b=2, t=5))
    assert set(base) == {"r", "mean"}


def test_blackout_summary_and_per_frame_error():
    per_frame = diagnostics.abs_error_per_frame(np.zeros((2, 6, 2)), np.ones((2, 6, 2)) * np.arange(6)[None, :, None])
    assert np.allclose(per_frame, np.arange(6))
    s = diagnostics.blackout_summary(per_frame, (2, 4), after=2)
    assert s == {"mae_blackout": 2.5, "mae_after_blackout": 4.5}
    with pytest.raises(ValueError, match="inside"):
        diagnostics.blackout_summary(per_frame, (4, 9))


def test_recovery_summary_on_a_known_curve():
    """Before the gap 0.1; the gap [4, 6) at 1.0; then 0.5, 0.2, 0.14, 0.1: back within 1.5 x 0.1 at the third
    frame after the gap (index 2), after / before = mean(0.5, 0.2, 0.14, 0.1) / 0.1."""
    per_frame = np.array([0.1, 0.1, 0.1, 0.1, 1.0, 1.0, 0.5, 0.2, 0.14, 0.1])
    s = diagnostics.recovery_summary(per_frame, (4, 6), after=4)
    assert s["mae_before_blackout"] == pytest.approx(0.1)
    assert s["recovery_ratio"] == pytest.approx(0.235 / 0.1)
    assert s["frames_to_recover"] == 2.0
    never = diagnostics.recovery_summary(np.r_[per_frame[:6], [0.5, 0.4, 0.3, 0.2]], (4, 6), after=4)
    assert np.isnan(never["frames_to_recover"])
    with pytest.raises(ValueError, match="one after it"):
        diagnostics.recovery_summary(per_frame, (4, 10))


def test_blackouts_replace_only_their_frames_with_pure_noise():
    arrays = pend.generate_pendulum(4, 20, Noise("rkn_uniform", 0.0), seed=3)
    dark = pend.with_blackout(arrays, 5, 9, seed=0)
    assert np.array_equal(dark["images"][:, :5], arrays["images"][:, :5])
    assert np.array_equal(dark["images"][:, 9:], arrays["images"][:, 9:])
    assert (dark["noise"][:, 5:9] == 1.0).all() and (dark["noise"][:, 9:] == 0.0).all()
    assert abs(dark["images"][:, 5:9].mean() - 127.5) < 5   # uniform noise, the rod gone
    assert arrays["noise"].max() == 0.0  # the input is not modified
    rand = pend.with_random_blackouts(arrays, 1.0, (3, 3), seed=1)
    assert ((rand["noise"] == 1.0).sum(axis=1) == 3).all()
    assert (rand["noise"][:, :5] == 0.0).all()
    with pytest.raises(ValueError, match="inside"):
        pend.with_blackout(arrays, 15, 25, seed=0)


# ----------------------------------------------------------------------------- references
def test_rk4_propagation_matches_the_generator():
    th0 = np.linspace(-3.0, 3.0, 13)
    theta, vel = pend._simulate(th0, 3, None, transition_noise_std=0.0)
    t1, v1 = references.pendulum_propagate(theta[:, 0], vel[:, 0])
    t2, v2 = references.pendulum_propagate(t1, v1)
    assert np.abs(np.angle(np.exp(1j * (t2 - theta[:, 2])))).max() < 1e-3
    assert np.abs(v2 - vel[:, 2]).max() < 1e-2


def test_particle_filter_recovers_a_known_trajectory():
    rng = np.random.default_rng(0)
    theta, _ = pend._simulate(rng.uniform(-np.pi, np.pi, 20), 40, np.random.default_rng(1))
    truth = np.stack([np.cos(theta), np.sin(theta)], -1)
    sigma = np.full(truth.shape, 0.3)
    obs = truth + rng.normal(0.0, 0.3, truth.shape)
    est = references.pendulum_particle_filter(obs, sigma, n_particles=400, seed=0)
    assert np.abs(est - truth)[:, 10:].mean() < 0.3 * np.abs(obs - truth)[:, 10:].mean()
    # pure-noise observations in the middle (huge sigma): the physics carries the state
    sigma[:, 20:30] = 1e3
    obs[:, 20:30] = rng.uniform(-1, 1, obs[:, 20:30].shape)
    est = references.pendulum_particle_filter(obs, sigma, n_particles=400, seed=0)
    assert np.abs(est - truth)[:, 20:30].mean() < 0.15
    with pytest.raises(ValueError, match=r"\(N, T, 2\)"):
        references.pendulum_particle_filter(obs[..., :1], sigma[..., :1])


def test_the_references_calibration_grid_widens_until_its_choice_is_interior():
    # the sigmas a model reports are 6x too small: the best scale lies beyond the starting grid (0.5 - 2)
    rng = np.random.default_rng(0)
    theta, _ = pend._simulate(rng.uniform(-np.pi, np.pi, 12), 30, np.random.default_rng(1))
    truth = np.stack([np.cos(theta), np.sin(theta)], -1)
    obs = truth + rng.normal(0.0, 0.3, truth.shape)
    cal = references.calibrate_particle_filter(obs, np.full(truth.shape, 0.05), truth, n_particles=100, seed=0)
    assert cal["sigma_scale"] >= 4.0 and cal["interior"]
    # with no room to widen, a choice at the grid's edge says so
    edge = references.calibrate_particle_filter(obs, np.full(truth.shape, 0.05), truth, n_particles=100, seed=0,
                                            max_widen=0)
    assert edge["sigma_scale"] == 2.0 and not edge["interior"]


def test_the_references_outlier_grid_ends_at_zero_a_bound_not_an_edge():
    # Gaussian observations whose sigma is right: the smallest outlier weight wins, so the grid steps down from
    # 3e-4 to 0 (no outlier term), a bound of the weight's range, and the choice counts as interior there
    rng = np.random.default_rng(0)
    theta, _ = pend._simulate(rng.uniform(-np.pi, np.pi, 12), 30, np.random.default_rng(1))
    truth = np.stack([np.cos(theta), np.sin(theta)], -1)
    obs = truth + rng.normal(0.0, 0.1, truth.shape)
    sigma = np.full(truth.shape, 0.1)
    cal = references.calibrate_particle_filter(obs, sigma, truth, n_particles=100, seed=0, outliers=(3e-4, 1e-3))
    assert cal["outlier"] == 0.0 and cal["interior"]
    edge = references.calibrate_particle_filter(obs, sigma, truth, n_particles=100, seed=0, outliers=(3e-4, 1e-3),
                                                max_widen=0)
    assert edge["outlier"] == 3e-4 and not edge["interior"]


def test_template_matching_reads_clean_and_noisy_frames():
    theta = np.array([[-2.0, -0.5, 0.3, 1.7, 3.0]])
    clean = pend.render_pendulum(theta)
    est = references.template_angles(clean, n_angles=1024)
    # the benchmark's rod is drawn hard-edged on the 128-px canvas, so nearby angles can give the
    # same frame: the match is exact up to that plateau (under a degree), not up to the grid step
    assert np.abs(np.angle(np.exp(1j * (est - theta)))).max() < 0.015
    noisy = pend.blend_uniform_noise(clean, np.full(theta.shape, 0.5), np.random.default_rng(0))
    est = references.template_angles(noisy, n_angles=1024)
    assert np.abs(np.angle(np.exp(1j * (est - theta)))).max() < 0.1


def test_template_matching_on_the_distinct_images_names_the_angle_a_search_over_every_template_names():
    """The renderer draws one image per arc, so template_angles scores each distinct image once: the angle it names
    is the first of the best over all n_angles templates, as a search over every one of them names it."""
    d = pend.generate_pendulum(4, 20, Noise("rkn_uniform", 0.6), 9)
    frames = np.concatenate([d["images"], d["clean"]]).reshape(-1, 576).astype(np.float32)
    angles = -np.pi + 2.0 * np.pi * np.arange(512) / 512
    every = pend.render_pendulum(angles).reshape(512, -1).astype(np.float32)
    every -= every.mean(axis=1, keepdims=True)
    every /= np.linalg.norm(every, axis=1, keepdims=True)
    brute = angles[np.argmax((frames - frames.mean(1, keepdims=True)) @ every.T, axis=1)]
    est = references.template_angles(np.concatenate([d["images"], d["clean"]]), n_angles=512).reshape(-1)
    assert np.array_equal(est, brute)


def test_constant_velocity_filter():
    n, steps, dt = 200, 30, 0.5
    rng = np.random.default_rng(0)
    x = 20 + np.cumsum(np.full((n, steps), 1.5 * dt), axis=1)                 # 1.5 m/s, exactly
    obs = x + rng.normal(0, 1.0, x.shape)
    est = references.constant_velocity_filter(obs, np.ones_like(obs), dt=dt, accel_std=0.01)
    assert np.abs(est - x)[:, 10:].mean() < 0.5 * np.abs(obs - x)[:, 10:].mean()
    exact = references.constant_velocity_filter(obs, np.full_like(obs, 1e-6), dt=dt, accel_std=1.0)
    assert np.allclose(exact, obs, atol=1e-4)
    # frames without an observation: the state moves on with its velocity
    seen = np.ones(obs.shape, bool)
    seen[:, 20:25] = False
    gap = references.constant_velocity_filter(obs, np.ones_like(obs), seen, dt=np.full((n, steps - 1), dt),
                                              accel_std=0.01)
    assert np.allclose(np.diff(gap[:, 19:25], axis=1), np.diff(gap[:, 19:21], axis=1), atol=1e-9)
    assert np.abs(gap - x)[:, 20:25].mean() < 0.7 * np.abs(obs - x)[:, 20:25].mean()
    with pytest.raises(ValueError, match="observed"):
        references.constant_velocity_filter(obs, np.ones_like(obs), seen[:, :5], dt=dt, accel_std=1.0)
    seen[:, 0] = False
    with pytest.raises(ValueError, match="first frame"):
        references.constant_velocity_filter(obs, np.ones_like(obs), seen, dt=dt, accel_std=1.0)


def test_mechanism_checks_take_a_noise_value_or_its_level(monkeypatch):
    from drfkit.study import dynamics, studies
    from drfkit.study.params import for_notebook, load_profile

    P = for_notebook("02_pendulum_dynamics", load_profile("quick"))
    asked = []
    monkeypatch.setattr(studies, "pendulum_split", lambda P, split, noise=None: asked.append((split, noise)) or {})
    monkeypatch.setattr(dynamics, "blackout_split", lambda P, split: {})
    for noise in (Noise("rkn_uniform", 0.75), 0.75):
        assert dynamics.mechanism_table(P, {}, noise, "val").empty
    assert asked == [("val", 0.75), ("val", 0.75)]
    with pytest.raises(ValueError, match="rkn_uniform"):  # the pedestrians' kind is not the pendulum's
        dynamics.mechanism_table(P, {}, Noise("salt_and_pepper", 0.05))


def test_the_reference_and_the_models_are_averaged_over_the_same_blackout_frames():
    """Like for like: the true-physics reference's blackout MAE is taken over the blackout frames alone,
    as every model's (``blackout_table``); a reference averaged over all 75 frames fails this."""
    from drfkit.data.noise import Noise
    from drfkit.data.pendulum import blackout_frames, generate_pendulum, with_blackout
    from drfkit.study.dynamics import blackout_table, reference_on

    val = generate_pendulum(4, 60, Noise("rkn_uniform", 0.5), seed=5)
    dark = with_blackout(generate_pendulum(3, 60, Noise("rkn_uniform", 0.5), seed=6), *blackout_frames(60), seed=1)
    rng = np.random.default_rng(0)

    def predict(arrays):  # a per-frame encoder: the truth plus noise, useless on pure-noise frames
        noisy = arrays["targets"] + rng.normal(0, 0.05, arrays["targets"].shape) * (1 + 20 * arrays["noise"][..., None])
        return noisy.astype(np.float32), np.full(arrays["targets"].shape, 0.1, np.float32)

    table, curves = reference_on(predict, val, {"blackout": dark}, n_particles=50, seed=0)
    reference = table.set_index("noise").loc["blackout"]
    as_model = blackout_table(curves.assign(seed=0))
    assert reference["mae"] == pytest.approx(float(as_model["mae_blackout"].iloc[0]), rel=1e-12)
    assert reference["mae"] != pytest.approx(reference["mae_all_frames"], rel=1e-3)  # the frames do matter here


def test_encoder_accuracy_check_draws_the_asked_accuracy_and_filters_it():
    """The drawn per-frame errors have the asked MAE (E|e| = s sqrt(2/pi)); the true-physics filter
    on them does better than the encoder; a more accurate encoder gives a better filter."""
    from drfkit.study.dynamics import encoder_accuracy_check

    rng = np.random.default_rng(0)
    theta, _ = pend._simulate(rng.uniform(-np.pi, np.pi, 8), 30, rng)
    targets = np.stack([np.cos(theta), np.sin(theta)], axis=-1)
    table = encoder_accuracy_check(targets, {"coarse": 0.1, "fine": 0.02}, n_particles=200, seed=0).set_index("name")
    assert table.loc["coarse", "encoder_mae_drawn"] == pytest.approx(0.1, rel=0.05)
    assert table.loc["fine", "sigma"] == pytest.approx(0.02 * math.sqrt(math.pi / 2))
    assert (table["filtered_mae"] < table["encoder_mae_drawn"]).all()
    assert table.loc["fine", "filtered_mae"] < table.loc["coarse", "filtered_mae"]


def test_the_quantisation_effect_scores_each_storage_with_each_likelihood_and_every_model(monkeypatch):
    """Rounded and truncated frames of the same draws, each scored by the limit with both likelihoods, and every model
    by its dropout-off pass on both."""
    from drfkit.data.pendulum import generate_pendulum
    from drfkit.study import dynamics, studies
    from drfkit.study.params import for_notebook, load_profile

    P = for_notebook("02_pendulum_dynamics", load_profile("quick"))
    asked = []

    def split(P, name, noise=None):
        asked.append((name, noise))
        return generate_pendulum(3, 12, noise, 17)

    monkeypatch.setattr(studies, "pendulum_split", split)
    torch.manual_seed(0)
    model = build_model(default_config("no_dynamics", "pendulum", 2)).train()
    table = dynamics.quantisation_effect(P, {("no_dynamics", 0): model}, [0.75], n_sequences=2, n_particles=200)
    assert asked == [("test", Noise("rkn_uniform", 0.75)), ("test", Noise("rkn_uniform_truncated", 0.75))]
    assert model.training   # its mode restored
    limit = table[table["estimator"] == "per_frame_bayes"].set_index(["frames", "likelihood"])["mae"]
    assert len(limit) == 4 and (limit > 0).all()
    for stored in ("round", "truncate"):       # each likelihood reads the frames differently (the MAE of 24 frames
        assert limit[(stored, "round")] != limit[(stored, "truncate")]   # cannot rank them: the measurement does)
    learned = table[table["estimator"] == "no_dynamics"]
    assert sorted(learned["frames"]) == ["round", "truncate"] and learned["likelihood"].isna().all()
    assert learned["mae"].nunique() == 2        # the frames differ, so does the output


def test_the_limit_on_pixels_keys_alike_in_notebooks_02_and_04():
    """Both notebooks call the cached limit on pixels; with the profile narrowed to what it reads, the second call's
    key is the first one's (a key of each notebook's whole parameter set missed it and computed it again), and a
    narrowed profile refuses a read of anything else rather than key a result on too little."""
    from drfkit.book.measurements import key
    from drfkit.study import dynamics
    from drfkit.study.params import for_notebook, load_profile
    from drfkit.study.schema import ParameterError

    keys, whole = set(), set()
    for notebook in ("02_pendulum_dynamics", "04_ood_noise_evaluation"):
        P = for_notebook(notebook, load_profile("paper"))
        keys.add(key(dynamics.pixel_limit, (dynamics.limit_profile(P), [0.5]), {}, with_machine=False))
        whole.add(key(dynamics.pixel_limit, (P, [0.5]), {}, with_machine=False))
    assert len(keys) == 1 and len(whole) == 2
    narrowed = dynamics.limit_profile(for_notebook("02_pendulum_dynamics", load_profile("paper")))
    assert narrowed.pendulum.test_seed == load_profile("paper")["pend_test_seed"]
    with pytest.raises(ParameterError, match="the limit on pixels.*pend_models"):
        narrowed.pendulum.models
    with pytest.raises(ParameterError, match="does not declare"):
        dynamics.limit_profile(for_notebook("03_nuscenes_training", load_profile("paper")))
