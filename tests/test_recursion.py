"""Tests of drfkit.models.recursion: the DRF's whole-sequence recursion (one autograd node,
hand-written backward) against nn.LSTMCell and against autograd through the per-step loop."""
from __future__ import annotations

import pytest
import torch

from drfkit.core.filter import kalman_predict, kalman_update
from drfkit.models import build_model, default_config
from drfkit.models.parts import VARIANCE_FLOOR
from drfkit.models.recursion import TransitionNetwork, _DRFRecursion, drf_recursion, lstm_cell

torch.set_num_threads(1)


def _transition(latent=30, hidden=64, dtype=torch.float64, seed=0):
    """A transition network with a nonzero F residual (a fresh one starts at F = I)."""
    torch.manual_seed(seed)
    net = TransitionNetwork(latent, hidden).to(dtype)
    with torch.no_grad():
        net.head.weight.normal_(0.0, 0.02)
        net.head.bias.normal_(0.0, 0.02)
    return net


def _observations(b, t, n, dtype=torch.float64, seed=1):
    g = torch.Generator().manual_seed(seed)
    w = torch.randn(b, t, n, generator=g, dtype=dtype).requires_grad_()
    r = (torch.rand(b, t, n, generator=g, dtype=dtype) * 2 + 0.1).requires_grad_()
    return w, r


def _reference(net, w, r):
    """The recursion from torch's own modules and the composed (autograd) Kalman step."""
    n = net.latent
    w_steps, r_steps = w.unbind(1), r.unbind(1)
    z, P = w_steps[0], torch.diag_embed(r_steps[0])
    zero = w.new_zeros(w.shape[0], net.hidden)
    h1 = c1 = h2 = c2 = zero
    means, variances = [z], [r_steps[0]]
    for t in range(1, w.shape[1]):
        h1, c1 = net.cell1(z, (h1, c1))
        h2, c2 = net.cell2(h1, (h2, c2))
        out = net.head(h2)
        F = out[:, : n * n].view(-1, n, n) + torch.eye(n, dtype=w.dtype)
        q = torch.nn.functional.elu(out[:, n * n:]) + (1.0 + VARIANCE_FLOOR)
        z, P, _ = kalman_update(*kalman_predict(z, P, F, q), w_steps[t], r_steps[t])
        means.append(z)
        variances.append(P.diagonal(dim1=-2, dim2=-1))
    return torch.stack(means, 1), torch.stack(variances, 1)


def _grads(outputs, upstream, inputs):
    loss = sum((o * u).sum() for o, u in zip(outputs, upstream) if u is not None)
    return torch.autograd.grad(loss, inputs, allow_unused=True, retain_graph=True)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("grad", [False, True])
def test_lstm_cell_equals_torch_lstm_cell_bitwise(dtype, grad):
    torch.manual_seed(0)
    cell = torch.nn.LSTMCell(30, 64).to(dtype)
    x, h, c = (torch.randn(50, k, dtype=dtype) for k in (30, 64, 64))
    with torch.set_grad_enabled(grad):
        expected = cell(x, (h, c))
        h_new, c_new, _, _ = lstm_cell(x, h, c, cell.weight_ih, cell.weight_hh, cell.bias_ih, cell.bias_hh)
    assert torch.equal(h_new, expected[0]) and torch.equal(c_new, expected[1])


def test_whole_sequence_forward_equals_the_per_step_loop_bitwise():
    # training (one node) and inference (per-step loop) compute the same values, so the
    # committed evaluations did not change when training moved to the one-node recursion
    torch.manual_seed(0)
    model = build_model(default_config("drf", "keypoints", 1))
    w, r = _observations(3, 9, 30, torch.float32)
    z, p, _ = model.run_filter(w, r)
    assert type(z.grad_fn).__name__ == "_DRFRecursionBackward"
    with torch.no_grad():
        z_loop, p_loop, _ = model.run_filter(w, r)
    assert torch.equal(z, z_loop) and torch.equal(p, p_loop)


def test_whole_sequence_matches_torch_modules_and_autograd_float64():
    net = _transition()
    w, r = _observations(3, 8, 30)
    inputs = [w, r, *net.parameters()]
    ours, ref = drf_recursion(net, w, r), _reference(net, w, r)  # each differentiated 3 times below
    for a, b in zip(ours, ref):
        torch.testing.assert_close(a, b, rtol=1e-12, atol=1e-12)
    g = torch.Generator().manual_seed(2)
    for upstream in ([torch.randn(o.shape, generator=g, dtype=o.dtype) for o in ours],
                     [torch.randn(ours[0].shape, generator=g, dtype=torch.float64), None],  # z only
                     [None, torch.randn(ours[1].shape, generator=g, dtype=torch.float64)]):  # diag P only
        for a, b in zip(_grads(ours, upstream, inputs), _grads(ref, upstream, inputs)):
            torch.testing.assert_close(a, b, rtol=1e-9, atol=1e-11)


def test_gradcheck_whole_sequence():
    net = _transition(latent=3, hidden=4)
    w, r = _observations(2, 4, 3)
    weights = tuple(p.detach().requires_grad_() for p in net.weights())

    def recursion(w, r, *weights):
        return _DRFRecursion.apply(w, r, net.eye, net.hidden, *weights)

    assert torch.autograd.gradcheck(recursion, (w, r, *weights), eps=1e-6, atol=1e-6, rtol=1e-5)


def test_model_gradients_whole_sequence_vs_per_step_float32_drf_size():
    torch.manual_seed(0)
    model = build_model(default_config("drf", "pendulum", 2)).train()
    with torch.no_grad():
        model.transition.head.weight.normal_(0.0, 0.01)
    g = torch.Generator().manual_seed(3)
    images = torch.randint(0, 256, (8, 75, 24, 24), dtype=torch.uint8, generator=g)
    targets = torch.randn(8, 75, 2, generator=g)
    params = list(model.parameters())
    grads = {}
    for whole in (True, False):
        model.whole_sequence = whole
        torch.manual_seed(5)  # the decoder's dropout draws the same masks in both runs
        mean, sigma = model(images)
        grads[whole] = torch.autograd.grad(model.loss(mean, sigma, targets), params, allow_unused=True)
    for (name, _), a, b in zip(model.named_parameters(), grads[True], grads[False]):
        if b is None:
            assert a is None, name
            continue
        torch.testing.assert_close(a, b, rtol=2e-3, atol=1e-5 * float(b.abs().max()) + 1e-8, msg=name)


def test_sequence_of_one_frame_passes_gradients_to_the_first_observation():
    net = _transition(latent=3, hidden=4)
    w, r = _observations(2, 1, 3)
    z, p = drf_recursion(net, w, r)
    assert torch.equal(z, w) and torch.equal(p, r)
    g_w, g_r, g_head = torch.autograd.grad(2 * z.sum() + 3 * p.sum(), (w, r, net.head.weight), allow_unused=True)
    assert torch.equal(g_w, torch.full_like(w, 2.0)) and torch.equal(g_r, torch.full_like(r, 3.0))
    assert g_head is None


def test_inference_and_gains_take_the_per_step_loop():
    torch.manual_seed(0)
    model = build_model(default_config("drf", "keypoints", 1))
    w, r = _observations(2, 5, 30, torch.float32)
    z, _, gains = model.run_filter(w, r, return_gains=True)
    assert gains.shape == (2, 5, 30, 30) and type(z.grad_fn).__name__ != "_DRFRecursionBackward"
    with torch.no_grad():
        assert model.run_filter(w, r)[0].grad_fn is None


def test_double_backward_is_refused():
    net = _transition(latent=3, hidden=4)
    w, r = _observations(2, 3, 3)
    z, _ = drf_recursion(net, w, r)
    upstream = torch.ones_like(z).requires_grad_()
    (g_w,) = torch.autograd.grad(z, (w,), upstream, create_graph=True)
    with pytest.raises(RuntimeError, match="once_differentiable"):
        g_w.sum().backward()


def test_joseph_form_is_stationary_in_the_gain_at_the_optimal_gain():
    # why the fused backward skips the Joseph form's K-derivative: it vanishes at K = P- S^-1
    g = torch.Generator().manual_seed(4)
    n = 6
    A = torch.randn(n, n, generator=g, dtype=torch.float64)
    P = A @ A.T / n + 0.2 * torch.eye(n, dtype=torch.float64)
    R = torch.diag(torch.rand(n, generator=g, dtype=torch.float64) + 0.1)
    K = (P @ torch.linalg.inv(P + R)).requires_grad_()
    I = torch.eye(n, dtype=torch.float64)
    J = (I - K) @ P @ (I - K).T + K @ R @ K.T
    G = torch.randn(n, n, generator=g, dtype=torch.float64)
    (dK,) = torch.autograd.grad((J * (G + G.T)).sum(), K)
    assert float(dK.abs().max()) < 1e-12
    K_off = (K.detach() + 0.01).requires_grad_()  # and it does not vanish elsewhere
    J_off = (I - K_off) @ P @ (I - K_off).T + K_off @ R @ K_off.T
    (dK_off,) = torch.autograd.grad((J_off * (G + G.T)).sum(), K_off)
    assert float(dK_off.abs().max()) > 1e-3
