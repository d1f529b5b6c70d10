"""Training objectives and schedules (drfkit.methods.objectives, drfkit.methods.train) on small known cases."""
import math

import numpy as np
import pytest
import torch

from drfkit.data.noise import Noise
from drfkit.data.pendulum import generate_pendulum, redraw_noise
from drfkit.util.io import torch_load_checked
from drfkit.models import gaussian_nll
from drfkit.methods.objectives import beta_nll, mse, objective_loss, random_windows
from drfkit.study.studies import model_config
from drfkit.methods.train import SequenceData, TrainConfig, fingerprint, train_model


pytestmark = pytest.mark.usefixtures("one_thread")  # tests/conftest.py


def values(seed=0, shape=(3, 4, 2)):
    g = torch.Generator().manual_seed(seed)
    mean = torch.randn(shape, generator=g, requires_grad=True)
    sigma = (0.05 + torch.rand(shape, generator=g)).requires_grad_(True)
    targets = torch.randn(shape, generator=g)
    mask = torch.rand(shape[:2], generator=g) > 0.3
    mask[0, 0] = True
    return mean, sigma, targets, mask


def test_beta_zero_is_the_nll():
    mean, sigma, targets, mask = values()
    torch.testing.assert_close(beta_nll(mean, sigma, targets, mask, beta=0.0), gaussian_nll(mean, sigma, targets, mask))


def test_beta_one_gives_the_mean_the_gradient_of_half_squared_error():
    """d/dmu [stopgrad(sigma^2) * (y - mu)^2 / (2 sigma^2)] = mu - y, whatever sigma is: the mean is
    fitted like MSE (a mutation that forgets the stop-gradient or uses sigma^beta fails this)."""
    mean, sigma, targets, mask = values(1)
    beta_nll(mean, sigma, targets, mask, beta=1.0).backward()
    n_valid = int(mask.sum()) * mean.shape[-1]
    expected = torch.where(mask.unsqueeze(-1), (mean - targets).detach(), 0.0) / n_valid
    torch.testing.assert_close(mean.grad, expected)
    # sigma still learns: its gradient is the NLL's, scaled by sigma^2
    s = sigma.detach().clone().requires_grad_(True)
    gaussian_nll(mean.detach(), s, targets, mask).backward()
    torch.testing.assert_close(sigma.grad, s.grad * sigma.detach() ** 2)


def test_half_beta_weights_by_sigma():
    mean, sigma, targets, mask = values(2)
    beta_nll(mean, sigma, targets, mask, beta=0.5).backward()
    n_valid = int(mask.sum()) * mean.shape[-1]
    expected = torch.where(mask.unsqueeze(-1), (mean - targets) / sigma, 0.0).detach() / n_valid
    torch.testing.assert_close(mean.grad, expected)


def test_mse_fits_only_the_mean():
    mean, sigma, targets, mask = values(3)
    loss = mse(mean, sigma, targets, mask)
    valid = mask.unsqueeze(-1).expand_as(mean)
    assert loss.item() == pytest.approx((0.5 * (targets - mean) ** 2)[valid].mean().item(), rel=1e-6)
    loss.backward()
    assert sigma.grad is None


def test_bad_objectives_are_refused():
    mean, sigma, targets, mask = values()
    with pytest.raises(ValueError, match="beta"):
        beta_nll(mean, sigma, targets, mask, beta=1.5)
    with pytest.raises(ValueError, match="objective"):
        objective_loss(None, "hinge", 1.0, mean, sigma, targets, mask)
    for bad in (dict(objective="hinge"), dict(beta=-0.1), dict(mse_warmup=-1), dict(lr_schedule="linear"),
                dict(weight_decay=-1.0), dict(window=1)):
        with pytest.raises(ValueError, match="TrainConfig"):
            TrainConfig(epochs=1, lr=1e-3, batch_size=1, seed=0, **bad)


def test_random_windows_cut_consecutive_frames_per_sequence():
    x = torch.arange(4 * 10).reshape(4, 10, 1, 1).expand(4, 10, 2, 2)
    y = torch.arange(4 * 10, dtype=torch.float32).reshape(4, 10, 1)
    xw, yw, mw = random_windows(x, y, None, 3, torch.Generator().manual_seed(0))
    assert xw.shape == (4, 3, 2, 2) and yw.shape == (4, 3, 1) and mw is None
    steps = yw[:, 1:, 0] - yw[:, :-1, 0]
    assert torch.equal(steps, torch.ones_like(steps))  # consecutive
    assert torch.equal(yw[:, 0, 0] // 10, torch.arange(4, dtype=torch.float32))  # each from its own sequence
    assert torch.equal(xw[:, :, 0, 0].float(), yw[..., 0])


def test_cosine_schedule_reaches_zero_and_its_epochs_enter_the_fingerprint():
    cfg = TrainConfig(epochs=4, lr=1e-2, batch_size=4, seed=0, lr_schedule="cosine")
    longer = TrainConfig(epochs=8, lr=1e-2, batch_size=4, seed=0, lr_schedule="cosine")
    assert fingerprint({}, cfg, "d") != fingerprint({}, longer, "d")
    step = TrainConfig(epochs=4, lr=1e-2, batch_size=4, seed=0)
    assert fingerprint({}, step, "d") == fingerprint({}, TrainConfig(epochs=8, lr=1e-2, batch_size=4, seed=0), "d")


def _fresh_setup():
    arrays = generate_pendulum(8, 12, Noise("rkn_uniform", 0.5), seed=3)
    val = generate_pendulum(4, 12, Noise("rkn_uniform", 0.5), seed=4)

    def as_data(a):
        return SequenceData(torch.from_numpy(a["images"]), torch.from_numpy(a["targets"]))

    def fresh(epoch):
        return as_data(redraw_noise(arrays, Noise("rkn_uniform", 0.5), 100 + epoch,
                                    {"fraction": 0.5, "lengths": (2, 4)}))

    return as_data(arrays), as_data(val), fresh


def test_fresh_noise_resumed_run_equals_uninterrupted_bit_for_bit(tmp_path):
    train, val, fresh = _fresh_setup()
    cfg = model_config("pendulum", "drf")
    tc = TrainConfig(epochs=4, lr=3e-3, batch_size=4, seed=0, objective="beta_nll", lr_schedule="cosine",
                     window=6, mse_warmup=1, select_on="l1", weight_decay=1e-4)
    a = train_model(cfg, train, val, tc, tmp_path / "a", progress=False, fresh_train=fresh)
    b1 = train_model(cfg, train, val, tc, tmp_path / "b", progress=False, fresh_train=fresh, stop_after_epochs=2)
    assert len(b1.history) == 2
    b2 = train_model(cfg, train, val, tc, tmp_path / "b", progress=False, fresh_train=fresh)
    assert b2.resumed_from == 2
    assert [h["train_loss"] for h in a.history] == [h["train_loss"] for h in b2.history]
    sa, sb = torch_load_checked(a.last_path)["model"], torch_load_checked(b2.last_path)["model"]
    assert all(torch.equal(sa[k], sb[k]) for k in sa)
    assert math.isclose(a.history[-1]["lr"], 0.0, abs_tol=1e-12)  # cosine to 0 at the last epoch
    # the noise really is new each epoch, on the same clean frames
    e0, e1 = fresh(0), fresh(1)
    assert not torch.equal(e0.inputs, e1.inputs) and torch.equal(e0.targets, e1.targets)
    assert torch.equal(fresh(0).inputs, e0.inputs)


def test_redraw_noise_keeps_clean_frames_and_targets():
    arrays = generate_pendulum(5, 10, Noise("rkn_uniform", 0.5), seed=1)
    new = redraw_noise(arrays, Noise("rkn_uniform", 0.5), seed=7)
    assert np.array_equal(new["clean"], arrays["clean"]) and np.array_equal(new["targets"], arrays["targets"])
    assert new["noise"].max() <= 0.5 and (new["noise"][:, :5] == 0).all()  # the benchmark's clean first frames
    assert not np.array_equal(new["images"], arrays["images"])
    with pytest.raises(ValueError, match="rkn_uniform"):
        redraw_noise(arrays, Noise("salt_and_pepper", 0.5), seed=7)


# --- filter levers: the one-step prior's loss and a constant Q -------------------------------------

def _drf(**options):
    from drfkit.models import build_model, default_config

    torch.manual_seed(0)
    return build_model(default_config("drf", "pendulum", 2, latent=4, feature_dim=8, decoder_hidden=8,
                                      transition_hidden=8, **options)).eval()


def _frames(b=3, t=6, seed=0):
    g = torch.Generator().manual_seed(seed)
    return torch.randint(0, 256, (b, t, 24, 24), dtype=torch.uint8, generator=g), torch.randn(b, t, 2, generator=g)


@pytest.mark.parametrize("options", [{}, {"constant_q": True}, {"transition_kind": "basis", "memory_dims": 1}])
def test_the_prior_is_the_predict_step_of_the_filter(options):
    """forward_with_prior decodes z_{t|t-1} = F_t z_{t-1} and diag(F_t P_{t-1} F_t^T + Q_t), recomputed
    here with drfkit.core.filter.kalman_predict from the filter's own F_t, q_t and posteriors."""
    from drfkit.core.filter import kalman_predict
    from drfkit.models.parts import mean_and_log_variance

    model = _drf(**options)
    inputs, _ = _frames()
    with torch.no_grad():
        w, r = model.observe(inputs)
        trace = model.filter_steps(w, r, return_transition=True, return_prior=True)
        _, (prior_mean, prior_sigma) = model.forward_with_prior(inputs)
        # P_{t-1} in full: rerun the filter step by step
        from drfkit.core.filter import kalman_step

        z, P = w[:, 0], torch.diag_embed(r[:, 0])
        for t in range(1, inputs.shape[1]):
            z_pred, P_pred = kalman_predict(z, P, trace["F"][:, t - 1], trace["q"][:, t - 1])
            torch.testing.assert_close(trace["z_prior"][:, t - 1], z_pred)
            torch.testing.assert_close(trace["p_prior"][:, t - 1], P_pred.diagonal(dim1=-2, dim2=-1))
            z, P, _ = kalman_step(z, P, trace["F"][:, t - 1], trace["q"][:, t - 1], w[:, t], r[:, t])
        expected = model.head(mean_and_log_variance(trace["z_prior"], trace["p_prior"]))
    torch.testing.assert_close(prior_mean, expected[0])
    torch.testing.assert_close(prior_sigma, expected[1])
    assert prior_mean.shape == (3, 5, 2)


def test_batch_loss_adds_the_weighted_prior_loss():
    from drfkit.methods.objectives import batch_loss

    model = _drf()
    inputs, targets = _frames()
    mask = torch.ones(targets.shape[:2], dtype=torch.bool)
    mask[0, 4:] = False
    with torch.no_grad():
        post = batch_loss(model, "beta_nll", 1.0, inputs, targets, mask, prior_weight=0.0)
        both = batch_loss(model, "beta_nll", 1.0, inputs, targets, mask, prior_weight=0.5)
        (_, _), (pm, ps) = model.forward_with_prior(inputs)
        prior = beta_nll(pm, ps, targets[:, 1:], mask[:, 1:], beta=1.0)
    torch.testing.assert_close(both, post + 0.5 * prior)
    from drfkit.models import build_model, default_config

    lstm = build_model(default_config("lstm", "pendulum", 2, latent=4, feature_dim=8, decoder_hidden=8))
    with pytest.raises(ValueError, match="prior_weight = 0 for it"):
        batch_loss(lstm, "nll", 0.0, inputs, targets, None, prior_weight=1.0)


def test_constant_q_is_learned_and_the_same_at_every_step():
    model = _drf(constant_q=True)
    assert model.config["constant_q"] is True and "constant_q" not in _drf().config  # paper configs unchanged
    inputs, targets = _frames()
    with torch.no_grad():
        q = model.filter_steps(*model.observe(inputs), return_transition=True)["q"]      # (B, T-1, n)
    torch.testing.assert_close(q, model.transition.log_q.exp().expand_as(q))
    model.train()
    mean, sigma = model(inputs)  # the per-step loop (the one-node recursion knows only the q head)
    gaussian_nll(mean, sigma, targets).backward()
    assert model.transition.log_q.grad is not None and model.transition.log_q.grad.abs().sum() > 0
    with pytest.raises(ValueError, match="constant already"):
        _drf(constant_q=True, transition_kind="basis")


def test_prior_weight_is_checked_and_stays_out_of_old_names():
    from drfkit.methods.train import naming_fields

    with pytest.raises(ValueError, match="prior_weight"):
        TrainConfig(epochs=1, lr=1e-3, batch_size=2, seed=0, prior_weight=-1.0)
    assert "prior_weight" not in naming_fields(TrainConfig(epochs=1, lr=1e-3, batch_size=2, seed=0))
    assert naming_fields(TrainConfig(epochs=1, lr=1e-3, batch_size=2, seed=0, prior_weight=1.0))["prior_weight"] == 1.0


def _term_grads(model, **weights):
    """The gradient that one loss term adds, per parameter name: grad(loss with the term) - grad(without it)."""
    from drfkit.methods.objectives import batch_loss

    torch.manual_seed(0)
    x = torch.randint(0, 256, (2, 6, 24, 24), dtype=torch.uint8, generator=torch.Generator().manual_seed(1))
    y = torch.randn(2, 6, 2) * 0.5

    def grads(**w):
        model.zero_grad()
        torch.manual_seed(2)  # the same dropout masks in both passes
        batch_loss(model, "beta_nll", 1.0, x, y, **w).backward()
        return {n: (p.grad.clone() if p.grad is not None else torch.zeros_like(p)) for n, p in model.named_parameters()}
    with_term, without = grads(**weights), grads(**{k: 0.0 for k in weights})
    return {n: (with_term[n] - without[n]).abs().sum().item() for n in with_term}


def test_the_observation_loss_reaches_the_observation_variance_head():
    from drfkit.models import build_model, default_config

    torch.manual_seed(0)
    model = build_model(default_config("drf", "pendulum", 2, latent=4))
    added = _term_grads(model, obs_weight=1.0)
    assert added["heads.linear2.weight"] > 0 and added["heads.linear2.bias"] > 0      # r is trained by it
    assert all(v == 0 for n, v in added.items() if n.startswith("transition."))       # the filter is not read


def test_the_prior_loss_reaches_the_transition():
    from drfkit.models import build_model, default_config

    torch.manual_seed(0)
    model = build_model(default_config("drf", "pendulum", 2, latent=4))
    added = _term_grads(model, prior_weight=1.0)
    assert added["transition.head.weight"] > 0 and added["transition.cell1.weight_ih"] > 0


def test_a_regulariser_reaches_its_own_parameters_only():
    from drfkit.models import build_model, default_config

    torch.manual_seed(0)
    model = build_model(default_config("known_dynamics", "pendulum", 2, transition="learned", learn_q=True, pull=10.0))
    with torch.no_grad():
        model.learned.outer.weight.normal_(0, 0.1)      # away from zero, so that the pull has a gradient
    model.zero_grad()
    model.regulariser().backward()
    reached = {n for n, p in model.named_parameters() if p.grad is not None and p.grad.abs().sum() > 0}
    assert reached and all(n.startswith("learned.") for n in reached)
    assert "learned.outer.weight" in reached


def test_skip_spans_skip_one_span_of_the_asked_lengths_never_the_start_in_the_asked_share():
    from drfkit.methods.objectives import skip_spans

    g = skip_spans(4000, 25, [1, 20], 0.5, torch.Generator().manual_seed(0))
    forced = ~torch.isnan(g)
    assert torch.all(g[forced] == 0) and not forced[:, 0].any()            # gain 0 where forced, never at frame 0
    lengths = forced.sum(1)
    used = lengths > 0
    assert abs(used.float().mean().item() - 0.5) < 0.03                      # half the windows
    assert lengths[used].min() >= 1 and lengths[used].max() <= 20
    starts = forced.float().argmax(1)[used]
    contiguous = (forced[used].float().diff(dim=1).abs().sum(1) <= 2)        # one span: at most one rise and one fall
    assert contiguous.all() and (starts >= 1).all()
    short = skip_spans(10, 6, [1, 20], 1.0, torch.Generator().manual_seed(1))  # spans cut to T - 1
    assert (~torch.isnan(short)).sum(1).max() <= 5 and not (~torch.isnan(short[:, 0])).any()


def test_skipped_updates_need_a_filter_and_reach_the_loss():
    from drfkit.methods.objectives import batch_loss
    from drfkit.models import build_model, default_config

    torch.manual_seed(0)
    x = torch.randint(0, 256, (2, 6, 24, 24), dtype=torch.uint8)
    y = torch.zeros(2, 6, 2)
    gain = torch.full((2, 6), float("nan"))
    gain[:, 2:5] = 0.0
    nd = build_model(default_config("no_dynamics", "pendulum", 2))
    with pytest.raises(ValueError, match="skip_spans"):
        batch_loss(nd, "nll", 1.0, x, y, gain=gain)
    drf = build_model(default_config("drf", "pendulum", 2, latent=4)).eval()
    own, skipped = (batch_loss(drf, "nll", 1.0, x, y, prior_weight=1.0, gain=g) for g in (None, gain))
    assert torch.isfinite(skipped) and not torch.isclose(own, skipped)
    skipped.backward()
    assert any(p.grad is not None and p.grad.abs().sum() > 0 for p in drf.transition.parameters())
