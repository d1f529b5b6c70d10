"""The known-dynamics filter: an EKF with the pendulum's true equations on the DRF family's encoder."""
import numpy as np
import pytest
import torch

from drfkit.core.filter import ekf_update, kalman_update
from drfkit.data import pendulum as pend
from drfkit.methods.objectives import batch_loss
from drfkit.methods.references import pendulum_propagate
from drfkit.models import build_model
from drfkit.models.known_dynamics import pendulum_step


def test_ekf_update_with_identity_observation_is_the_kalman_update():
    g = torch.Generator().manual_seed(0)
    z, w = torch.randn(5, 3, generator=g, dtype=torch.float64), torch.randn(5, 3, generator=g, dtype=torch.float64)
    A = torch.randn(5, 3, 3, generator=g, dtype=torch.float64)
    P = A @ A.mT + 0.1 * torch.eye(3, dtype=torch.float64)
    R = torch.rand(5, 3, generator=g, dtype=torch.float64) + 0.05
    H = torch.eye(3, dtype=torch.float64).expand(5, 3, 3)
    z1, P1, K1 = ekf_update(z, P, w - z, H, R)
    z2, P2, K2 = kalman_update(z, P, w, R)
    assert torch.allclose(z1, z2) and torch.allclose(P1, P2) and torch.allclose(K1, K2)
    with pytest.raises(ValueError, match="H must be"):
        ekf_update(z, P, w - z, torch.eye(2, 3, dtype=torch.float64).expand(5, 2, 3), R)


def test_pendulum_step_is_the_true_physics_with_its_jacobian():
    theta = torch.linspace(-3.0, 3.0, 13, dtype=torch.float64)
    omega = torch.linspace(-4.0, 4.0, 13, dtype=torch.float64)
    th1, om1, F = pendulum_step(theta, omega)
    ref_th, ref_om = pendulum_propagate(theta.numpy(), omega.numpy())
    assert np.abs(th1.numpy() - ref_th).max() < 1e-6 and np.abs(om1.numpy() - ref_om).max() < 1e-5
    eps = 1e-6
    for col, (dt, do) in enumerate(((eps, 0.0), (0.0, eps))):
        a, b, _ = pendulum_step(theta + dt, omega + do)
        c, d, _ = pendulum_step(theta - dt, omega - do)
        fd = torch.stack([(a - c) / (2 * eps), (b - d) / (2 * eps)], -1)
        assert torch.allclose(F[..., :, col], fd, atol=1e-6)
    # and the generator's own integration over a frame
    sim_th, _ = pend._simulate(theta.numpy()[:6], 2, None, transition_noise_std=0.0)
    th_still, _, _ = pendulum_step(theta[:6], torch.zeros(6, dtype=torch.float64))
    assert np.abs(np.angle(np.exp(1j * (th_still.numpy() - sim_th[:, 1])))).max() < 2e-4


def _truth(n=8, steps=60, seed=0):
    rng = np.random.default_rng(seed)
    theta, _ = pend._simulate(rng.uniform(-np.pi, np.pi, n), steps, rng)
    return torch.from_numpy(np.stack([np.cos(theta), np.sin(theta)], -1)).float()


def test_filter_beats_its_observations_and_coasts_when_they_vanish():
    model = build_model({"kind": "known_dynamics", "input_kind": "pendulum", "out_dim": 2}).eval()
    target = _truth()
    sigma = 0.05
    w = target + sigma * torch.randn(target.shape, generator=torch.Generator().manual_seed(1))
    r = torch.full_like(w, sigma ** 2)
    r[:, 30:45], w[:, 30:45] = 1e6, 0.0   # a blackout: observations that carry nothing
    with torch.no_grad():
        tr = model.filter_steps(w, r)
        mean, sigma_out = model.head(model.belief(tr["x"], tr["p"]))
    err = (mean - target).abs()
    assert err[:, 10:30].mean() < 0.5 * (w - target).abs()[:, 10:30].mean()
    assert err[:, 30:45].mean() < 0.15                          # the true physics carries the state
    assert sigma_out[:, 40].mean() > 2 * sigma_out[:, 25].mean()  # and knows it is less sure


def test_streaming_equals_whole_sequences_and_config_round_trip():
    torch.manual_seed(0)
    model = build_model({"kind": "known_dynamics", "input_kind": "pendulum", "out_dim": 2}).eval()
    again = build_model(model.config)
    again.load_state_dict(model.state_dict())
    x = torch.randint(0, 255, (2, 6, 24, 24), dtype=torch.uint8)
    with torch.no_grad():
        h, gains = model.features(x, return_gains=True)
        assert torch.equal(h, again.features(x)[0]) and gains.shape == (2, 6, 2, 2)
        carry, steps = model.initial_carry(x[:, :1]), []
        for t in range(1, 6):
            out, carry = model.stream_step(x[:, t:t + 1], carry)
            steps.append(out)
    assert torch.allclose(torch.cat(steps, 1), h[:, 1:], atol=1e-3)
    mean, sigma = model.head(h, n_samples=4)
    assert mean.shape == (4, 2, 6, 2) and torch.equal(mean[0], mean[3])   # no dropout: no epistemic spread


def test_observation_loss_reaches_r_and_is_refused_where_there_is_none():
    torch.manual_seed(0)
    x = torch.randint(0, 255, (3, 5, 24, 24), dtype=torch.uint8)
    y = _truth(3, 5)
    for config in ({"kind": "known_dynamics"}, {"kind": "drf", "decoder_split": True}):
        model = build_model({"input_kind": "pendulum", "out_dim": 2, **config})
        without = batch_loss(model, "beta_nll", 1.0, x, y)
        model.zero_grad()
        with_obs = batch_loss(model, "beta_nll", 1.0, x, y, obs_weight=1.0)
        assert not torch.isclose(without, with_obs)
        with_obs.backward()
        noise_head = model.obs_log_r if config["kind"] == "known_dynamics" else model.heads.linear2
        assert noise_head.weight.grad.abs().sum() > 0
    lstm = build_model({"kind": "lstm", "input_kind": "pendulum", "out_dim": 2})
    with pytest.raises(ValueError, match="obs_weight"):
        batch_loss(lstm, "beta_nll", 1.0, x, y, obs_weight=1.0)


def test_quality_head_raises_every_r_together():
    from drfkit.models.parts import ObservationHeads
    head = ObservationHeads(8, latent=4, noise_head="quality")
    with torch.no_grad():
        head.quality_slope.fill_(1.0)
        head.linear2.weight.zero_()
        head.linear2.bias.fill_(-2.0)
        _, low = head(torch.zeros(1, 8))
        head.linear2.bias.fill_(2.0)
        _, high = head(torch.zeros(1, 8))
    assert torch.all(high > low)


def test_learned_transition_carries_its_jacobian_and_the_pull_drives_it_to_the_true_one():
    from drfkit.models.known_dynamics import LearnedTransition

    torch.manual_seed(0)
    step = LearnedTransition(16).double()
    torch.nn.init.normal_(step.outer.weight, std=0.3)   # away from its zero start, so the Jacobian is not I
    theta = torch.linspace(-3.0, 3.0, 9, dtype=torch.float64)
    omega = torch.linspace(-8.0, 8.0, 9, dtype=torch.float64)
    _, _, F = step(theta, omega)
    eps = 1e-6
    for col, (dt, do) in enumerate(((eps, 0.0), (0.0, eps))):
        a, b, _ = step(theta + dt, omega + do)
        c, d, _ = step(theta - dt, omega - do)
        assert torch.allclose(F[..., :, col], torch.stack([(a - c) / (2 * eps), (b - d) / (2 * eps)], -1), atol=1e-7)
    # started at zero the learned transition is a random walk; the pull alone drives it toward the pendulum
    model = build_model({"kind": "known_dynamics", "input_kind": "pendulum", "out_dim": 2, "transition": "learned",
                         "pull": 100.0})
    assert build_model(model.config).transition == "learned"                 # the config carries it
    x, y = torch.randint(0, 255, (2, 4, 24, 24), dtype=torch.uint8), _truth(2, 4)
    pulled = batch_loss(model, "beta_nll", 1.0, x, y)
    model.pull = 0.0
    free = batch_loss(model, "beta_nll", 1.0, x, y)
    model.pull = 100.0
    assert torch.isclose(pulled - free, model.regulariser())                  # the training loss carries the pull
    start = float(model.regulariser().detach())
    opt = torch.optim.Adam(model.learned.parameters(), lr=1e-2)
    for _ in range(300):
        opt.zero_grad()
        loss = model.regulariser()
        loss.backward()
        opt.step()
    assert float(model.regulariser().detach()) < 0.1 * start
    # the true transition has none, and a pull without a learned transition is refused early
    plain = build_model({"kind": "known_dynamics", "input_kind": "pendulum", "out_dim": 2})
    assert plain.regulariser() == 0.0 and "transition" not in plain.config
    with pytest.raises(ValueError, match="pull"):
        build_model({"kind": "known_dynamics", "input_kind": "pendulum", "out_dim": 2, "pull": 1.0})
