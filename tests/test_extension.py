"""Adding a model is one file plus one registry line: here the "file" is a class defined in the test
and the "line" is its entry in ``MODEL_CLASSES`` and the pendulum study's ``kinds``, both made inside
the test (monkeypatched, so nothing outlives it). The new kind then goes through what every model
goes through -- training, evaluation, timing, a claim's verdict -- on tiny data, with no other file
touched. Likewise a noise kind: its meaning and its corruption of frames, registered in the test."""
from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest
import torch

from drfkit.models import MODEL_CLASSES, NoDynamics
from drfkit.study import bench, claims, registry, studies
from drfkit.study.evaluate import evaluate_study
from drfkit.study.params import for_notebook, load_profile


class ToyModel(NoDynamics):
    """A new per-frame model: the no_dynamics network under a new kind (what matters here is the
    wiring, not the model)."""

    kind = "toy"


@pytest.fixture
def toy_registered(monkeypatch, tmp_path):
    monkeypatch.setenv("DRF_RESULTS", str(tmp_path / "results"))
    monkeypatch.setitem(MODEL_CLASSES, "toy", ToyModel)
    entry = registry.STUDIES["pendulum"]
    monkeypatch.setitem(registry.STUDIES, "pendulum", dataclasses.replace(entry, kinds=entry.kinds + ("toy",)))
    values = load_profile("quick") | {
        "profile": "tiny", "pend_train_sequences": 4, "pend_val_sequences": 2, "pend_test_sequences": 2,
        "pend_seq_len": 6, "pend_epochs": 1, "pend_batch_size": 2, "seeds": [0], "pend_models": ["drf", "toy"],
        "pend_protocols": ["paper"]}
    return for_notebook("01_pendulum_training", values)


def test_a_model_kind_registered_in_the_test_trains_evaluates_is_timed_and_judged(toy_registered):
    P = toy_registered
    assert studies.study_models(P, "pendulum") == ["drf", "toy"]  # the profile's check reads the registry
    # training: checkpoints under the study's names, the config rebuilt from its stored form
    results = studies.train_models(P, "pendulum", progress=False)
    assert set(results) == {("drf", 0), ("toy", 0)}
    assert studies.checkpoint_stem(P, "pendulum", "toy", 0).name.startswith("pendulum-toy-seed0-")
    models = studies.trained_models(P, "pendulum")
    assert type(models[("toy", 0)]) is ToyModel
    curves = pd.read_csv(studies.tables_dir(P.profile) / f"{studies.curves_name('pendulum')}.csv")
    assert set(curves["model"]) == {"drf", "toy"}
    # evaluation at an out-of-distribution level, one row per (model, seed, dropout rate)
    evals = evaluate_study(P, "pendulum", [0.75], dropout_rates=[0.1, 0.3], models=models)
    assert set(evals["model"]) == {"drf", "toy"} and len(evals) == 4 and (evals["mae"] > 0).all()
    # timing: the benchmark times it in the default modes, with and without sampling
    assert "toy" in bench.STUDIES["pendulum"][2] and bench.MODES["toy"] == bench.DEFAULT_MODES
    timed = bench.build_timing_model("toy", "pendulum")
    frame = bench.example_frames("pendulum", 2)
    fn = bench.make_frame_fn(timed, "batched", frame, None, n_samples=3)
    assert all(t.shape == (2, 1, 2) for t in fn())
    # a claim: C5 with the new kind as the DRF's baseline, on its PICP-MPIW curve
    curves = evals.assign(study="pendulum")
    row = claims.c5_intervals_under_shift(curves, [("pendulum", 0.75)], {"pendulum": ["toy"]})
    table = claims.upsert(P.profile, [row], protocol="paper")
    assert row["verdict"] in claims.VERDICTS and "toy" in row["ours"]
    assert (table["id"] == "C5").sum() == 1


def test_an_unregistered_kind_is_named_in_the_error(toy_registered, monkeypatch):
    monkeypatch.delitem(MODEL_CLASSES, "toy")
    with pytest.raises(ValueError, match="unknown model kind 'toy'"):
        studies.model_config("pendulum", "toy", toy_registered)
    with pytest.raises(ValueError, match="protocol 'book' has no 'toy' model"):
        studies.train_config(toy_registered, "pendulum", "toy", 0, "book")
    assert torch.is_tensor(bench.example_frames("pendulum", 1))


def _gaussian_frames(clean, level, factor_rng, pixel_rng):
    """A toy noise kind: Gaussian pixel noise of standard deviation level x 255 on every frame."""
    noisy = clean + pixel_rng.normal(0.0, 255.0 * level, size=clean.shape)
    return np.clip(np.rint(noisy), 0, 255).astype(np.uint8), np.full(clean.shape[:2], level, np.float32)


def test_a_noise_kind_registered_in_the_test_makes_its_own_data_and_runs(monkeypatch, tmp_path):
    """A noise kind is its meaning (``NOISE_KINDS``) and how it corrupts frames (``FRAME_CORRUPTIONS``);
    a study that names it gets its own frames, caches and checkpoint names, and trains and evaluates."""
    from drfkit.data import noise as noise_module
    from drfkit.data import pendulum

    monkeypatch.setenv("DRF_RESULTS", str(tmp_path / "results"))
    monkeypatch.setitem(noise_module.NOISE_KINDS, "toy_gaussian", "std of Gaussian pixel noise / 255")
    monkeypatch.setitem(pendulum.FRAME_CORRUPTIONS, "toy_gaussian", _gaussian_frames)
    entry = dataclasses.replace(registry.STUDIES["pendulum"], name="pendulum_gaussian", noise_kind="toy_gaussian")
    monkeypatch.setitem(registry.STUDIES, "pendulum_gaussian", entry)
    values = load_profile("quick") | {
        "profile": "tiny", "pend_train_sequences": 4, "pend_val_sequences": 2, "pend_test_sequences": 2,
        "pend_seq_len": 6, "pend_epochs": 1, "pend_batch_size": 2, "seeds": [0], "pend_models": ["no_dynamics"],
        "pend_protocols": ["paper"]}
    P = for_notebook("01_pendulum_training", values)
    gaussian, benchmark = (studies.study_data(P, s, "test", 0.3) for s in ("pendulum_gaussian", "pendulum"))
    assert not torch.equal(gaussian.inputs, benchmark.inputs) and torch.equal(gaussian.targets, benchmark.targets)
    frames = pendulum.generate_pendulum(2, 6, noise_module.Noise("toy_gaussian", 0.3), seed=P.pendulum.data_seed + 2)
    assert np.array_equal(gaussian.inputs.numpy(), frames["images"])  # the registered corruption made them
    assert studies.study_data_key(P, "pendulum_gaussian")["noise_kind"] == "toy_gaussian"
    assert "noise_kind" not in studies.study_data_key(P, "pendulum")  # the benchmark's runs keep their names
    results = studies.train_models(P, "pendulum_gaussian", progress=False)
    assert results[("no_dynamics", 0)].best_path.name.startswith("pendulum_gaussian-no_dynamics-seed0-")
    evals = evaluate_study(P, "pendulum_gaussian", [0.3, 0.6])
    assert set(evals["noise"]) == {0.3, 0.6} and (evals["mae"] > 0).all()
    with pytest.raises(ValueError, match="no corruption of pendulum frames for salt_and_pepper"):
        pendulum.generate_pendulum(2, 6, noise_module.Noise("salt_and_pepper", 0.1), seed=0)
