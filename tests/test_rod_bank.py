"""The rod bank: every frame the renderer draws, keyed by the rod's integer tip, equal to PIL's drawing."""
import numpy as np

from drfkit.data import pendulum as pend
from drfkit.data.rod_bank import rod_bank, rod_keys


def test_bank_renders_exactly_what_pil_draws():
    rng = np.random.default_rng(3)
    theta = np.concatenate([rng.uniform(-np.pi, np.pi, 1500), [0.0, np.pi / 2, -np.pi, np.pi - 1e-9]])
    assert np.array_equal(pend.render_pendulum(theta), pend.render_pendulum_pil(theta))


def test_a_frame_depends_on_the_integer_tip_alone():
    bank = rod_bank()
    rng = np.random.default_rng(4)
    j = rng.integers(0, len(bank), 20)
    # angles of the same tip: nudge an angle that draws image j by far less than a pixel
    centre = np.arctan2(bank.arc_mean[j, 1], bank.arc_mean[j, 0])
    for th in centre:
        keys = rod_keys(np.array([th, th + 1e-7]), pend.CANVAS_PIVOT, pend.ROD_LENGTH_PX)
        if keys[0] == keys[1]:
            a, b = pend.render_pendulum_pil(np.array([th, th + 1e-7]))
            assert np.array_equal(a, b)


def test_bank_covers_the_circle_once():
    bank = rod_bank()
    assert 400 <= len(bank) <= 460
    assert abs(bank.arc_weight.sum() - 1.0) < 1e-12
    assert np.all(np.abs(np.linalg.norm(bank.arc_mean, axis=1) - 1.0) < 1e-3)  # short arcs: means near the circle
    # a tip outside the bank falls back to PIL (the index says -1 there)
    assert bank.index[0] == -1
    out = pend.render_pendulum(np.array([[0.1, 0.2], [0.3, 0.4]]))
    assert out.shape == (2, 2, 24, 24) and out.dtype == np.uint8
