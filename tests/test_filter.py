"""Tests of drfkit.core.filter against an independent numpy Kalman filter and known answers."""
import math

import numpy as np
import pytest
import torch

from drfkit.data.noise import Noise
from drfkit.core.filter import kalman_predict, kalman_step, kalman_update


# --------------------------------------------------------------------------- helpers

def random_spd(rng, n, scale=1.0):
    A = rng.standard_normal((n, n))
    return scale * (A @ A.T / n + 0.5 * np.eye(n))


def random_system(rng, n, T, full_noise):
    """A random linear-Gaussian system: F_t near a rotation, random noise covariances."""
    Fs = [np.linalg.qr(rng.standard_normal((n, n)))[0] * rng.uniform(0.8, 1.1) for _ in range(T)]
    if full_noise:
        Qs = [random_spd(rng, n, 0.1) for _ in range(T)]
        Rs = [random_spd(rng, n, 0.5) for _ in range(T)]
    else:
        Qs = [rng.uniform(0.01, 0.2, n) for _ in range(T)]
        Rs = [rng.uniform(0.1, 2.0, n) for _ in range(T)]
    x = rng.standard_normal(n)
    ws = []
    for t in range(T):  # simulate the system so that the observations are plausible
        Qm = Qs[t] if full_noise else np.diag(Qs[t])
        Rm = Rs[t] if full_noise else np.diag(Rs[t])
        x = Fs[t] @ x + rng.multivariate_normal(np.zeros(n), Qm)
        ws.append(x + rng.multivariate_normal(np.zeros(n), Rm))
    return Fs, Qs, ws, Rs


def reference_filter(z, P, Fs, Qs, ws, Rs):
    """Textbook Kalman filter (H = I), explicit inverse and the short covariance update."""
    out = []
    n = len(z)
    for F, Q, w, R in zip(Fs, Qs, ws, Rs):
        Q = Q if Q.ndim == 2 else np.diag(Q)
        R = R if R.ndim == 2 else np.diag(R)
        z = F @ z
        P = F @ P @ F.T + Q
        K = P @ np.linalg.inv(P + R)
        z = z + K @ (w - z)
        P = (np.eye(n) - K) @ P
        out.append((z.copy(), P.copy(), K.copy()))
    return out


def t64(x):
    return torch.as_tensor(np.asarray(x), dtype=torch.float64)


# --------------------------------------------------------------------------- (1) reference agreement

@pytest.mark.parametrize("full_noise", [False, True])
def test_matches_reference_filter_float64(full_noise):
    rng = np.random.default_rng(1 if full_noise else 2)
    n, T = 4, 50
    Fs, Qs, ws, Rs = random_system(rng, n, T, full_noise)
    z0, P0 = rng.standard_normal(n), random_spd(rng, n)
    expected = reference_filter(z0, P0, Fs, Qs, ws, Rs)

    z, P = t64(z0), t64(P0)
    for t in range(T):
        z, P, K = kalman_step(z, P, t64(Fs[t]), t64(Qs[t]), t64(ws[t]), t64(Rs[t]))
        z_ref, P_ref, K_ref = expected[t]
        np.testing.assert_allclose(z.numpy(), z_ref, rtol=0, atol=1e-10)
        np.testing.assert_allclose(P.numpy(), P_ref, rtol=0, atol=1e-10)
        np.testing.assert_allclose(K.numpy(), K_ref, rtol=0, atol=1e-10)


def test_predict_and_update_separately_match_formulas():
    rng = np.random.default_rng(3)
    n = 3
    z, P, F, Q = rng.standard_normal(n), random_spd(rng, n), rng.standard_normal((n, n)), rng.uniform(0.1, 1, n)
    zp, Pp = kalman_predict(t64(z), t64(P), t64(F), t64(Q))
    np.testing.assert_allclose(zp.numpy(), F @ z, atol=1e-12)
    np.testing.assert_allclose(Pp.numpy(), F @ P @ F.T + np.diag(Q), atol=1e-12)

    w, R = rng.standard_normal(n), random_spd(rng, n)
    zn, Pn, K = kalman_update(t64(z), t64(P), t64(w), t64(R))
    K_ref = P @ np.linalg.inv(P + R)
    np.testing.assert_allclose(K.numpy(), K_ref, atol=1e-12)
    np.testing.assert_allclose(zn.numpy(), z + K_ref @ (w - z), atol=1e-12)
    np.testing.assert_allclose(Pn.numpy(), P - K_ref @ P, atol=1e-12)


# --------------------------------------------------------------------------- (2) batching

@pytest.mark.parametrize("full_noise", [False, True])
def test_batched_equals_per_item_loop(full_noise):
    torch.manual_seed(0)
    batch, n = (2, 3), 4
    z = torch.randn(*batch, n, dtype=torch.float64)
    A = torch.randn(*batch, n, n, dtype=torch.float64)
    P = A @ A.mT + torch.eye(n, dtype=torch.float64)
    F = torch.randn(n, n, dtype=torch.float64)  # shared across the batch (broadcast)
    w = torch.randn(*batch, n, dtype=torch.float64)
    if full_noise:
        B = torch.randn(*batch, n, n, dtype=torch.float64)
        R = B @ B.mT + 0.1 * torch.eye(n, dtype=torch.float64)
        Q = 0.1 * torch.eye(n, dtype=torch.float64).expand(1, 1, n, n)  # shared, full
    else:
        R = torch.rand(*batch, n, dtype=torch.float64) + 0.1
        Q = torch.rand(n, dtype=torch.float64) * 0.1  # shared, diagonal
    zb, Pb, Kb = kalman_step(z, P, F, Q, w, R)
    assert zb.shape == (*batch, n) and Pb.shape == Kb.shape == (*batch, n, n)
    for i in range(batch[0]):
        for j in range(batch[1]):
            Qij = Q[0, 0] if full_noise else Q
            zi, Pi, Ki = kalman_step(z[i, j], P[i, j], F, Qij, w[i, j], R[i, j])
            torch.testing.assert_close(zb[i, j], zi, rtol=0, atol=1e-12)
            torch.testing.assert_close(Pb[i, j], Pi, rtol=0, atol=1e-12)
            torch.testing.assert_close(Kb[i, j], Ki, rtol=0, atol=1e-12)


# --------------------------------------------------------------------------- (3) gradients

def _spd(A):
    return A @ A.mT + torch.eye(A.shape[-1], dtype=A.dtype)


@pytest.mark.parametrize("full_q", [False, True])
def test_gradcheck_predict(full_q):
    torch.manual_seed(1)
    n, b = 3, 2
    z = torch.randn(b, n, dtype=torch.float64, requires_grad=True)
    A = torch.randn(b, n, n, dtype=torch.float64, requires_grad=True)
    F = torch.randn(b, n, n, dtype=torch.float64, requires_grad=True)
    if full_q:
        Q = (0.3 * torch.randn(n, n, dtype=torch.float64)).expand(1, n, n).clone().requires_grad_()
    else:
        Q = (torch.rand(b, n, dtype=torch.float64) + 0.1).requires_grad_()

    def fn(z, A, F, Q):
        return kalman_predict(z, _spd(A), F, Q)

    assert torch.autograd.gradcheck(fn, (z, A, F, Q))


@pytest.mark.parametrize("full_r", [False, True])
def test_gradcheck_update(full_r):
    torch.manual_seed(2)
    n, b = 3, 2
    z = torch.randn(b, n, dtype=torch.float64, requires_grad=True)
    A = torch.randn(b, n, n, dtype=torch.float64, requires_grad=True)
    w = torch.randn(b, n, dtype=torch.float64, requires_grad=True)
    if full_r:
        C = torch.randn(b, n, n, dtype=torch.float64, requires_grad=True)
        make_R = _spd
    else:
        C = (torch.rand(b, n, dtype=torch.float64) + 0.2).requires_grad_()
        make_R = lambda c: c  # noqa: E731

    def fn(z, A, w, C):
        return kalman_update(z, _spd(A), w, make_R(C))

    assert torch.autograd.gradcheck(fn, (z, A, w, C))


def test_gradcheck_step_with_broadcast_shared_arguments():
    # P and F shared by the batch, R batched: gradients must be summed over the broadcast.
    torch.manual_seed(3)
    n, b = 3, 2
    z = torch.randn(b, n, dtype=torch.float64, requires_grad=True)
    A = torch.randn(n, n, dtype=torch.float64, requires_grad=True)
    F = torch.randn(n, n, dtype=torch.float64, requires_grad=True)
    q = (torch.rand(n, dtype=torch.float64) + 0.1).requires_grad_()
    w = torch.randn(b, n, dtype=torch.float64, requires_grad=True)
    r = (torch.rand(b, n, dtype=torch.float64) + 0.2).requires_grad_()

    def fn(z, A, F, q, w, r):
        return kalman_step(z, _spd(A), F, q, w, r)

    assert torch.autograd.gradcheck(fn, (z, A, F, q, w, r))


# --------------------------------------------------------------------------- (4) long runs, extreme noise

def _log_uniform(gen, shape, dtype):
    return torch.pow(10.0, torch.empty(shape, dtype=torch.float64).uniform_(-6, 6, generator=gen)).to(dtype)


@pytest.mark.parametrize("path", ["composed", "fused"])
@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
def test_long_run_extreme_noise_keeps_P_valid(dtype, path):
    gen = torch.Generator().manual_seed(4)
    b, n, T = 4, 5, 1000
    z = torch.zeros(b, n, dtype=dtype)
    P = torch.eye(n, dtype=dtype).expand(b, n, n)
    F = torch.linalg.qr(torch.randn(T, n, n, generator=gen, dtype=torch.float64))[0].to(dtype)
    if path == "fused":  # a batched F takes the fused step (test_fused_path_is_taken_only_for_...)
        F = F.unsqueeze(1).expand(T, b, n, n)
    Q = _log_uniform(gen, (T, b, n), dtype)
    R = _log_uniform(gen, (T, b, n), dtype)
    w = torch.randn(T, b, n, generator=gen, dtype=torch.float64).to(dtype)
    for t in range(T):
        z, P, K = kalman_step(z, P, F[t], Q[t], w[t], R[t])
        assert torch.isfinite(P).all() and torch.isfinite(z).all() and torch.isfinite(K).all(), t
        if dtype == torch.float64:
            assert torch.equal(P, P.mT), t  # symmetrised exactly
            assert (torch.linalg.cholesky_ex(P)[1] == 0).all(), t
            assert (torch.linalg.eigvalsh(P) > 0).all(), t
    assert P.dtype == dtype


# --------------------------------------------------------------------------- (5) known answer

@pytest.mark.parametrize("q,r", [(0.5, 2.0), (1e-3, 10.0), (4.0, 0.1)])
def test_scalar_random_walk_steady_state(q, r):
    # F = 1: the steady posterior variance p solves p = (p + q) r / (p + q + r),
    # i.e. p^2 + q p - q r = 0, and the steady gain is K = (p + q) / (p + q + r) = p / r.
    p_exact = (-q + math.sqrt(q * q + 4 * q * r)) / 2
    one = torch.ones(1, 1, dtype=torch.float64)
    z, P = torch.zeros(1, dtype=torch.float64), 100.0 * one
    for _ in range(2000):
        z, P, K = kalman_step(z, P, one, torch.tensor([q], dtype=torch.float64),
                              torch.zeros(1, dtype=torch.float64), torch.tensor([r], dtype=torch.float64))
    assert P.item() == pytest.approx(p_exact, rel=1e-12)
    assert K.item() == pytest.approx(p_exact / r, rel=1e-12)


# --------------------------------------------------------------------------- (6) errors

def _ok_args(n=3, b=2):
    return dict(z=torch.zeros(b, n), P=torch.eye(n).expand(b, n, n), F=torch.eye(n), Q=torch.ones(n),
                w=torch.zeros(b, n), R=torch.ones(b, n))


@pytest.mark.parametrize("change,match", [
    (dict(P=torch.eye(4)), r"P must have shape \(\.\.\., 3, 3\)"),
    (dict(F=torch.ones(3, 2)), r"F must have shape \(\.\.\., 3, 3\)"),
    (dict(w=torch.zeros(2, 4)), r"w must have shape \(\.\.\., 3\)"),
    (dict(Q=torch.ones(4)), r"Q must have shape"),
    (dict(R=torch.ones(1, 1, 2, 3, 3)), r"R has shape .* full matrix"),
    (dict(R=torch.ones(5, 3)), r"batch dims do not broadcast"),
    (dict(z=torch.tensor(0.0)), r"0-dim"),
    (dict(R=torch.ones(2, 3, dtype=torch.float64)), r"share one dtype"),
    (dict(w=np.zeros((2, 3))), r"must be a torch.Tensor"),
    (dict(z=torch.zeros(2, 3, dtype=torch.int64)), r"floating point"),
])
def test_bad_shapes_raise_clear_errors(change, match):
    args = _ok_args()
    args.update(change)
    exc = TypeError if any(w in match for w in ("dtype", "Tensor", "floating")) else ValueError
    with pytest.raises(exc, match=match):
        kalman_step(**args)


def test_singular_S_gets_jitter_and_bad_covariances_raise():
    # P singular and R = 0: S is singular, Cholesky fails; the jittered retry must give finite output.
    P = torch.tensor([[1.0, 1.0], [1.0, 1.0]], dtype=torch.float64)
    z, w, R = (torch.tensor(v, dtype=torch.float64) for v in ([0.0, 0.0], [1.0, 1.0], [0.0, 0.0]))
    assert torch.linalg.cholesky_ex(P + torch.diag(R))[1].item() > 0
    zn, Pn, K = kalman_update(z, P, w, R)
    assert torch.isfinite(zn).all() and torch.isfinite(Pn).all() and torch.isfinite(K).all()
    with pytest.raises(ValueError, match="not positive definite"):
        kalman_update(z, -torch.eye(2, dtype=torch.float64), w, R)
    with pytest.raises(ValueError, match="NaN or inf"):
        kalman_update(z, torch.full((2, 2), float("nan"), dtype=torch.float64), w, R)


# --------------------------------------------------------------------------- (7) float32

@pytest.mark.parametrize("path", ["composed", "fused"])
def test_float32_matches_float64(path):
    rng = np.random.default_rng(5)
    n, T, b = 6, 30, 3
    runs = {}
    for dtype in (torch.float32, torch.float64):
        z = torch.zeros(b, n, dtype=dtype)
        P = torch.eye(n, dtype=dtype).expand(b, n, n)
        rng = np.random.default_rng(5)
        for _ in range(T):
            F = torch.as_tensor(np.linalg.qr(rng.standard_normal((n, n)))[0], dtype=dtype)
            F = F.expand(b, n, n) if path == "fused" else F
            q = torch.as_tensor(rng.uniform(0.01, 0.3, (b, n)), dtype=dtype)
            w = torch.as_tensor(rng.standard_normal((b, n)), dtype=dtype)
            r = torch.as_tensor(rng.uniform(0.1, 2.0, (b, n)), dtype=dtype)
            z, P, K = kalman_step(z, P, F, q, w, r)
        assert z.dtype == P.dtype == K.dtype == dtype
        runs[dtype] = (z, P)
    torch.testing.assert_close(runs[torch.float32][0].double(), runs[torch.float64][0], rtol=1e-4, atol=1e-5)
    torch.testing.assert_close(runs[torch.float32][1].double(), runs[torch.float64][1], rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("shared_F", [False, True])
def test_float32_backward_runs(shared_F):
    torch.manual_seed(6)
    b, n = 4, 30
    z = torch.zeros(b, n)
    P = torch.eye(n).expand(b, n, n)
    F = (torch.eye(n) + 0.05 * torch.randn(1 if shared_F else b, n, n)).requires_grad_()
    q = (0.1 * torch.rand(b, n) + 0.01).requires_grad_()
    w = torch.randn(b, n, requires_grad=True)
    r = (torch.rand(b, n) + 0.1).requires_grad_()
    for _ in range(5):
        z, P, K = kalman_step(z, P, F, q, w, r)
    (z.square().sum() + P.diagonal(dim1=-2, dim2=-1).sum()).backward()
    for t in (F, q, w, r):
        assert t.grad is not None and t.grad.dtype == torch.float32 and torch.isfinite(t.grad).all()
        assert t.grad.abs().sum() > 0


# --------------------------------------------------------------------------- (8) the fused step
# kalman_step takes a fused path (one autograd node, hand-written backward, S^-1 by
# cholesky_inverse) for batched z, P, F, q, w, r with diagonal noise: the DRF's case.

def _batched_args(b=4, n=5, dtype=torch.float64, seed=0):
    g = torch.Generator().manual_seed(seed)
    A = torch.randn(b, n, n, generator=g, dtype=dtype)
    P = A @ A.mT / n + 0.3 * torch.eye(n, dtype=dtype)
    return dict(z=torch.randn(b, n, generator=g, dtype=dtype),
                P=(P + P.mT) / 2,  # exactly symmetric, as a filter step returns it
                F=torch.eye(n, dtype=dtype) + 0.2 * torch.randn(b, n, n, generator=g, dtype=dtype),
                Q=torch.rand(b, n, generator=g, dtype=dtype) + 0.05,
                w=torch.randn(b, n, generator=g, dtype=dtype),
                R=torch.rand(b, n, generator=g, dtype=dtype) + 0.1)


def _composed(z, P, F, Q, w, R):
    return kalman_update(*kalman_predict(z, P, F, Q), w, R)


def test_fused_path_is_taken_only_for_batched_diagonal_arguments():
    args = _batched_args()
    leaf = {k: v.clone().requires_grad_() for k, v in args.items()}
    assert type(kalman_step(**leaf)[0].grad_fn).__name__ == "_FusedStepBackward"
    shared_F = {**leaf, "F": leaf["F"][0]}
    assert type(kalman_step(**shared_F)[0].grad_fn).__name__ != "_FusedStepBackward"
    full_R = {**leaf, "R": torch.diag_embed(leaf["R"])}
    assert type(kalman_step(**full_R)[0].grad_fn).__name__ != "_FusedStepBackward"


@pytest.mark.parametrize("used", ["all", "z", "P", "K"])
def test_fused_step_matches_composed_values_and_gradients(used):
    args = {k: v.requires_grad_() for k, v in _batched_args().items()}
    fused, composed = kalman_step(**args), _composed(**args)
    assert type(fused[0].grad_fn).__name__ == "_FusedStepBackward"
    for a, b in zip(fused, composed):
        torch.testing.assert_close(a, b, rtol=0, atol=1e-12)
    g = torch.Generator().manual_seed(1)
    upstream = [torch.randn(o.shape, generator=g, dtype=o.dtype) for o in fused]
    pick = {"all": (0, 1, 2), "z": (0,), "P": (1,), "K": (2,)}[used]
    grads = [torch.autograd.grad([out[i] for i in pick], list(args.values()), [upstream[i] for i in pick],
                                 allow_unused=True) for out in (fused, composed)]
    for name, a, b in zip(args, *grads):
        if b is None:  # P, K do not depend on z and w
            assert a is None or torch.count_nonzero(a) == 0, name
        else:
            torch.testing.assert_close(a, b, rtol=0, atol=1e-11, msg=name)


def test_fused_backward_for_symmetric_inputs_matches_the_general_one_and_writes_out_F():
    # symmetric=True (the DRF recursion's case) skips sym(g_P) and P + P^T; with symmetric
    # P and g_P it must give the general backward's gradients, dL/dF written into out_F
    from drfkit.core.filter import fused_step_backward, fused_step_forward

    args = _batched_args(seed=4)
    *_, saved = fused_step_forward(*args.values())
    g = torch.Generator().manual_seed(5)
    g_z = torch.randn(4, 5, generator=g, dtype=torch.float64)
    A = torch.randn(4, 5, 5, generator=g, dtype=torch.float64)
    g_P = A + A.mT
    general = fused_step_backward(saved, g_z, g_P, None)
    out_F = torch.full((4, 5, 5), float("nan"), dtype=torch.float64)
    lean = fused_step_backward(saved, g_z, g_P, None, symmetric=True, out_F=out_F)
    assert lean[2].data_ptr() == out_F.data_ptr()
    for name, a, b in zip(("z", "P", "F", "q", "w", "r"), lean, general):
        torch.testing.assert_close(a, b, rtol=0, atol=1e-12, msg=name)
    only_P = fused_step_backward(saved, None, g_P, None, symmetric=True)  # no out_F, no dL/dz_new
    torch.testing.assert_close(only_P[1], fused_step_backward(saved, None, g_P, None)[1], rtol=0, atol=1e-12)


def test_gradcheck_fused_step_with_unsymmetric_P():
    # the gradient is that of the function on any P (it enters through F P F^T, then symmetrised)
    args = _batched_args(b=2, n=3, seed=2)
    args["P"] = args["P"] + 0.05 * torch.randn(2, 3, 3, dtype=torch.float64, generator=torch.Generator().manual_seed(3))
    leaves = tuple(v.requires_grad_() for v in args.values())
    assert torch.autograd.gradcheck(kalman_step, leaves)


def test_fused_step_matches_composed_over_a_float32_drf_sized_run():
    g = torch.Generator().manual_seed(7)
    b, n, T = 50, 30, 75
    w = torch.randn(T, b, n, generator=g)
    r = torch.pow(10.0, torch.empty(T, b, n).uniform_(-2, 1, generator=g))
    F = torch.eye(n) + 0.05 * torch.randn(T, b, n, n, generator=g)
    q = 0.01 + 0.1 * torch.rand(T, b, n, generator=g)
    runs = []
    for step in (kalman_step, _composed):
        z, P = w[0], torch.diag_embed(r[0])
        for t in range(1, T):
            z, P, K = step(z, P, F[t], q[t], w[t], r[t])
        runs.append((z, P, K))
    for a, b_ in zip(*runs):
        torch.testing.assert_close(a, b_, rtol=1e-4, atol=1e-5)


def test_fused_step_singular_S_gets_jitter_and_nan_raises():
    P = torch.tensor([[[1.0, 1.0], [1.0, 1.0]]], dtype=torch.float64)
    F, z, w, R = torch.eye(2, dtype=torch.float64).expand(1, 2, 2), torch.zeros(1, 2, dtype=torch.float64), \
        torch.ones(1, 2, dtype=torch.float64), torch.zeros(1, 2, dtype=torch.float64)
    zn, Pn, K = kalman_step(z, P, F, R, w, R)
    assert torch.isfinite(zn).all() and torch.isfinite(Pn).all() and torch.isfinite(K).all()
    with pytest.raises(ValueError, match="NaN or inf"):
        kalman_step(z, torch.full((1, 2, 2), float("nan"), dtype=torch.float64), F, R, w, R)


def test_fused_step_keeps_the_committed_paper_drf_predictions():
    # The paper's pendulum DRF was trained and evaluated with the composed step; the fused one
    # must give the same predictions (to float32 rounding) from its committed checkpoint.
    from pathlib import Path

    import drfkit.core.filter as filter_module
    from drfkit import load_checkpoint
    from drfkit.data.pendulum import generate_pendulum

    from drfkit.util.paths import REPO_ROOT

    # a committed paper-protocol DRF (the paper's LSTM transition): whichever frames it was trained on
    paths = sorted(Path(REPO_ROOT, "results", "paper", "models").glob("pendulum-drf-seed*-best.pt"))
    models = [load_checkpoint(p).eval() for p in paths]
    models = [m for m in models if "transition_kind" not in m.config and "memory_dims" not in m.config]
    assert models, "no committed paper-protocol pendulum DRF checkpoint"
    model = models[0]
    images = torch.as_tensor(generate_pendulum(4, 75, Noise("rkn_uniform", 0.75), seed=11)["images"])
    original, fused_steps = filter_module._batched_diagonal, []

    def recorded(*args):
        fused_steps.append(original(*args))
        return fused_steps[-1]

    with torch.no_grad():
        try:
            filter_module._batched_diagonal = recorded
            fused = model(images)
            filter_module._batched_diagonal = lambda *args: False  # force the composed path
            composed = model(images)
        finally:
            filter_module._batched_diagonal = original
    assert len(fused_steps) == 74 and all(fused_steps)
    torch.testing.assert_close(fused[0], composed[0], rtol=0, atol=1e-5)
    torch.testing.assert_close(fused[1], composed[1], rtol=1e-4, atol=1e-6)
