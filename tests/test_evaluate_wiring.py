"""Known answers through the evaluation path: a stub prediction with fixed mean, aleatoric and
epistemic parts and a padded mask goes through ``evaluate_model_rates``; every metric is checked
against a value computed here by hand from the TOTAL sigma. Handing the metrics ``pred.aleatoric``
(or ignoring the mask) fails this."""
from drfkit.study.profile import build_profile
import math

import numpy as np
import pytest
import torch

import drfkit.methods.uncertainty as unc
from drfkit.study.evaluate import evaluate_model_rates
from drfkit.methods.train import SequenceData

Z975 = 1.959963984540054  # the 97.5 % quantile of N(0, 1)


def _phi(x):
    return math.exp(-0.5 * x * x) / math.sqrt(2 * math.pi)


def _cdf(x):
    return 0.5 * (1 + math.erf(x / math.sqrt(2)))


def test_metrics_of_a_stub_prediction_use_the_total_sigma_and_the_mask(monkeypatch):
    # 2 sequences x 3 frames x 1 output; the last frame of sequence 1 is padding
    mean = torch.tensor([[[0.0], [1.0], [2.0]], [[0.5], [0.0], [9.0]]])
    aleatoric = torch.full_like(mean, 0.3)
    epistemic = torch.full_like(mean, 0.4)
    total = torch.sqrt(aleatoric ** 2 + epistemic ** 2)  # 0.5
    targets = torch.tensor([[[0.1], [1.5], [2.0]], [[0.0], [-1.2], [100.0]]])
    mask = torch.tensor([[True, True, True], [True, True, False]])
    pred = unc.Prediction(mean=mean, aleatoric=aleatoric, epistemic=epistemic, total=total, n_samples=8,
                          dropout_p=0.1, point=mean)
    monkeypatch.setattr(unc, "predict_rates", lambda *a, **k: [pred])
    data = SequenceData(torch.zeros(2, 3, 17, 3), targets, mask)
    (m,) = evaluate_model_rates(None, data, n_samples=8, dropout_rates=[0.1])

    err = [0.1, 0.5, 0.0, 0.5, 1.2]  # |y - mu| on the five real frames
    s = 0.5
    assert m["mae"] == pytest.approx(np.mean(err))
    assert m["picp"] == pytest.approx(np.mean([e <= Z975 * s for e in err]))  # 1.2 > 0.98: 4 of 5 inside
    assert m["picp"] == pytest.approx(0.8)
    assert m["mpiw"] == pytest.approx(2 * Z975 * s)
    nll = np.mean([math.log(s) + 0.5 * math.log(2 * math.pi) + 0.5 * (e / s) ** 2 for e in err])
    assert m["nll"] == pytest.approx(nll)
    crps = np.mean([s * ((e / s) * (2 * _cdf(e / s) - 1) + 2 * _phi(e / s) - 1 / math.sqrt(math.pi)) for e in err])
    assert m["crps"] == pytest.approx(crps)
    assert m["aleatoric"] == pytest.approx(0.3) and m["epistemic"] == pytest.approx(0.4)


def _stub_study(monkeypatch, tmp_path):
    """evaluate_study / calibration_points on one stub model and a padded data set, with the
    prediction fixed (mean, aleatoric 0.3, epistemic 0.4: total 0.5)."""
    import types

    import drfkit.study.evaluate as ev
    from drfkit.study import studies

    mean = torch.tensor([[[0.0], [1.0], [2.0]], [[0.5], [0.0], [9.0]]])
    targets = torch.tensor([[[0.1], [1.5], [2.0]], [[0.0], [-1.2], [100.0]]])
    mask = torch.tensor([[True, True, True], [True, True, False]])
    pred = unc.Prediction(mean=mean, aleatoric=torch.full_like(mean, 0.3), epistemic=torch.full_like(mean, 0.4),
                          total=torch.full_like(mean, 0.5), n_samples=8, dropout_p=0.1, point=mean)
    monkeypatch.setattr(ev, "cached_predict_rates", lambda *a, **k: [pred] * len(k["dropout_rates"]))
    monkeypatch.setattr(studies, "study_data", lambda P, study, split, noise: SequenceData(
        torch.zeros(2, 3, 17, 3), targets, mask))
    monkeypatch.setattr(studies, "pick_device", lambda device: torch.device("cpu"))
    monkeypatch.setenv("DRF_RESULTS", str(tmp_path))
    P = build_profile(dict(n_samples=8, interval_level=0.95, profile="stub", device="cpu"), "a test")
    model = types.SimpleNamespace(default_dropout_p=0.1)
    return P, {("drf", 0): model}


def test_evaluate_study_rows_carry_the_total_sigma_metrics(monkeypatch, tmp_path):
    from drfkit.study.evaluate import evaluate_study

    P, models = _stub_study(monkeypatch, tmp_path)
    rows = evaluate_study(P, "pedestrians", [0.01, 0.05], models=models)
    assert len(rows) == 2 and set(rows["noise"]) == {0.01, 0.05} and (rows["dropout_p"] == 0.1).all()
    err = np.array([0.1, 0.5, 0.0, 0.5, 1.2])
    assert rows["mae"].tolist() == pytest.approx([err.mean()] * 2)
    assert rows["picp"].tolist() == pytest.approx([0.8] * 2)
    assert rows["mpiw"].tolist() == pytest.approx([2 * Z975 * 0.5] * 2)


def test_a_sweep_level_on_fewer_sequences_is_scored_on_its_first_ones_and_says_so(monkeypatch, tmp_path):
    """``sequences`` (level -> N) scores that level on the first N test sequences and records N; other levels keep
    every sequence, and the calibration pass asks for the evaluation's batch size (one cache entry for both)."""
    from drfkit.study import evaluate as ev

    P, models = _stub_study(monkeypatch, tmp_path)
    seen = []
    real = ev.cached_predict_rates
    monkeypatch.setattr(ev, "cached_predict_rates", lambda model, x, **k: seen.append((x.shape[0], k["batch_size"]))
                        or real(model, x, **k))  # the stub's prediction: what reaches it is what is checked
    rows = ev.evaluate_study(P, "pedestrians", [0.01, 0.05], models=models, sequences={0.05: 1}).set_index("noise")
    assert rows.loc[0.01, "sequences"] == 2 and rows.loc[0.05, "sequences"] == 1
    ev.calibration_points(P, "pedestrians", [0.05], models=models)
    assert seen[0][0] == 2 and seen[1][0] == 1 and {b for _, b in seen} == {ev.EVAL_BATCH_SIZE}
    data = SequenceData(torch.zeros(3, 2, 1), torch.zeros(3, 2, 1))
    assert ev.first_sequences(data, None) is data and ev.first_sequences(data, 5) is data
    assert len(ev.first_sequences(data, 2)) == 2
    with pytest.raises(ValueError, match="at least one"):
        ev.first_sequences(data, 0)


def test_calibration_points_count_standardised_residuals_of_the_total_sigma(monkeypatch, tmp_path):
    """Residuals / total sigma on the real frames: 0.2, 1.0, 0.0, -1.0, -2.4; at the 50 % level the
    observed fraction at or below the median is 3/5, at 95 % (z 1.645) all five."""
    from drfkit.study.evaluate import calibration_points

    P, models = _stub_study(monkeypatch, tmp_path)
    cal = calibration_points(P, "pedestrians", [0.05], models=models).set_index("expected")["observed"]
    assert cal.loc[0.5] == pytest.approx(3 / 5)
    assert cal.loc[0.95] == pytest.approx(1.0)
    assert cal.loc[0.05] == pytest.approx(1 / 5)  # only -2.4 is below z(0.05) = -1.645


def test_a_models_reported_mae_is_its_dropout_off_mae_and_its_intervals_are_mc_dropouts():
    # a real model with a heavy dropout rate, so that the MC mean and the dropout-off pass differ
    from drfkit.core.metrics import mae, picp
    from drfkit.models import build_model, default_config

    torch.manual_seed(0)
    model = build_model(default_config("no_dynamics", "pendulum", 2, dropout_p=0.5)).eval()
    x = torch.randint(0, 256, (4, 6, 24, 24), dtype=torch.uint8, generator=torch.Generator().manual_seed(1))
    y = torch.randn(4, 6, 2) * 0.1
    data = SequenceData(x, y)
    (m,) = evaluate_model_rates(model, data, n_samples=5, dropout_rates=[None], seed=3, cache=None)
    with torch.no_grad():
        point, _ = model(x)
    assert m["mae"] == pytest.approx(mae(y.numpy(), point.numpy()), rel=1e-6)
    torch.manual_seed(3)
    pred = unc.predict(model, x, n_samples=5)
    assert torch.equal(pred.point, point)
    assert mae(y.numpy(), pred.mean.numpy()) != pytest.approx(m["mae"], rel=1e-3)  # the MC mean would differ
    lower, upper = unc.intervals(pred)
    assert m["picp"] == pytest.approx(picp(y.numpy(), lower.numpy(), upper.numpy()))
