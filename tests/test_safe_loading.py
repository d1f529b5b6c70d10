"""Loading never executes code: a checkpoint, a resume state, a prediction-cache entry and a
measurement-cache entry carrying an ``os.system`` payload are refused (or ignored as foreign data)
and the payload never runs. Each of these fails on a loader that calls ``torch.load(...,
weights_only=False)`` or ``pickle.loads``: the marker file would be written."""
from __future__ import annotations

import glob
import os
import pickle

import pytest
import torch

import drfkit.book.measurements as measurements
from drfkit.util.io import UnsafeArtefactError, torch_load_checked
from drfkit.models import build_model, default_config
from drfkit.util.paths import REPO_ROOT
from drfkit.methods.predictions import cached_predict_rates, prediction_key
from drfkit.methods.train import SequenceData, TrainConfig, load_checkpoint, train_model


class Payload:
    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return os.system, (f"touch {self.marker}",)


def crafted(path, marker, **extra):
    torch.save({"config": {"kind": "drf"}, "state_dict": {}, "format": 1, "payload": Payload(marker)} | extra, path)
    return path


def test_a_crafted_checkpoint_is_refused_and_runs_nothing(tmp_path):
    marker = tmp_path / "ran"
    path = crafted(tmp_path / "evil-best.pt", marker)
    with pytest.raises(UnsafeArtefactError, match=r"refused to load .*evil-best\.pt.*nothing in it was run"):
        load_checkpoint(path)
    assert not marker.exists()


def test_a_crafted_resume_state_is_refused_and_runs_nothing(tmp_path):
    marker = tmp_path / "ran"
    images = torch.zeros(4, 6, 24, 24, dtype=torch.uint8)
    data = SequenceData(images, torch.zeros(4, 6, 2))
    crafted(tmp_path / "run-last.pt", marker, fingerprint="x")
    with pytest.raises(UnsafeArtefactError, match="run-last.pt"):
        train_model(default_config("drf", "pendulum", 2), data, data,
                    TrainConfig(epochs=1, lr=1e-3, batch_size=2, seed=0), tmp_path / "run", progress=False)
    assert not marker.exists()


def test_a_crafted_prediction_cache_entry_is_refused_and_runs_nothing(tmp_path):
    marker = tmp_path / "ran"
    torch.manual_seed(0)
    model = build_model(default_config("drf", "keypoints", 1)).eval()
    x = torch.rand(2, 3, 17, 3)
    key = prediction_key(model, x, 4, [model.default_dropout_p], 0, None, None)
    torch.save({"format": 1, "predictions": [Payload(marker)]}, tmp_path / f"{key}.pt")
    with pytest.raises(UnsafeArtefactError, match=key):
        cached_predict_rates(model, x, cache=tmp_path, n_samples=4, dropout_rates=[None], seed=0)
    assert not marker.exists()


def test_a_crafted_measurement_cache_entry_is_never_unpickled(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("DRF_RESULTS", str(tmp_path))
    monkeypatch.setenv(measurements.REMEASURE_ENV, "")
    marker = tmp_path / "ran"

    def study(n):
        return {"n": n}

    measurements.cached("p", study, 3, timing=False)
    (entry,) = measurements.measurements_dir("p").glob("study-*.json")
    entry.write_bytes(pickle.dumps({"format": measurements.FORMAT, "fn": "x", "value": Payload(marker)}))
    assert measurements.cached("p", study, 3, timing=False) == {"n": 3}  # computed again, not unpickled
    assert not marker.exists()
    assert "not a data-only entry" in capsys.readouterr().err


def test_every_committed_checkpoint_loads_through_the_safe_path():
    paths = sorted(glob.glob(str(REPO_ROOT / "results" / "paper" / "models" / "*.pt")))
    assert paths, "the paper profile's checkpoints are committed"
    for path in paths:
        state = torch_load_checked(path)
        assert isinstance(state, dict)
        if path.endswith("-best.pt"):
            load_checkpoint(path)
