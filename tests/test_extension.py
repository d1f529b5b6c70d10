"""Adding a model is one file plus one registry line: here the "file" is a class defined in the test
and the "line" is its entry in ``MODEL_CLASSES`` and the pendulum study's ``kinds``, both made inside
the test (monkeypatched, so nothing outlives it). The new kind then goes through what every model
goes through -- training, evaluation, timing, a claim's verdict -- on tiny data, with no other file
touched. Likewise a noise kind: its meaning and its corruption of frames, registered in the test.

What a model can do beyond the interface is what its class declares (``drfkit.models.sequence``), never
its kind's name: a new filter that declares ``competency_gain`` is gated and one that does not is not; a
model that declares ``one_node_recursion`` has its recursion timed. What a study is judged by is its
registry entry's (``Study.gating_claim``, its section's kinds and protocols), never its name."""
from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest
import torch

from drfkit.methods import gating
from drfkit.models import MODEL_CLASSES, DeepRecursiveFilter, KnownDynamicsFilter, NoDynamics, default_config
from drfkit.models.parts import mean_and_log_variance
from drfkit.study import bench, claims, gating_study, registry, studies
from drfkit.study.evaluate import evaluate_study
from drfkit.study.params import ParameterError, allowed_text, for_notebook, load_profile


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


class ToyFilter(NoDynamics):
    """A new filter: each latent dim a random walk, filtered by a scalar Kalman filter on the encoder's w_t, r_t
    (z_t = z_{t-1} + k_t (w_t - z_{t-1}), k_t = P- / (P- + r_t), P- = P_{t-1} + q). Its gains diag(k_t) act on
    its state, so it declares ``competency_gain``: gating runs on it as on the DRF, with no other file touched."""

    kind = "toy_filter"
    per_frame = False
    competency_gain = True
    q = 0.01

    def features(self, inputs, return_gains=False):
        w, r = self.observe(inputs)
        z, p = w[:, 0], r[:, 0]
        zs, ps, ks = [z], [p], [torch.ones_like(p)]
        for t in range(1, w.shape[1]):
            prior = p + self.q
            k = prior / (prior + r[:, t])
            z, p = z + k * (w[:, t] - z), (1 - k) * prior
            zs.append(z), ps.append(p), ks.append(k)
        h = mean_and_log_variance(torch.stack(zs, 1), torch.stack(ps, 1))
        return h, torch.diag_embed(torch.stack(ks, 1)) if return_gains else None


class ToyRecursive(DeepRecursiveFilter):
    """A new kind built on the DRF's filter: it inherits the DRF's declarations (``competency_gain``,
    ``one_node_recursion``), so the training-speed study times its recursion under its own kind."""

    kind = "toy_recursive"


@pytest.fixture
def gating_profile(monkeypatch, tmp_path):
    monkeypatch.setenv("DRF_RESULTS", str(tmp_path / "results"))
    for cls in (ToyModel, ToyFilter, ToyRecursive):
        monkeypatch.setitem(MODEL_CLASSES, cls.kind, cls)
    entry = registry.STUDIES["pendulum"]
    monkeypatch.setitem(registry.STUDIES, "pendulum", dataclasses.replace(
        entry, kinds=entry.kinds + ("toy", "toy_filter", "toy_recursive")))
    values = load_profile("quick") | {
        "profile": "tiny", "pend_train_sequences": 4, "pend_val_sequences": 3, "pend_test_sequences": 3,
        "pend_seq_len": 6, "pend_eval_max_noise": [0.5, 0.75], "seeds": [0, 1], "device": "cpu",
        "pend_models": ["toy", "toy_filter"], "eval_studies": ["pendulum"], "n_samples": 4,
        "gating_sweep_points": 3, "gating_timing_frames": 0}
    return for_notebook("06_competency_gating", values)


def _build(kind: str, seed: int = 0):
    torch.manual_seed(seed)
    return MODEL_CLASSES[kind](**{k: v for k, v in default_config(kind, "pendulum", 2, latent=4, feature_dim=8,
                                                                  decoder_hidden=8).items() if k != "kind"})


def test_a_filter_that_declares_competency_gain_is_gated_and_one_that_does_not_is_not(gating_profile):
    P = gating_profile
    assert P.pendulum.models == ["toy", "toy_filter"]  # the profile's check reads the registry's kinds
    models = {("toy", 0): _build("toy"), ("toy_filter", 0): _build("toy_filter", 0),
              ("toy_filter", 1): _build("toy_filter", 1)}
    gated = gating_study.gated_models(models)
    assert list(gated) == [0, 1] and all(type(m) is ToyFilter for m in gated.values())
    out = gating_study.gating_study(P, "pendulum", models=models, min_run_time=0.001)
    assert set(out["table"]["seed"]) == {0, 1} and set(out["table"]["setting"]) == set(gating.SETTINGS)
    assert set(out["sweep"]["method"]) == {"kalman_gain", "random", "oracle"}
    # the gate tuned at the training noise reads it off the study's registry entry (Study.train_level)
    tuned = gating_study.train_noise_gates(P, "pendulum", models)
    assert tuned["seed"].tolist() == [0, 1] and (tuned["val_noise"] == P.pendulum.train_max_noise).all()
    # without the declaration there is no gate, even for a model with a Kalman filter's gains
    val = studies.study_data(P, "pendulum", "val")
    with pytest.raises(ValueError, match="declares no competency_gain"):
        gating.fit_gate(models[("toy", 0)], val, n_samples=4, tolerance=0.0, n_points=3)
    with pytest.raises(ValueError, match="no trained 'drf' model"):
        gating_study.gating_study(P, "pendulum", models={("toy", 0): models[("toy", 0)]})
    known = KnownDynamicsFilter()
    assert known.kalman_gains(val.inputs[:1]) is not None  # gains (state x observation), but not declared
    drf = _build("drf")
    assert gating_study.gated_models({("known_dynamics", 0): known, ("drf", 0): drf}) == {0: drf}
    # two gated kinds would share the tables' per-seed rows: a clear error names them
    with pytest.raises(ValueError, match=r"\['drf', 'toy_filter'\]"):
        gating_study.gated_models(models | {("drf", 0): drf})


def test_a_model_that_declares_a_one_node_recursion_has_it_timed(gating_profile):
    from drfkit.methods import timing

    inputs, targets = bench.example_frames("pendulum", 2, 3), torch.rand(2, 3, 2)
    base = default_config("toy", "pendulum", 2)
    table = timing.recursion_scaling(base, default_config("toy_recursive", "pendulum", 2), inputs, targets,
                                     sizes=(1, 4), min_run_time=0.0, min_rounds=2, threads=1)
    assert list(zip(table["model"], table["part"])) == [("toy", "step"), ("toy_recursive", "step")] + [
        ("toy_recursive", "recursion")] * 3
    with pytest.raises(ValueError, match="declares one_node_recursion"):
        timing.recursion_scaling(base, default_config("toy_filter", "pendulum", 2), inputs, targets, min_run_time=0.0)


def test_a_study_is_judged_by_the_gating_claim_its_entry_names(monkeypatch, tmp_path):
    """A study registered in the test, on the pendulum's section: its profile keys are bounded by its entry,
    and notebook 06's claim on it is the one its entry names (none: no row)."""
    from drfkit.study.claims import judge
    from drfkit.util.paths import tables_dir

    monkeypatch.setenv("DRF_RESULTS", str(tmp_path / "results"))
    entry = dataclasses.replace(registry.STUDIES["pendulum"], name="pendulum_again", gating_claim="C7b",
                                all_protocols=registry.STUDIES["pendulum"].all_protocols + ("toy_protocol",))
    monkeypatch.setitem(registry.STUDIES, "pendulum_again", entry)
    assert "'toy_protocol'" in allowed_text("pend_protocols")  # the section's protocols are its studies'
    values = load_profile("quick") | {"profile": "tiny", "eval_studies": ["pendulum_again"], "seeds": [0, 1, 2]}
    P = for_notebook("06_competency_gating", values)
    with pytest.raises(ParameterError, match="pend_protocols"):
        for_notebook("06_competency_gating", values | {"pend_protocols": ["paper", "no_such_protocol"]})
    rows = [{"study": "pendulum_again", "protocol": "paper", "seed": seed, "val_fraction": f, "fraction": f,
             "method": method, "picp": 0.9 + 0.001 * seed, "time_ms": 1.0}
            for seed in (0, 1, 2) for f in (0.0, 0.5, 1.0) for method in ("kalman_gain", "random")]
    folder = tables_dir(P.profile)
    folder.mkdir(parents=True, exist_ok=True)
    pd.DataFrame(rows).to_csv(folder / "gating_sweep.csv", index=False)
    [(protocol, row)] = judge.judge_gating(P)
    assert protocol == "paper" and row["id"] == "C7b" and row["verdict"] == claims.REPRODUCED  # KG = random
    assert claims.c7_gating(pd.DataFrame(rows), "pendulum_again", claim="C7a")["id"] == "C7a"
    monkeypatch.setitem(registry.STUDIES, "pendulum_again", dataclasses.replace(entry, gating_claim=""))
    assert judge.judge_gating(P) == []
    with pytest.raises(ValueError, match="no gating claim on 'pendulum_again'"):
        claims.c7_gating(pd.DataFrame(rows), "pendulum_again")
