"""Tests for drfkit.models: shapes, the filter's limiting behaviour, gradients, losses,
Monoloco, MC dropout in the decoder, config round trips and input checks."""
from __future__ import annotations

import copy
import math

import pytest
import torch

from drfkit.models import (Decoder, DeepRecursiveFilter, Monoloco, build_model, centre_keypoints,
                           default_config, gaussian_nll, relative_laplace_loss)
from drfkit.models.parts import SIGMA_FLOOR, VARIANCE_FLOOR, keypoint_box_centre

torch.set_num_threads(1)

FAMILY = ["drf", "no_dynamics", "lstm"]
ALL_CASES = [(k, ik) for k in FAMILY for ik in ("pendulum", "keypoints")] + [("monoloco", "keypoints")]


def make(kind: str, input_kind: str, **overrides):
    torch.manual_seed(0)
    return build_model(default_config(kind, input_kind, 2 if input_kind == "pendulum" else 1, **overrides))


def inputs_for(input_kind: str, b: int = 3, t: int = 6, seed: int = 0) -> torch.Tensor:
    g = torch.Generator().manual_seed(seed)
    if input_kind == "pendulum":
        return torch.randint(0, 256, (b, t, 24, 24), dtype=torch.uint8, generator=g)
    kp = torch.randn(b, t, 17, 3, generator=g)
    kp[..., 2] = torch.rand(b, t, 17, generator=g)
    return kp


@pytest.mark.parametrize("kind,input_kind", ALL_CASES)
def test_forward_shapes_and_positive_sigma(kind, input_kind):
    model = make(kind, input_kind).eval()
    x = inputs_for(input_kind)
    mean, sigma = model(x)
    out = 2 if input_kind == "pendulum" else 1
    assert mean.shape == sigma.shape == (3, 6, out)
    assert torch.isfinite(mean).all() and (sigma > 0).all()
    h, gains = model.features(x, return_gains=True)
    assert h.shape[:2] == (3, 6)
    samples_mean, samples_sigma = model.head(h, n_samples=4)
    assert samples_mean.shape == samples_sigma.shape == (4, 3, 6, out)
    if kind == "drf":
        assert gains.shape == (3, 6, 30, 30)
        assert model.kalman_gains(x).shape == (3, 6, 30, 30)
    else:
        assert gains is None and model.kalman_gains(x) is None


def test_drf_without_return_gains_gives_none():
    model = make("drf", "keypoints")
    _, gains = model.features(inputs_for("keypoints"))
    assert gains is None


def test_transition_starts_at_identity():
    model = make("drf", "keypoints")
    z = torch.randn(4, 30)
    F_t, q_t, _ = model.transition(z, model.transition.initial_state(4, z))
    assert torch.equal(F_t, torch.eye(30).expand(4, 30, 30))
    assert (q_t >= VARIANCE_FLOOR).all()


def _freeze_transition(model: DeepRecursiveFilter, q_bias: float) -> float:
    """Make the transition output F = I and a constant q; return that q."""
    with torch.no_grad():
        model.transition.head.weight.zero_()
        model.transition.head.bias.zero_()
        model.transition.head.bias[30 * 30:] = q_bias
    return float(torch.nn.functional.elu(torch.tensor(q_bias, dtype=torch.float64))) + 1 + VARIANCE_FLOOR


def test_filter_matches_scalar_kalman_recursion():
    """With F = I and diagonal Q, R the latent filter splits into n scalar filters."""
    model = make("drf", "keypoints").double()
    q = _freeze_transition(model, q_bias=-0.7)
    g = torch.Generator().manual_seed(1)
    w = torch.randn(2, 8, 30, generator=g, dtype=torch.float64)
    r = torch.rand(2, 8, 30, generator=g, dtype=torch.float64) * 2 + 0.1
    z, p_diag, gains = model.run_filter(w, r, return_gains=True)

    zr, pr = w[:, 0].clone(), r[:, 0].clone()
    assert torch.allclose(z[:, 0], zr) and torch.allclose(p_diag[:, 0], pr)
    assert torch.equal(gains[:, 0], torch.eye(30, dtype=torch.float64).expand(2, 30, 30))
    for t in range(1, 8):
        prior = pr + q
        k = prior / (prior + r[:, t])
        zr = zr + k * (w[:, t] - zr)
        pr = (1 - k) * prior
        assert torch.allclose(z[:, t], zr, atol=1e-10)
        assert torch.allclose(p_diag[:, t], pr, atol=1e-10)
        assert torch.allclose(gains[:, t], torch.diag_embed(k), atol=1e-10)


def test_huge_observation_noise_gives_zero_gain_and_constant_state():
    model = make("drf", "keypoints")
    _freeze_transition(model, q_bias=-30.0)  # q = VARIANCE_FLOOR
    w = torch.randn(2, 10, 30)
    r = torch.full((2, 10, 30), 1e6)
    r[:, 0] = 1.0  # a confident first observation, then nothing worth trusting
    z, _, gains = model.run_filter(w, r, return_gains=True)
    assert gains[:, 1:].abs().max() < 1e-5
    assert torch.allclose(z, w[:, :1].expand_as(z), atol=1e-4)


def test_tiny_observation_noise_gives_identity_gain_and_tracks_observations():
    model = make("drf", "keypoints")
    w = torch.randn(2, 10, 30)
    r = torch.full((2, 10, 30), 1e-6)
    z, _, gains = model.run_filter(w, r, return_gains=True)
    assert torch.allclose(gains, torch.eye(30).expand_as(gains), atol=1e-4)
    assert torch.allclose(z, w, atol=1e-4)


@pytest.mark.parametrize("kind,input_kind", ALL_CASES)
def test_gradient_reaches_every_parameter(kind, input_kind):
    model = make(kind, input_kind).train()
    x = inputs_for(input_kind, b=4, t=5)
    targets = torch.rand(4, 5, model.out_dim) + 1.0
    mean, sigma = model(x)
    model.loss(mean, sigma, targets).backward()
    for name, p in model.named_parameters():
        assert p.grad is not None, f"{name} got no gradient"
        assert torch.isfinite(p.grad).all(), f"{name} has a non-finite gradient"
        assert p.grad.abs().sum() > 0, f"{name} got an all-zero gradient"


@pytest.mark.parametrize("input_kind", ["keypoints", "pendulum"])
def test_drf_stays_finite_on_long_random_sequences(input_kind):
    model = make("drf", input_kind).eval()
    with torch.no_grad():  # a transition that is far from the identity
        model.transition.head.weight.normal_(0, 0.3)
        model.transition.head.bias.normal_(0, 0.3)
    x = inputs_for(input_kind, b=2, t=200, seed=3)
    if input_kind == "keypoints":
        x[..., :2] *= 20  # far outside the normalised range
    with torch.no_grad():
        mean, sigma = model(x)
        h, gains = model.features(x, return_gains=True)
    for t in (mean, sigma, h, gains):
        assert torch.isfinite(t).all()


# ------------------------------------------------------------------------------ losses

def test_gaussian_nll_known_values():
    mean = torch.zeros(1, 2, 1)
    sigma = torch.ones(1, 2, 1)
    at_mean = gaussian_nll(mean, sigma, torch.zeros(1, 2, 1))
    one_off = gaussian_nll(mean, sigma, torch.ones(1, 2, 1))
    assert at_mean.item() == pytest.approx(0.9189385, abs=1e-6)
    assert one_off.item() == pytest.approx(1.4189385, abs=1e-6)
    assert gaussian_nll(mean, 2 * sigma, torch.zeros(1, 2, 1)).item() == pytest.approx(
        0.9189385 + math.log(2), abs=1e-6)


@pytest.mark.parametrize("kind", ["drf", "monoloco"])
def test_masked_loss_ignores_padded_frames(kind):
    model = make(kind, "keypoints")
    mean = torch.rand(2, 5, 1) * 10 + 1
    sigma = torch.rand(2, 5, 1) + 0.5
    targets = torch.rand(2, 5, 1) * 10 + 1
    mask = torch.ones(2, 5, dtype=torch.bool)
    mask[0, 3:] = False
    garbage = targets.clone()
    garbage[0, 3:] = 0.0 if kind == "monoloco" else float("nan")
    mean = mean.requires_grad_()
    masked = model.loss(mean, sigma, garbage, mask)
    valid = torch.cat([model.loss(mean[:1, :3], sigma[:1, :3], targets[:1, :3]).reshape(1) * 3,
                       model.loss(mean[1:], sigma[1:], targets[1:]).reshape(1) * 5]).sum() / 8
    assert masked.item() == pytest.approx(valid.item(), rel=1e-6)
    masked.backward()
    assert torch.isfinite(mean.grad).all() and (mean.grad[0, 3:] == 0).all()


def test_loss_rejects_bad_mask_and_shapes():
    model = make("no_dynamics", "keypoints")
    m = torch.ones(2, 3, 1)
    with pytest.raises(ValueError, match="mask"):
        model.loss(m, m, m, torch.ones(2, 3))  # not bool
    with pytest.raises(ValueError, match="no frame"):
        model.loss(m, m, m, torch.zeros(2, 3, dtype=torch.bool))
    with pytest.raises(ValueError, match="one shape"):
        model.loss(m, m, torch.ones(2, 3, 2))


# ---------------------------------------------------------------------------- Monoloco

def test_monoloco_parameter_count():
    model = make("monoloco", "keypoints")
    assert sum(p.numel() for p in model.parameters()) == 407_810  # ~0.41 M, as published


def test_monoloco_loss_matches_formula_and_gradients():
    mu = torch.tensor([10.0, 4.0, 20.0], dtype=torch.float64, requires_grad=True)
    s = torch.tensor([0.5, -1.0, 0.1], dtype=torch.float64, requires_grad=True)
    d = torch.tensor([8.0, 5.0, 20.0], dtype=torch.float64)
    hand = [abs(1 - 10 / 8) * math.exp(-0.5) + 0.5, abs(1 - 4 / 5) * math.exp(1.0) - 1.0, 0.1]
    direct = relative_laplace_loss(mu, s, d)
    assert direct.tolist() == pytest.approx(hand, rel=1e-12)
    mean, sigma = Monoloco.mean_and_sigma(mu, s)
    assert sigma[0, 0].item() == pytest.approx(math.sqrt(2) * math.exp(0.5) * 10)
    via_model = make("monoloco", "keypoints").loss(mean.view(1, 3, 1), sigma.view(1, 3, 1), d.view(1, 3, 1))
    assert via_model.item() == pytest.approx(sum(hand) / 3, rel=1e-10)
    g_model = torch.autograd.grad(via_model, (mu, s))
    g_direct = torch.autograd.grad(direct.mean(), (mu, s))
    for a, b in zip(g_model, g_direct):
        assert torch.allclose(a, b, rtol=1e-8)


def test_family_encoder_centres_on_the_box_of_detected_keypoints():
    kp = torch.zeros(1, 2, 17, 3)
    kp[0, 0, 0] = torch.tensor([1.0, 2.0, 0.9])
    kp[0, 0, 1] = torch.tensor([3.0, 6.0, 0.5])
    kp[0, 0, 2:] = torch.tensor([100.0, 100.0, 0.0])  # undetected: ignored and zeroed
    centre, out = keypoint_box_centre(kp)  # frame 1 has no keypoint at all
    assert out.shape == (1, 2, 17, 2)
    assert torch.allclose(centre[0, 0, 0], torch.tensor([2.0, 4.0]))
    assert torch.allclose(out[0, 0, 0], torch.tensor([-1.0, -2.0]))
    assert torch.allclose(out[0, 0, 1], torch.tensor([1.0, 2.0]))
    assert (out[0, 0, 2:] == 0).all() and (out[0, 1] == 0).all() and (centre[0, 1] == 0).all()


def test_monoloco_centres_on_the_box_of_all_17_placeholders_included():
    # as the published code: the box around every keypoint, a missed one's placeholder too
    kp = torch.zeros(1, 1, 17, 3)
    kp[0, 0, 0] = torch.tensor([1.0, 2.0, 0.9])
    kp[0, 0, 1] = torch.tensor([3.0, 6.0, 0.5])
    kp[0, 0, 2:] = torch.tensor([-5.0, -4.0, 0.0])  # 15 missed keypoints at their placeholder
    out = centre_keypoints(kp).view(17, 2)
    centre = torch.tensor([(-5.0 + 3.0) / 2, (-4.0 + 6.0) / 2])
    assert torch.allclose(out[0], torch.tensor([1.0, 2.0]) - centre)
    assert torch.allclose(out[1], torch.tensor([3.0, 6.0]) - centre)
    assert torch.allclose(out[2:], torch.tensor([-5.0, -4.0]) - centre)
    # every keypoint seen: the same numbers as the family's centring
    kp[0, 0, 2:, 2] = 0.3
    assert torch.allclose(centre_keypoints(kp), keypoint_box_centre(kp)[1].flatten(-2))


def test_monoloco_mc_dropout_switches_on_only_the_first_dropout():
    model = make("monoloco", "keypoints").eval()
    x = inputs_for("keypoints", b=2, t=3)
    h, _ = model.features(x)
    S, p = 300, model.dropout_p
    torch.manual_seed(5)
    mean, _ = model.head(h, n_samples=S)  # (S, 2, 3, 1)
    # by hand: the input layer in eval mode, one dropout mask per sample on its output, then the
    # residual blocks and the output layer in eval mode (no dropout)
    torch.manual_seed(5)
    first = torch.relu(model.input_norm(model.input_layer(h.reshape(6, 34))))
    masks = (torch.rand(S, 6, first.shape[-1]) >= p) / (1 - p)
    mus = []
    for m in masks:
        y = first * m
        for i in range(0, len(model.layers), 2):
            z = torch.relu(model.norms[i](model.layers[i](y)))
            y = y + torch.relu(model.norms[i + 1](model.layers[i + 1](z)))
        mus.append(model.output_layer(y)[:, 0])
    hand = torch.stack(mus).view(S, 2, 3, 1)
    assert torch.allclose(mean, hand, atol=1e-5)
    hand_spread = hand.std(0)
    assert torch.allclose(mean.std(0), hand_spread, rtol=1e-4)
    # all seven dropouts on (the book's old choice) spreads mu more
    torch.manual_seed(5)
    flat = h.reshape(6, 34).unsqueeze(0).expand(S, -1, -1).reshape(S * 6, 34)
    all_mu, _ = model.mlp(flat, p, dropout_on=True, bn_batch_stats=False)
    assert all_mu.view(S, 6).std(0).mean() > 1.05 * hand_spread.mean()


def test_monoloco_sampling_keeps_batchnorm_in_eval_and_modes_agree():
    model = make("monoloco", "keypoints").train()
    h, _ = model.features(inputs_for("keypoints", b=2, t=2))
    before = [n.running_mean.clone() for n in model.norms]
    torch.manual_seed(0)
    batched_mean, _ = model.head(h, n_samples=400)
    assert all(torch.equal(b, n.running_mean) for b, n in zip(before, model.norms))
    model.mc_mode = "sequential"
    torch.manual_seed(1)
    seq_mean, _ = model.head(h, n_samples=400)
    # same distribution of dropout passes: sample means and spreads agree
    spread = batched_mean.std(0)
    assert ((batched_mean.mean(0) - seq_mean.mean(0)).abs() < 4 * spread / math.sqrt(200)).all()
    assert torch.allclose(seq_mean.std(0), spread, rtol=0.25)
    # p = 0: every sample is the eval-mode pass
    model.eval()
    zero_mean, zero_sigma = model.head(h, n_samples=3, dropout_p=0.0)
    eval_mean, eval_sigma = model.head(h)
    assert torch.equal(zero_mean, eval_mean.expand(3, -1, -1, -1))
    assert torch.equal(zero_sigma, eval_sigma.expand(3, -1, -1, -1))


def test_monoloco_fed_the_drf_familys_inputs_reads_exactly_what_their_encoder_reads():
    from drfkit.models.parts import keypoint_features

    torch.manual_seed(0)
    kp = torch.cat([torch.randn(2, 3, 17, 2), torch.rand(2, 3, 17, 1)], dim=-1)
    kp[0, 1, 4:9, 2] = 0.0  # missed keypoints
    model = build_model({"kind": "monoloco", "input_kind": "keypoints", "out_dim": 1, "inputs": "detected"}).eval()
    h, _ = model.features(kp)
    assert h.shape == (2, 3, 53) and torch.equal(h, keypoint_features(kp))
    assert torch.equal(h[0, 1, 8:18], torch.zeros(10))  # missed keypoints are 0, not their placeholders
    encoder = make("no_dynamics", "keypoints").encoder
    assert torch.allclose(encoder(kp), encoder.net(h))  # the family's encoder reads the same 53 numbers
    assert model.input_layer.in_features == 53 and model.config["inputs"] == "detected"
    mean, sigma = model(kp)
    assert mean.shape == sigma.shape == (2, 3, 1)
    assert "inputs" not in make("monoloco", "keypoints").config  # the published model's name is unchanged
    with pytest.raises(ValueError, match="inputs must be one of"):
        build_model({"kind": "monoloco", "input_kind": "keypoints", "out_dim": 1, "inputs": "raw"})


def test_monoloco_rejects_other_inputs():
    with pytest.raises(ValueError, match="keypoints"):
        build_model({"kind": "monoloco", "input_kind": "pendulum", "out_dim": 2})
    with pytest.raises(ValueError, match="mc_mode"):
        build_model({"kind": "monoloco", "input_kind": "keypoints", "out_dim": 1, "mc_mode": "loop"})


# ----------------------------------------------------------------------------- decoder

def test_decoder_batched_masks_equal_the_per_sample_definition():
    dec = Decoder(6, 2, hidden=16, dropout_p=0.3).eval()
    x = torch.randn(4, 5, 6)
    torch.manual_seed(7)
    means, sigmas = dec(x, n_samples=5)
    torch.manual_seed(7)
    h = dec.hidden(x)
    masks = (torch.rand((5, *h.shape)) >= 0.3).float()
    for s in range(5):
        m, sg = dec.readout(h * masks[s] / 0.7)
        assert torch.allclose(means[s], m, atol=1e-6) and torch.allclose(sigmas[s], sg, atol=1e-6)


def test_decoder_batched_sampling_matches_sequential_train_mode_passes():
    dec = Decoder(6, 1, hidden=32, dropout_p=0.2)
    x = torch.randn(3, 6)
    torch.manual_seed(0)
    batched, _ = dec(x, n_samples=2000)
    dec.train()
    torch.manual_seed(1)
    sequential = torch.stack([dec(x)[0] for _ in range(2000)])
    spread = batched.std(0)
    assert ((batched.mean(0) - sequential.mean(0)).abs() < 4 * spread / math.sqrt(1000)).all()
    assert torch.allclose(sequential.std(0), spread, rtol=0.1)


def test_decoder_modes_and_floor():
    dec = Decoder(4, 2, hidden=8, dropout_p=0.5)
    x = torch.randn(10, 4)
    dec.eval()
    assert torch.equal(dec(x)[0], dec(x)[0])  # eval, n_samples = 0: deterministic
    means, _ = dec(x, n_samples=6)  # eval, n_samples > 0: dropout on anyway
    assert means.shape == (6, 10, 2) and means.std(0).max() > 0
    zero, _ = dec(x, n_samples=6, dropout_p=0.0)
    # equal up to rounding: a batched (6, 10, .) product may sum in another order than the (10, .) one (it
    # does on some CPUs' BLAS kernels); a dropout that stayed on would differ by O(1)
    torch.testing.assert_close(zero, dec(x)[0].expand(6, -1, -1), rtol=1e-5, atol=1e-6)
    with torch.no_grad():
        dec.linear5.bias.fill_(-1e4)
    assert dec(x)[1].min().item() == pytest.approx(SIGMA_FLOOR, rel=1e-3)


@pytest.mark.parametrize("bad", [-1, 1.5, True, "3"])
def test_decoder_rejects_bad_n_samples(bad):
    with pytest.raises(ValueError, match="n_samples"):
        Decoder(4, 1)(torch.zeros(2, 4), n_samples=bad)


@pytest.mark.parametrize("bad", [1.0, -0.1, "0.1"])
def test_decoder_rejects_bad_dropout(bad):
    with pytest.raises(ValueError, match="dropout_p"):
        Decoder(4, 1)(torch.zeros(2, 4), n_samples=2, dropout_p=bad)


# ------------------------------------------------------------------------------ config

@pytest.mark.parametrize("kind,input_kind", ALL_CASES)
def test_build_model_round_trip(kind, input_kind):
    model = make(kind, input_kind)
    with torch.no_grad():  # make BatchNorm running stats non-trivial
        for name, buf in model.named_buffers():
            if name.endswith("running_mean"):
                buf.normal_()
    torch.manual_seed(99)
    rebuilt = build_model(model.config)
    rebuilt.load_state_dict(model.state_dict())
    assert rebuilt.config == model.config and type(rebuilt) is type(model)
    x = inputs_for(input_kind)
    with torch.no_grad():
        for a, b in zip(model.eval()(x), rebuilt.eval()(x)):
            assert torch.equal(a, b)


def test_config_contents_and_defaults():
    cfg = default_config("drf", "pendulum", 2)
    assert cfg["kind"] == "drf" and cfg["latent"] == 30 and cfg["input_kind"] == "pendulum"
    mono = make("monoloco", "keypoints")
    assert mono.default_dropout_p == 0.2 and make("lstm", "keypoints").default_dropout_p == 0.1
    stride = make("no_dynamics", "pendulum", image_downsample="stride")
    assert stride(inputs_for("pendulum"))[0].shape == (3, 6, 2)


@pytest.mark.parametrize("config,match", [
    ({"kind": "kalman", "input_kind": "pendulum", "out_dim": 2}, "unknown model kind"),
    ({"input_kind": "pendulum"}, "kind"),
    ({"kind": "drf", "input_kind": "pendulum", "out_dim": 2, "latnet": 30}, "latnet"),
    ({"kind": "no_dynamics", "input_kind": "pendulum", "out_dim": 2, "transition_hidden": 8},
     "transition_hidden"),
    ({"kind": "drf", "input_kind": "images", "out_dim": 2}, "input_kind"),
    ({"kind": "lstm", "input_kind": "pendulum", "out_dim": 0}, "out_dim"),
    ({"kind": "drf", "input_kind": "pendulum", "out_dim": 2, "image_downsample": "avg"}, "image_downsample"),
])
def test_build_model_rejects_bad_config(config, match):
    with pytest.raises(ValueError, match=match):
        build_model(config)


# ------------------------------------------------------------------------------ inputs

def test_inputs_are_checked():
    pend = make("no_dynamics", "pendulum")
    with pytest.raises(ValueError, match="24, 24"):
        pend(torch.zeros(2, 3, 28, 28, dtype=torch.uint8))
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        pend(torch.full((1, 2, 24, 24), 200.0))
    with pytest.raises(TypeError, match="uint8"):
        pend(torch.zeros(1, 2, 24, 24, dtype=torch.int32))
    images = torch.randint(0, 256, (1, 2, 24, 24), dtype=torch.uint8)
    pend.eval()
    assert torch.allclose(pend(images)[0], pend(images.float() / 255)[0], atol=1e-6)
    kp = make("drf", "keypoints")
    with pytest.raises(ValueError, match="17, 3"):
        kp(torch.zeros(1, 2, 17, 2))
    with pytest.raises(TypeError, match="float"):
        kp(torch.zeros(1, 2, 17, 3, dtype=torch.int64))
    with pytest.raises(ValueError, match="w and r"):
        kp.run_filter(torch.zeros(1, 2, 30), torch.ones(1, 2, 29))


def test_decoder_target_scaling_is_an_affine_map_of_the_unscaled_decoder():
    from drfkit.models import Decoder

    torch.manual_seed(0)
    plain = Decoder(8, 1, hidden=16, dropout_p=0.1)
    scaled = Decoder(8, 1, hidden=16, dropout_p=0.1, target_offset=25.0, target_scale=12.0)
    scaled.load_state_dict(plain.state_dict())
    x = torch.randn(4, 5, 8)
    (m0, s0), (m1, s1) = plain.eval()(x), scaled.eval()(x)
    torch.testing.assert_close(m1, 25.0 + 12.0 * m0)
    torch.testing.assert_close(s1, 12.0 * s0)
    with pytest.raises(ValueError, match="target_scale"):
        Decoder(8, 1, target_scale=0.0)


def test_keypoint_encoder_sees_position_and_shape_separately():
    from drfkit.models import KeypointEncoder

    torch.manual_seed(0)
    enc = KeypointEncoder(feature_dim=16)
    kp = torch.rand(2, 3, 17, 3) + 0.1  # all keypoints detected (confidence > 0)
    shifted = kp.clone()
    shifted[..., :2] += 0.5  # same person, elsewhere in the image
    # the centred part is unchanged by a shift; only the 2 centre inputs differ
    assert enc.net[0].in_features == 17 * 3 + 2
    assert not torch.allclose(enc(kp), enc(shifted))
    with torch.no_grad():
        enc.net[0].weight[:, 34:36] = 0.0  # cut the centre inputs
    torch.testing.assert_close(enc(kp), enc(shifted))


def test_image_encoder_chunks_compute_the_same_function():
    from drfkit.models.parts import ENCODER_CHUNK_FRAMES, ImageEncoder

    torch.manual_seed(0)
    enc = ImageEncoder()
    # more frames than one chunk, and not a multiple of it, so the last chunk is short
    images = torch.randint(0, 256, (3, ENCODER_CHUNK_FRAMES // 2 + 7, 24, 24), dtype=torch.uint8)
    chunked = enc(images)
    whole = enc.encode_frames(images.flatten(0, 1).float() / 255.0).view(3, -1, enc.out_dim)
    assert chunked.shape == (3, ENCODER_CHUNK_FRAMES // 2 + 7, enc.out_dim)
    torch.testing.assert_close(chunked, whole, rtol=1e-5, atol=1e-6)
    grads = torch.autograd.grad(chunked.square().sum(), list(enc.parameters()))
    grads_whole = torch.autograd.grad(whole.square().sum(), list(enc.parameters()))
    for g, gw in zip(grads, grads_whole):
        torch.testing.assert_close(g, gw, rtol=1e-4, atol=1e-5)


def test_a_split_decoder_reads_the_mean_from_z_and_sigma_from_the_variance_alone():
    """decoder_split: changing the belief's log variance moves sigma, never the mean; changing its
    mean moves the mean, never sigma (for one pass and for MC-dropout samples)."""
    from drfkit.models.parts import Decoder

    torch.manual_seed(0)
    dec = Decoder(8, 2, hidden=16, dropout_p=0.2, split=4).eval()
    x = torch.randn(3, 5, 8)
    other_var = x.clone()
    other_var[..., 4:] += 1.0
    other_mean = x.clone()
    other_mean[..., :4] += 1.0
    with torch.no_grad():
        m0, s0 = dec(x)
        m1, s1 = dec(other_var)
        m2, s2 = dec(other_mean)
        assert torch.equal(m0, m1) and not torch.allclose(s0, s1)
        assert torch.equal(s0, s2) and not torch.allclose(m0, m2)
        torch.manual_seed(1)
        ms, ss = dec(x, n_samples=4)
        torch.manual_seed(1)
        ms1, ss1 = dec(other_var, n_samples=4)
        assert ms.shape == (4, 3, 5, 2) and torch.equal(ms, ms1)
    with pytest.raises(ValueError, match="split"):
        Decoder(8, 2, split=8)
    with pytest.raises(ValueError, match="cannot be split"):
        build_model(default_config("lstm", "pendulum", 2, decoder_split=True))


def test_fast_pooling_is_max_pool2d_bit_for_bit_and_training_keeps_max_pool2d():
    from drfkit.models.parts import ImageEncoder, max_pool_2x2
    x = torch.randn(7, 5, 24, 24)
    x[:, :, :4, :4] = 0.25  # ties, as on a blank background
    with torch.no_grad():
        assert torch.equal(max_pool_2x2(x), torch.nn.functional.max_pool2d(x, 2))
    enc = ImageEncoder(16, 6)
    frames = torch.randint(0, 256, (2, 3, 24, 24), dtype=torch.uint8)
    with torch.no_grad():
        fast = enc(frames)
    slow = enc(frames)  # autograd on: max_pool2d itself
    assert slow.requires_grad and torch.equal(fast, slow.detach())


def test_distinct_frames_once_encodes_each_repeated_frame_once_with_the_same_numbers(monkeypatch):
    """Inside ``distinct_frames_once`` (evaluation) an image model's encoder sees each distinct frame once, and the
    features (encoder, filter) are bit for bit those of every frame encoded; outside it, with autograd, and after
    the block, every frame is encoded (training and the timed inference are untouched)."""
    from drfkit.models import default_config
    from drfkit.models.frame_codes import distinct_frames_once
    from drfkit.models.parts import ImageEncoder

    torch.manual_seed(0)
    model = build_model(default_config("drf", "pendulum", 2)).eval()
    g = torch.Generator().manual_seed(1)
    bank = torch.randint(0, 256, (5, 24, 24), generator=g, dtype=torch.uint8)  # a rod bank's clean images
    x = torch.randint(0, 256, (6, 40, 24, 24), generator=g, dtype=torch.uint8)  # noisy frames: all distinct
    x[:, ::3] = bank[torch.randint(0, 5, (6, 14), generator=g)]  # a third of the frames from the bank
    x[2, 20:30] = 0  # ten identical frames
    seen = []
    real = ImageEncoder.encode_frames
    monkeypatch.setattr(ImageEncoder, "encode_frames", lambda self, f: seen.append(f.shape[0]) or real(self, f))
    with torch.no_grad():
        every, every_gains = model.features(x, return_gains=True)
        n_every = sum(seen)
        seen.clear()
        with distinct_frames_once(model):
            once, once_gains = model.features(x, return_gains=True)
        n_once = sum(seen)
    distinct = torch.unique(x.flatten(2).flatten(0, 1), dim=0).shape[0]
    assert n_every == 6 * 40 and n_once == distinct < 6 * 40 - 6 * 14 + 5
    assert torch.equal(every, once) and torch.equal(every_gains, once_gains)
    assert model.encoder.distinct_frames is False  # restored
    seen.clear()
    with distinct_frames_once(model):
        model.features(x)  # autograd on (training): every frame, max_pool2d's gradient rule kept
    assert sum(seen) == 6 * 40


def test_one_block_encodes_a_frame_once_across_calls_a_blackout_costs_its_gap_only(monkeypatch):
    """Inside one (outermost) ``distinct_frames_once`` block the encoder keeps the codes it computed: a second call
    on the blackout version of a set (its gap pure noise, every other frame the same bytes) encodes the gap's
    frames only, a third call on either set nothing, and every output is bit for bit the frame-by-frame one. A
    change of the weights inside the block empties the book; a nested block shares it; after the block it is
    gone."""
    from drfkit.models import default_config
    from drfkit.models.frame_codes import distinct_frames_once
    from drfkit.models.parts import ImageEncoder

    torch.manual_seed(0)
    model = build_model(default_config("drf", "pendulum", 2)).eval()
    g = torch.Generator().manual_seed(2)
    x = torch.randint(0, 256, (4, 30, 24, 24), generator=g, dtype=torch.uint8)  # noisy frames: all distinct
    dark = x.clone()
    dark[:, 12:18] = torch.randint(0, 256, (4, 6, 24, 24), generator=g, dtype=torch.uint8)  # the gap: pure noise
    seen = []  # the frames the distinct path sends to the encoder (before its chunks are padded)
    real = ImageEncoder._encode_rows
    monkeypatch.setattr(ImageEncoder, "_encode_rows", lambda self, f: seen.append(f.shape[0]) or real(self, f))
    with torch.no_grad():
        every = [model.features(v, return_gains=True) for v in (x, dark)]
        codes_every = model.encoder(x)
        seen.clear()
        with distinct_frames_once(model):
            first = model.features(x, return_gains=True)
            n_first = sum(seen)
            with distinct_frames_once(model):  # nested: the outer block's book
                second = model.features(dark, return_gains=True)
            n_second = sum(seen) - n_first
            again = model.encoder(x[:2])  # seen before: nothing encoded
            n_again = sum(seen) - n_first - n_second
            book = model.encoder.frame_codes
            with torch.no_grad():
                model.encoder.fc.bias.add_(0.5)  # the weights change inside the block: the book is emptied
            changed = model.encoder(x)
            n_changed = sum(seen) - n_first - n_second - n_again
            assert copy.deepcopy(model).encoder.frame_codes is None  # a copy (float64 passes) carries no book
        assert model.encoder.frame_codes is None and model.encoder.distinct_frames is False  # gone with the block
        fresh = model.encoder(x)
    assert (n_first, n_second, n_again, n_changed) == (4 * 30, 4 * 6, 0, 4 * 30)
    assert book.encoded == 4 * 30 + 4 * 6 + 4 * 30
    for (h, k), (h0, k0) in zip((first, second), every):
        assert torch.equal(h, h0) and torch.equal(k, k0)
    assert torch.equal(again, codes_every[:2]) and torch.equal(changed, fresh)


def test_a_frame_encoded_alone_in_a_block_gets_its_large_batch_code():
    """A call of a block that meets one new frame encodes it in a padded chunk (``MIN_CODE_CHUNK``): its code is
    the one it gets among many frames, bit for bit (oneDNN's kernels for a batch of 1-3 frames round differently,
    which would make a gathered code depend on what was encoded with it)."""
    from drfkit.models import default_config
    from drfkit.models.frame_codes import distinct_frames_once

    torch.manual_seed(0)
    model = build_model(default_config("drf", "pendulum", 2)).eval()
    g = torch.Generator().manual_seed(4)
    x = torch.randint(0, 256, (1, 41, 24, 24), generator=g, dtype=torch.uint8)
    with torch.no_grad():
        many = model.encoder(x)  # every frame, one chunk of 41
        with distinct_frames_once(model):
            model.encoder(x[:, :40])
            alone = [model.encoder(x[:, 40:])]  # the one new frame
            alone.append(model.encoder(x[:, 40:]))  # and again, from the book
    assert all(torch.equal(a[0, 0], many[0, 40]) for a in alone)


def test_frame_codes_survive_hash_collisions_and_refuse_bad_rows(monkeypatch):
    """Every key match is checked byte for byte: with every key equal (all collide), each frame still gets its own
    code; rows that are not uint8 multiples of 8 bytes are refused with the shape named."""
    import drfkit.models.frame_codes as fc
    from drfkit.models.parts import ImageEncoder

    g = torch.Generator().manual_seed(3)
    rows = torch.randint(0, 256, (20, 576), generator=g, dtype=torch.uint8)
    book = fc.FrameCodes(ImageEncoder(8, 4))
    encode = lambda r: r[:, :8].to(torch.float32)  # noqa: E731  a code that names its frame
    with pytest.raises(ValueError, match=r"uint8 rows.*\(3, 5\)"):
        fc.frame_keys(torch.zeros(3, 5, dtype=torch.uint8))
    monkeypatch.setattr(fc, "frame_keys", lambda r: torch.zeros(r.shape[0], dtype=torch.int64))  # all collide
    book.codes_of(rows[:12], encode)
    codes = book.codes_of(rows[6:], encode)  # 6 seen, 8 new
    assert torch.equal(codes, rows[6:, :8].float())
