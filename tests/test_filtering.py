"""The recursive filter's loop shared by the DRF and the known-dynamics filter (drfkit.models.filtering): on a
scalar linear system with a known answer, the shapes it stacks, and both models' loops and streams agreeing."""
import math

import pytest
import torch

from drfkit.models import build_model, default_config
from drfkit.models.filtering import run_filter_loop, stack_steps


def test_a_scalar_random_walk_filter_gives_the_closed_form_posterior():
    """x_t = x_{t-1} + v, v ~ N(0, q); w_t = x_t + e, e ~ N(0, r). With P_0 = r and q = r the variances follow
    P_t = (P_{t-1} + q) r / (P_{t-1} + q + r): 1, 2/3, 5/8, ... (r = 1), and the mean is the gain-weighted blend."""
    q, r = 1.0, 1.0

    def start(w0, r0):
        return (w0, r0), {"x": w0, "p": r0}

    def step(carry, w_t, r_t):
        x, p = carry
        prior = p + q
        k = prior / (prior + r_t)
        x, p = x + k * (w_t - x), (1 - k) * prior
        return (x, p), {"x": x, "p": p, "k": k}

    w = torch.tensor([[[0.0], [1.0], [3.0], [2.0]]])
    first, steps = run_filter_loop(start, step, w, torch.full_like(w, r))
    p = stack_steps(steps, "p", w.new_empty(1, 0, 1), first["p"])[0, :, 0]
    x = stack_steps(steps, "x", w.new_empty(1, 0, 1), first["x"])[0, :, 0]
    assert p.tolist() == pytest.approx([1.0, 2 / 3, 5 / 8, 13 / 21])
    assert x[1].item() == pytest.approx(2 / 3 * 1.0) and x[2].item() == pytest.approx(2 / 3 + 5 / 8 * (3 - 2 / 3))
    assert stack_steps(steps, "k", w.new_empty(1, 0, 1)).shape == (1, 3, 1)      # steps only: t = 1..T-1
    one, none = run_filter_loop(start, step, w[:, :1], w[:, :1])
    assert none == {} and stack_steps(none, "k", w.new_empty(1, 0, 1)).shape == (1, 0, 1)
    with pytest.raises(ValueError, match=r"\(B, T, m\)"):
        run_filter_loop(start, step, w[0], w[0])


@pytest.mark.parametrize("kind", ["drf", "known_dynamics", "drf_calibrated"])
def test_each_filters_loop_and_its_stream_compute_the_same_values(kind):
    torch.manual_seed(0)
    model = build_model(default_config(kind, "pendulum", 2)).eval()
    x = torch.randint(0, 256, (3, 6, 24, 24), dtype=torch.uint8, generator=torch.Generator().manual_seed(1))
    with torch.no_grad():
        h_loop, _ = model.features(x)
        carry, streamed = model.initial_carry(x[:, :1]), []
        for t in range(1, x.shape[1]):
            h, carry = model.stream_step(x[:, t:t + 1], carry)
            streamed.append(h)
    # the encoder sees one frame at a time when streaming: float rounding of a different batch, no more
    assert torch.allclose(torch.cat(streamed, 1), h_loop[:, 1:], atol=1e-5, rtol=0)
    assert math.isfinite(float(h_loop.sum()))
