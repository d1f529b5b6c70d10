"""Tests for drfkit.methods.uncertainty: shapes, the once-only deterministic pass, exact zero
epistemic spread without dropout, the summary formulas, intervals and argument checks."""
from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from drfkit.data.noise import Noise
from drfkit.models import build_model, default_config
from drfkit.methods.uncertainty import Prediction, intervals, predict, predict_rates, summarise_samples

torch.set_num_threads(1)

ALL_CASES = [(k, ik) for k in ("drf", "no_dynamics", "lstm") for ik in ("pendulum", "keypoints")] \
    + [("monoloco", "keypoints")]


def make(kind: str, input_kind: str, **overrides):
    torch.manual_seed(0)
    return build_model(default_config(kind, input_kind, 2 if input_kind == "pendulum" else 1, **overrides))


def numpy_inputs(input_kind: str, b: int = 5, t: int = 4, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    if input_kind == "pendulum":
        return rng.integers(0, 256, (b, t, 24, 24), dtype=np.uint8)
    kp = rng.normal(size=(b, t, 17, 3)).astype(np.float32)
    kp[..., 2] = rng.uniform(size=(b, t, 17))
    return kp


@pytest.mark.parametrize("kind,input_kind", ALL_CASES)
def test_predict_shapes_and_consistency(kind, input_kind):
    model = make(kind, input_kind)
    pred = predict(model, numpy_inputs(input_kind), n_samples=6, return_gains=True)
    out = 2 if input_kind == "pendulum" else 1
    for field in (pred.mean, pred.aleatoric, pred.epistemic, pred.total):
        assert isinstance(field, torch.Tensor) and field.shape == (5, 4, out)
        assert field.device.type == "cpu" and field.dtype == torch.float32
    assert (pred.epistemic > 0).all() and (pred.aleatoric > 0).all()
    assert torch.allclose(pred.total ** 2, pred.aleatoric ** 2 + pred.epistemic ** 2, rtol=1e-5)
    if kind == "drf":
        assert pred.gains.shape == (5, 4, 30, 30)
        assert torch.equal(pred.gains[:, 0], torch.eye(30).expand(5, 30, 30))
    else:
        assert pred.gains is None
    assert pred.n_samples == 6 and pred.dropout_p == model.default_dropout_p


def test_deterministic_part_runs_once_for_all_samples():
    model = make("drf", "pendulum")
    calls = {"encoder": 0, "transition": 0, "filter": 0}
    model.encoder.register_forward_hook(lambda *a: calls.__setitem__("encoder", calls["encoder"] + 1))
    model.transition.register_forward_hook(
        lambda *a: calls.__setitem__("transition", calls["transition"] + 1))
    run_filter = model.run_filter

    def counted(*args, **kwargs):
        calls["filter"] += 1
        return run_filter(*args, **kwargs)

    model.run_filter = counted
    pred = predict(model, numpy_inputs("pendulum", b=5, t=4), n_samples=25)
    assert pred.epistemic.shape == (5, 4, 2)
    assert calls == {"encoder": 1, "filter": 1, "transition": 3}  # T - 1 steps, once

    calls.update(encoder=0, filter=0, transition=0)
    predict(model, numpy_inputs("pendulum", b=5, t=4), n_samples=25, batch_size=2)
    assert calls == {"encoder": 3, "filter": 3, "transition": 9}  # chunks of 2, 2, 1


@pytest.mark.parametrize("kind,mc_mode", [("drf", None), ("no_dynamics", None), ("lstm", None),
                                          ("monoloco", "batched"), ("monoloco", "sequential")])
def test_zero_dropout_gives_exactly_zero_epistemic(kind, mc_mode):
    model = make(kind, "keypoints", **({"mc_mode": mc_mode} if mc_mode else {}))
    x = numpy_inputs("keypoints")
    pred = predict(model, x, n_samples=25, dropout_p=0.0)
    assert torch.equal(pred.epistemic, torch.zeros_like(pred.epistemic))
    det = predict(model, x, n_samples=0)
    assert torch.equal(det.epistemic, torch.zeros_like(det.epistemic)) and det.dropout_p == 0.0
    assert torch.allclose(pred.mean, det.mean, atol=1e-6) and torch.allclose(pred.total, det.total, atol=1e-6)
    with torch.no_grad():
        mean, sigma = model.eval()(torch.from_numpy(x))
    assert torch.equal(det.mean, mean) and torch.equal(det.aleatoric, sigma)


def test_summarise_samples_known_answer():
    means = torch.tensor([[1.0], [3.0], [2.0], [2.0]])
    sigmas = torch.tensor([[1.0], [1.0], [3.0], [1.0]])
    mean, aleatoric, epistemic, total = summarise_samples(means, sigmas)
    assert mean.item() == pytest.approx(2.0)
    assert epistemic.item() == pytest.approx(math.sqrt(0.5))  # population std of 1, 3, 2, 2
    assert aleatoric.item() == pytest.approx(math.sqrt(3.0))  # sqrt(mean(1, 1, 9, 1))
    assert total.item() == pytest.approx(math.sqrt(3.5))
    with pytest.raises(ValueError, match="share a shape"):
        summarise_samples(means, sigmas[:2])


def test_rates_share_one_draw_and_each_equals_its_own_prediction():
    """predict_rates draws the masks' uniforms once per chunk: each rate's prediction is the one
    ``predict`` gives at that rate from the same seed, and the masks are nested across rates."""
    model = make("drf", "keypoints")
    x = numpy_inputs("keypoints", b=3, t=5)
    torch.manual_seed(4)
    both = predict_rates(model, x, n_samples=6, dropout_rates=[0.1, 0.4])
    for pred, p in zip(both, (0.1, 0.4)):
        torch.manual_seed(4)
        alone = predict(model, x, n_samples=6, dropout_p=p)
        for field in ("mean", "aleatoric", "epistemic", "total"):
            assert torch.equal(getattr(pred, field), getattr(alone, field)), (p, field)
    assert not torch.equal(both[0].epistemic, both[1].epistemic)


def test_mc_equals_the_sequential_definition_for_the_same_masks():
    """predict's batched pass == S separate dropout passes drawing the same masks."""
    model = make("lstm", "keypoints")
    x = numpy_inputs("keypoints", b=3, t=5)
    torch.manual_seed(11)
    pred = predict(model, x, n_samples=8, dropout_p=0.3)
    torch.manual_seed(11)
    with torch.no_grad():
        h, _ = model.eval().features(torch.from_numpy(x))
        hidden = model.decoder.hidden(h)
        masks = (torch.rand((8, *hidden.shape)) >= 0.3) / 0.7
        outs = [model.decoder.readout(hidden * masks[s]) for s in range(8)]
    means = torch.stack([m for m, _ in outs])
    sigmas = torch.stack([s for _, s in outs])
    assert torch.allclose(pred.mean, means.mean(0), atol=1e-6)
    assert torch.allclose(pred.epistemic, means.std(0, correction=0), atol=1e-6)
    assert torch.allclose(pred.aleatoric, sigmas.pow(2).mean(0).sqrt(), atol=1e-6)


def test_monoloco_batched_and_sequential_predictions_agree_in_distribution():
    x = numpy_inputs("keypoints", b=2, t=2)
    torch.manual_seed(0)
    batched = predict(make("monoloco", "keypoints"), x, n_samples=400)
    torch.manual_seed(1)
    sequential = predict(make("monoloco", "keypoints", mc_mode="sequential"), x, n_samples=400)
    se = batched.epistemic / math.sqrt(200)
    assert ((batched.mean - sequential.mean).abs() < 4 * se).all()
    assert torch.allclose(batched.epistemic, sequential.epistemic, rtol=0.25)


def test_chunking_numpy_and_tensor_inputs_agree():
    model = make("drf", "keypoints")
    x = numpy_inputs("keypoints", b=5)
    whole = predict(model, x, n_samples=0, return_gains=True)
    chunked = predict(model, torch.from_numpy(x), n_samples=0, batch_size=2, return_gains=True)
    for a, b in ((whole.mean, chunked.mean), (whole.total, chunked.total), (whole.gains, chunked.gains)):
        assert torch.allclose(a, b, atol=1e-6)
    as_double = predict(model, x.astype(np.float64), n_samples=0)  # cast to float32 inside
    assert torch.allclose(as_double.mean, whole.mean, atol=1e-6)


def test_predict_restores_mode_and_does_not_track_gradients():
    model = make("no_dynamics", "pendulum").train()
    pred = predict(model, numpy_inputs("pendulum"), n_samples=3)
    assert model.training and not pred.mean.requires_grad
    model.eval()
    predict(model, numpy_inputs("pendulum"), n_samples=3)
    assert not model.training


def test_dropout_rate_controls_the_spread():
    model = make("no_dynamics", "keypoints")
    x = numpy_inputs("keypoints", b=4, t=5)
    torch.manual_seed(0)
    low = predict(model, x, n_samples=200, dropout_p=0.05)
    torch.manual_seed(0)
    high = predict(model, x, n_samples=200, dropout_p=0.5)
    assert high.epistemic.mean() > 2 * low.epistemic.mean()
    assert high.dropout_p == 0.5


def test_intervals_are_95_percent_gaussian():
    pred = Prediction(mean=torch.tensor([[[1.0]]]), aleatoric=torch.tensor([[[0.6]]]),
                      epistemic=torch.tensor([[[0.8]]]), total=torch.tensor([[[1.0]]]),
                      n_samples=2, dropout_p=0.1, point=torch.tensor([[[1.0]]]))
    lower, upper = intervals(pred)
    assert lower.item() == pytest.approx(1.0 - 1.959964, abs=1e-5)
    assert upper.item() == pytest.approx(1.0 + 1.959964, abs=1e-5)
    lower68, upper68 = intervals(pred, level=0.6826895)
    assert (upper68 - lower68).item() == pytest.approx(2.0, abs=1e-4)


@pytest.mark.parametrize("kwargs,error,match", [
    ({"n_samples": -1}, ValueError, "n_samples"),
    ({"n_samples": 2.5}, ValueError, "n_samples"),
    ({"n_samples": True}, ValueError, "n_samples"),
    ({"dropout_p": 1.0}, ValueError, "dropout_p"),
    ({"dropout_p": -0.2}, ValueError, "dropout_p"),
    ({"batch_size": 0}, ValueError, "batch_size"),
])
def test_predict_rejects_bad_arguments(kwargs, error, match):
    with pytest.raises(error, match=match):
        predict(make("no_dynamics", "keypoints"), numpy_inputs("keypoints"), **kwargs)


def test_predict_rejects_bad_inputs():
    pend = make("no_dynamics", "pendulum")
    with pytest.raises(ValueError, match="24, 24"):
        predict(pend, np.zeros((2, 3, 32, 32), dtype=np.uint8))
    with pytest.raises(TypeError, match="uint8"):
        predict(pend, np.zeros((2, 3, 24, 24), dtype=np.int16))
    kp = make("drf", "keypoints")
    with pytest.raises(ValueError, match="17, 3"):
        predict(kp, np.zeros((2, 3, 17, 2), dtype=np.float32))
    with pytest.raises(TypeError, match="float32"):
        predict(kp, np.zeros((2, 3, 17, 3), dtype=np.int64))
    with pytest.raises(TypeError, match="numpy array or torch tensor"):
        predict(kp, [[0.0]])
    with pytest.raises(ValueError, match="B = 0"):
        predict(kp, np.zeros((0, 3, 17, 3), dtype=np.float32))


def test_predict_rates_shares_the_filter_and_matches_single_rate_predictions():
    from drfkit.methods.uncertainty import predict_rates

    model = make("drf", "pendulum")
    calls = {"filter": 0}
    run_filter = model.run_filter

    def counted(*args, **kwargs):
        calls["filter"] += 1
        return run_filter(*args, **kwargs)

    model.run_filter = counted
    x = numpy_inputs("pendulum", b=3, t=5)
    torch.manual_seed(7)
    many = predict_rates(model, x, n_samples=10, dropout_rates=[0.0, 0.3, None])
    assert calls["filter"] == 1 and [p.dropout_p for p in many] == [0.0, 0.3, model.default_dropout_p]
    assert torch.equal(many[0].epistemic, torch.zeros_like(many[0].epistemic))
    torch.manual_seed(7)
    first = predict(model, x, n_samples=10, dropout_p=0.0)
    torch.testing.assert_close(first.mean, many[0].mean)
    # the second rate draws the masks that follow the first rate's (none at p = 0)
    torch.manual_seed(7)
    second = predict(model, x, n_samples=10, dropout_p=0.3)
    torch.testing.assert_close(second.mean, many[1].mean)
    torch.testing.assert_close(second.epistemic, many[1].epistemic)


@pytest.mark.parametrize("kind,input_kind", [("drf", "pendulum"), ("drf", "keypoints")])
def test_predict_rejects_nan_inputs(kind, input_kind):
    model = make(kind, input_kind)
    x = numpy_inputs(input_kind).astype(np.float32) / (255.0 if input_kind == "pendulum" else 1.0)
    x[0, 0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        predict(model, x, n_samples=2)


def test_compare_prediction_modes_deterministic_has_no_epistemic_part():
    import torch

    from drfkit.data.pendulum import generate_pendulum
    from drfkit.study.evaluate import compare_prediction_modes, prediction_metrics
    from drfkit.models import build_model, default_config
    from drfkit.methods.train import SequenceData
    from drfkit.methods.uncertainty import predict

    arrays = generate_pendulum(3, 7, Noise("rkn_uniform", 0.5), seed=1)
    data = SequenceData(torch.from_numpy(arrays["images"]), torch.from_numpy(arrays["targets"]))
    torch.manual_seed(0)
    model = build_model(default_config("no_dynamics", "pendulum", 2)).eval()
    model.checkpoint_meta = {"epoch": 7}
    table = compare_prediction_modes({"best": model}, data, n_samples=5, seed=3)
    assert table["mode"].tolist() == ["deterministic", "mc_dropout"] and (table["epoch"] == 7).all()
    det = predict(model, data.inputs, n_samples=0)  # dropout off: total sigma is the aleatoric one
    expected = prediction_metrics(det.mean, det.aleatoric, data.targets)
    assert table.iloc[0]["nll"] == expected["nll"] and table.iloc[0]["mae"] == expected["mae"]
    assert table.iloc[1]["mpiw"] > table.iloc[0]["mpiw"]  # the dropout spread widens the intervals
