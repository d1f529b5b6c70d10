"""The accelerator path (``drfkit.models.compiled``): the DRF's filter step without a host
synchronisation, captured by ``torch.compile``, gives the checked loop's values, and a batch in
which a factorisation fails is run again by the checked loop (same error). Measured on a GPU only
where one is present; here the code paths are compared on the CPU."""
from __future__ import annotations

import shutil

import pytest
import torch

from drfkit.core.filter import kalman_step, kalman_step_unchecked
from drfkit.models import DeepRecursiveFilter
from drfkit.models.compiled import accelerated, compile_step, filter_loop, filter_step


def _covariance(b, n, gen):
    A = torch.randn(b, n, n, generator=gen)
    return A @ A.mT / n + 0.1 * torch.eye(n)


def _step_args(b=5, n=6, seed=0):
    g = torch.Generator().manual_seed(seed)
    return (torch.randn(b, n, generator=g), _covariance(b, n, g), torch.eye(n) + 0.1 * torch.randn(b, n, n, generator=g),
            torch.rand(b, n, generator=g) + 0.01, torch.randn(b, n, generator=g), torch.rand(b, n, generator=g) + 0.01)


def test_the_unchecked_step_is_the_checked_one_bit_for_bit_and_flags_a_failed_factorisation():
    args = _step_args()
    z, P, K, failed = kalman_step_unchecked(*args)
    for mine, theirs in zip((z, P, K), kalman_step(*args)):
        assert torch.equal(mine, theirs)
    assert failed.shape == (5,) and not failed.any()
    z0, P0, F, q, w, r = args
    r = r.clone()
    r[2] = -50.0  # S = P- + R far from positive definite in item 2 only
    *_, failed = kalman_step_unchecked(z0, P0, F, q, w, r)
    assert failed.tolist() == [False, False, True, False, False]
    with pytest.raises(ValueError, match="not positive definite"):
        kalman_step(z0, P0, F, q, w, r)


def _drf(seed=0, **kwargs):
    torch.manual_seed(seed)
    model = DeepRecursiveFilter("pendulum", latent=8, transition_hidden=16, **kwargs).eval()
    head = getattr(model.transition, "head", None)
    if head is not None:  # a transition that moves the state (an untrained one starts at F = I)
        with torch.no_grad():
            head.weight.normal_(0, 0.05)
    return model


def _observations(model, b=4, t=7, seed=1):
    g = torch.Generator().manual_seed(seed)
    w = torch.randn(b, t, model.latent, generator=g)
    r = torch.rand(b, t, model.latent, generator=g) * 0.5 + 0.05
    return w, r


@pytest.mark.parametrize("kwargs", [{}, {"transition_kind": "basis"}, {"memory_dims": 2}, {"constant_q": True}],
                         ids=["lstm", "basis", "memory", "constant_q"])
def test_the_loop_of_unchecked_steps_is_the_checked_loop(kwargs):
    model = _drf(**kwargs)
    w, r = _observations(model)
    with torch.no_grad():
        trace = model.filter_steps(w, r, return_gains=True)
        step = lambda *a: filter_step(model.transition, *a)  # noqa: E731
        z, p_diag, gains = filter_loop(step, model.transition, w, r, return_gains=True)
    assert torch.equal(z, trace["z"]) and torch.equal(p_diag, trace["p_diag"]) and torch.equal(gains, trace["gains"])


def test_the_captured_step_gives_the_checked_values_and_falls_back_on_a_failed_factorisation():
    model = _drf()
    w, r = _observations(model)
    with torch.no_grad():
        z, p_diag, _ = model.run_filter(w, r)
        model.compiled_step = compile_step(model.transition, backend="aot_eager")
        try:
            zc, pc, gc = model.run_filter(w, r)
            assert gc is None
            torch.testing.assert_close(zc, z, rtol=1e-6, atol=1e-6)
            torch.testing.assert_close(pc, p_diag, rtol=1e-6, atol=1e-6)
            bad = r.clone()
            bad[1, 3] = -100.0  # item 1's factorisation fails at step 3
            assert filter_loop(model.compiled_step, model.transition, w, bad) is None
            with pytest.raises(ValueError, match="not positive definite"):  # the checked loop's error
                model.run_filter(w, bad)
        finally:
            model.compiled_step = None


def test_training_never_takes_the_captured_step():
    model = _drf()
    w, r = _observations(model)
    model.compiled_step = lambda *a: pytest.fail("the captured step ran with gradients on")
    z, _, _ = model.run_filter(w.requires_grad_(), r)
    z.sum().backward()
    assert w.grad is not None


def test_accelerated_switches_a_filter_on_cuda_only_and_restores_it():
    drf = _drf()
    with accelerated(drf, "cpu"):
        assert drf.compiled_step is None
    with accelerated(drf, torch.device("cuda"), backend="aot_eager"):  # built lazily: nothing runs here
        assert callable(drf.compiled_step)
        first = drf.compiled_step
    assert drf.compiled_step is None
    with accelerated(drf, "cuda", backend="aot_eager"):
        assert drf.compiled_step is first  # one capture per model, kept for the next block
    lstm_free = torch.nn.Linear(2, 2)
    with accelerated(lstm_free, "cuda"):  # a model without the slot: untouched
        assert not hasattr(lstm_free, "compiled_step")


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None,
                    reason="inductor on the CPU needs a C compiler")
def test_inductor_code_for_the_step_agrees_with_the_eager_step():
    model = _drf()
    w, r = _observations(model, b=8, t=6)
    with torch.no_grad():
        z, p_diag, _ = model.run_filter(w, r)
        out = filter_loop(compile_step(model.transition, backend="inductor"), model.transition, w, r)
    assert out is not None
    torch.testing.assert_close(out[0], z, rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(out[1], p_diag, rtol=1e-5, atol=1e-5)
