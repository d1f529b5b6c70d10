"""Known answers through the evaluation path: a stub prediction with fixed mean, aleatoric and
epistemic parts and a padded mask goes through ``evaluate_model_rates``; every metric is checked
against a value computed here by hand from the TOTAL sigma. Handing the metrics ``pred.aleatoric``
(or ignoring the mask) fails this."""
import math

import numpy as np
import pytest
import torch

import drfkit.uncertainty as unc
from drfkit.evaluate import evaluate_model_rates
from drfkit.train import SequenceData

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
                          dropout_p=0.1)
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
