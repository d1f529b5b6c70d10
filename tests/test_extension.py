"""Adding a model or a noise kind is one file: an extension (``drfkit.util.registry``) that registers
its class (``MODEL_CLASSES``, the class's ``ModelSpec`` saying where it belongs and how it is shown) or
its noise (``NOISE_KINDS`` and a corruption of the study's inputs: ``FRAME_CORRUPTIONS`` for pendulum
frames, ``PEDESTRIAN_CORRUPTIONS`` for pedestrian images and keypoints), plus, for a noise, the study
variant that uses it (``STUDIES``). Here each file is written into the test's folder and imported by
``extensions(path)`` for the test's duration: nothing is patched by hand and nothing outlives the block.
The new kind then goes through what every model or noise goes through -- training, evaluation, timing,
a claim's verdict -- on tiny data, with no other file touched.

What a model can do beyond the interface is what its class declares (``drfkit.models.sequence``), never
its kind's name: a new filter that declares ``competency_gain`` is gated and one that does not is not; a
model that declares ``one_node_recursion`` has its recursion timed. What a study is judged by is its
registry entry's (``Study.gating_claim``, its section's kinds and protocols), never its name."""
from __future__ import annotations

import textwrap

import numpy as np
import pandas as pd
import pytest
import torch

from drfkit.data import noise as noise_module
from drfkit.data import pendulum
from drfkit.methods import gating
from drfkit.methods.protocols import PROTOCOLS
from drfkit.models import MODEL_CLASSES, KnownDynamicsFilter, default_config
from drfkit.report import figures
from drfkit.study import bench, claims, gating_study, registry, studies
from drfkit.study.evaluate import evaluate_study
from drfkit.study.params import ParameterError, allowed_text, for_notebook, load_profile
from drfkit.util.registry import extensions

TOY_MODEL = """
    from drfkit.models import MODEL_CLASSES, ModelSpec, NoDynamics


    @MODEL_CLASSES.register("toy")
    class ToyModel(NoDynamics):
        \"\"\"A new per-frame model: the no_dynamics network under a new kind (what matters is the wiring).\"\"\"

        kind = "toy"
        spec = ModelSpec("Toy (per frame)", "tab:pink", studies=("pendulum",))
"""

TOY_FILTERS = """
    import torch

    from drfkit.models import MODEL_CLASSES, DeepRecursiveFilter, ModelSpec, NoDynamics
    from drfkit.models.parts import mean_and_log_variance


    @MODEL_CLASSES.register("toy_filter")
    class ToyFilter(NoDynamics):
        \"\"\"A new filter: each latent dim a random walk, filtered by a scalar Kalman filter on the encoder's
        w_t, r_t (z_t = z_{t-1} + k_t (w_t - z_{t-1}), k_t = P- / (P- + r_t), P- = P_{t-1} + q). Its gains
        diag(k_t) act on its state, so it declares competency_gain: gating runs on it as on the DRF.\"\"\"

        kind = "toy_filter"
        spec = ModelSpec("Toy filter", "tab:olive", studies=("pendulum",))
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


    @MODEL_CLASSES.register("toy_recursive")
    class ToyRecursive(DeepRecursiveFilter):
        \"\"\"A new kind built on the DRF's filter: it inherits the DRF's declarations (competency_gain,
        one_node_recursion), so the training-speed study times its recursion under its own kind; its spec
        it declares itself (a spec is never inherited).\"\"\"

        kind = "toy_recursive"
        spec = ModelSpec("Toy recursive", "tab:cyan", studies=("pendulum",))
"""

PENDULUM_NOISE = """
    import dataclasses

    import numpy as np

    from drfkit.data.noise import NOISE_KINDS
    from drfkit.data.pendulum import FRAME_CORRUPTIONS
    from drfkit.study.registry import STUDIES

    NOISE_KINDS.register("toy_gaussian", "std of Gaussian pixel noise / 255")


    @FRAME_CORRUPTIONS.register("toy_gaussian")
    def gaussian_frames(clean, level, factor_rng, pixel_rng):
        \"\"\"Gaussian pixel noise of standard deviation level x 255 on every frame.\"\"\"
        noisy = clean + pixel_rng.normal(0.0, 255.0 * level, size=clean.shape)
        return np.clip(np.rint(noisy), 0, 255).astype(np.uint8), np.full(clean.shape[:2], level, np.float32)


    STUDIES.register("pendulum_gaussian", dataclasses.replace(STUDIES["pendulum"], name="pendulum_gaussian",
                                                              noise_kind="toy_gaussian"))
"""

PEDESTRIAN_NOISE = """
    import dataclasses

    import numpy as np

    from drfkit.data.noise import NOISE_KINDS, PEDESTRIAN_CORRUPTIONS, PedestrianCorruption
    from drfkit.study.registry import STUDIES

    NOISE_KINDS.register("toy_jitter", "std of Gaussian pixel noise / 255; keypoints jittered by level x 100 px")


    def gaussian_pixels(pixels, level, rng):
        noisy = pixels + rng.normal(0.0, 255.0 * level, size=pixels.shape)
        return np.clip(np.rint(noisy), 0, 255).astype(np.uint8)


    def jitter(keypoints, level, rng):
        \"\"\"The detector's keypoints moved by Gaussian pixel error of sd level x 100 px.\"\"\"
        out = keypoints.copy()
        out[..., :2] += rng.normal(0.0, 100.0 * level, size=out[..., :2].shape)
        return out


    PEDESTRIAN_CORRUPTIONS.register("toy_jitter", PedestrianCorruption(gaussian_pixels, keypoints=jitter))
    STUDIES.register("pedestrians_jitter", dataclasses.replace(STUDIES["pedestrians"], name="pedestrians_jitter",
                                                               noise_kind="toy_jitter"))
"""


def extension_file(folder, name: str, text: str):
    path = folder / f"{name}.py"
    path.write_text(textwrap.dedent(text))
    return path


PEND_TINY = {"profile": "tiny", "pend_train_sequences": 4, "pend_val_sequences": 2, "pend_test_sequences": 2,
             "pend_seq_len": 6, "pend_epochs": 1, "pend_batch_size": 2, "seeds": [0], "pend_protocols": ["paper"]}


@pytest.fixture
def toy_registered(monkeypatch, tmp_path):
    monkeypatch.setenv("DRF_RESULTS", str(tmp_path / "results"))
    with extensions(extension_file(tmp_path, "toy_model", TOY_MODEL)):
        values = load_profile("quick") | PEND_TINY | {"pend_models": ["drf", "toy"]}
        yield for_notebook("01_pendulum_training", values)


def test_a_model_kind_added_in_one_file_trains_evaluates_is_timed_and_judged(toy_registered):
    P = toy_registered
    # its spec puts it in the pendulum study (after the book's kinds), the bench, the figures
    assert registry.STUDIES["pendulum"].kinds == ("drf", "drf_calibrated", "drf_calibrated_steep", "no_dynamics", "lstm",
                                                  "known_dynamics", "toy")
    assert "toy" not in registry.STUDIES["pedestrians"].kinds
    assert studies.study_models(P, "pendulum") == ["drf", "toy"]  # the profile's check reads the registry
    assert (figures.label("toy"), figures.color("toy"), figures.drawn_in_colour("toy")) == \
        ("Toy (per frame)", "tab:pink", True)
    # training: checkpoints under the study's names, the config rebuilt from its stored form
    results = studies.train_models(P, "pendulum", progress=False)
    assert set(results) == {("drf", 0), ("toy", 0)}
    assert studies.checkpoint_stem(P, "pendulum", "toy", 0).name.startswith("pendulum-toy-seed0-")
    models = studies.trained_models(P, "pendulum")
    assert type(models[("toy", 0)]) is MODEL_CLASSES["toy"]
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


def test_nothing_outlives_the_extension_and_a_missing_kind_is_named(monkeypatch, tmp_path):
    monkeypatch.setenv("DRF_RESULTS", str(tmp_path / "results"))
    before = (dict(MODEL_CLASSES), registry.STUDIES["pendulum"].kinds, {p: dict(v) for p, v in PROTOCOLS.items()})
    with extensions(extension_file(tmp_path, "toy_model", TOY_MODEL)):
        P = for_notebook("01_pendulum_training", load_profile("quick") | PEND_TINY | {"pend_models": ["drf", "toy"]})
        with pytest.raises(ValueError, match="model kind 'toy' is registered already"):
            MODEL_CLASSES.register("toy", KnownDynamicsFilter)
        with pytest.raises(TypeError, match="not by item assignment"):
            MODEL_CLASSES["toy2"] = KnownDynamicsFilter
    assert (dict(MODEL_CLASSES), registry.STUDIES["pendulum"].kinds, {p: dict(v) for p, v in PROTOCOLS.items()}) == before
    assert "toy" not in bench.MODES and figures.label("toy") == "toy"
    with pytest.raises(ValueError, match="unknown model kind 'toy'"):
        studies.model_config("pendulum", "toy", P)
    with pytest.raises(ValueError, match="protocol 'book' has no 'toy' model"):
        studies.train_config(P, "pendulum", "toy", 0, "book")
    with pytest.raises(ParameterError, match="pend_models"):
        for_notebook("01_pendulum_training", load_profile("quick") | PEND_TINY | {"pend_models": ["drf", "toy"]})
    assert torch.is_tensor(bench.example_frames("pendulum", 1))


def test_a_pendulum_noise_kind_added_in_one_file_makes_its_own_data_and_runs(monkeypatch, tmp_path):
    """A noise kind is its meaning (``NOISE_KINDS``) and how it corrupts frames (``FRAME_CORRUPTIONS``);
    a study that names it gets its own frames, caches and checkpoint names, and trains and evaluates."""
    monkeypatch.setenv("DRF_RESULTS", str(tmp_path / "results"))
    with extensions(extension_file(tmp_path, "pendulum_gaussian", PENDULUM_NOISE)):
        P = for_notebook("01_pendulum_training", load_profile("quick") | PEND_TINY | {"pend_models": ["no_dynamics"]})
        assert registry.STUDIES["pendulum_gaussian"].kinds == registry.STUDIES["pendulum"].kinds  # same section
        gaussian, benchmark = (studies.study_data(P, s, "test", 0.3) for s in ("pendulum_gaussian", "pendulum"))
        assert not torch.equal(gaussian.inputs, benchmark.inputs) and torch.equal(gaussian.targets, benchmark.targets)
        frames = pendulum.generate_pendulum(2, 6, noise_module.Noise("toy_gaussian", 0.3), seed=P.pendulum.test_seed)
        assert np.array_equal(gaussian.inputs.numpy(), frames["images"])  # the registered corruption made them
        assert studies.study_data_key(P, "pendulum_gaussian")["noise_kind"] == "toy_gaussian"
        assert "noise_kind" not in studies.study_data_key(P, "pendulum")  # the benchmark's runs keep their names
        results = studies.train_models(P, "pendulum_gaussian", progress=False)
        assert results[("no_dynamics", 0)].best_path.name.startswith("pendulum_gaussian-no_dynamics-seed0-")
        evals = evaluate_study(P, "pendulum_gaussian", [0.3, 0.6])
        assert set(evals["noise"]) == {0.3, 0.6} and (evals["mae"] > 0).all()
        with pytest.raises(ValueError, match="no corruption of pendulum frames for salt_and_pepper"):
            pendulum.generate_pendulum(2, 6, noise_module.Noise("salt_and_pepper", 0.1), seed=0)
        with pytest.raises(ValueError, match="no corruption of pedestrian data for toy_gaussian.*PEDESTRIAN_CORRUPTIONS"):
            noise_module.pedestrian_corruption(noise_module.Noise("toy_gaussian", 0.1), "the pedestrian data")
    assert "toy_gaussian" not in noise_module.NOISE_KINDS and "pendulum_gaussian" not in registry.STUDIES


PED_TINY = {"profile": "tiny", "ped_n_scenes": 6, "ped_frames_per_scene": 6, "ped_seq_len": 4, "ped_epochs": 1,
            "ped_batch_size": 4, "seeds": [0], "ped_models": ["no_dynamics"], "ped_protocols": ["paper"]}


def test_a_pedestrian_noise_kind_added_in_one_file_makes_its_own_data_and_runs(monkeypatch, tmp_path):
    """A pedestrian noise kind is its meaning and how it corrupts camera images and keypoints
    (``PEDESTRIAN_CORRUPTIONS``); the simulated detector sees the same people through it, and a study
    that names it gets its own records, caches and checkpoint names, and trains and evaluates."""
    from drfkit.data.drawing import render_frame
    from drfkit.data.sim_world import simulate_truth
    from drfkit.study.pedestrian_runs import pedestrian_records

    monkeypatch.setenv("DRF_RESULTS", str(tmp_path / "results"))
    with extensions(extension_file(tmp_path, "pedestrians_jitter", PEDESTRIAN_NOISE)):
        P = for_notebook("03_nuscenes_training", load_profile("quick") | PED_TINY)
        jitter, salt = noise_module.Noise("toy_jitter", 0.05), noise_module.Noise("salt_and_pepper", 0.05)
        # the same people, seen through another noise: other keypoints, the same depths
        ours, paper = pedestrian_records(P, jitter), pedestrian_records(P, salt)
        assert np.array_equal(ours["position"], paper["position"]) and not np.array_equal(ours["keypoints"], paper["keypoints"])
        assert np.allclose(ours["noise"], 0.05)
        truth = simulate_truth(2, 2, seed=0)
        image_id = int(truth["image_id"][0])
        assert not np.array_equal(render_frame(truth, image_id, jitter), render_frame(truth, image_id, salt))
        gaussian, benchmark = (studies.study_data(P, s, "test", 0.05) for s in ("pedestrians_jitter", "pedestrians"))
        assert not torch.equal(gaussian.inputs, benchmark.inputs)
        assert studies.study_data_key(P, "pedestrians_jitter")["noise_kind"] == "toy_jitter"
        assert "noise_kind" not in studies.study_data_key(P, "pedestrians")
        results = studies.train_models(P, "pedestrians_jitter", progress=False)
        assert results[("no_dynamics", 0)].best_path.name.startswith("pedestrians_jitter-no_dynamics-seed0-")
        evals = evaluate_study(P, "pedestrians_jitter", [0.01, 0.05])
        assert set(evals["noise"]) == {0.01, 0.05} and (evals["mae"] > 0).all()
    with pytest.raises(ValueError, match="unknown noise kind 'toy_jitter'"):
        noise_module.Noise("toy_jitter", 0.05)


@pytest.fixture
def gating_profile(monkeypatch, tmp_path):
    monkeypatch.setenv("DRF_RESULTS", str(tmp_path / "results"))
    with extensions(extension_file(tmp_path, "toy_model", TOY_MODEL), extension_file(tmp_path, "toy_filters", TOY_FILTERS)):
        values = load_profile("quick") | {
            "profile": "tiny", "pend_train_sequences": 4, "pend_val_sequences": 3, "pend_test_sequences": 3,
            "pend_seq_len": 6, "pend_eval_max_noise": [0.5, 0.75], "seeds": [0, 1], "device": "cpu",
            "pend_models": ["toy", "toy_filter"], "eval_studies": ["pendulum"], "n_samples": 4,
            "gating_sweep_points": 3, "gating_timing_frames": 0}
        yield for_notebook("06_competency_gating", values)


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
    assert list(gated) == [0, 1] and all(type(m) is MODEL_CLASSES["toy_filter"] for m in gated.values())
    out = gating_study.gating_study(P, "pendulum", models=models, min_run_time=0.001)
    assert set(out["table"]["seed"]) == {0, 1} and set(out["table"]["setting"]) == set(gating.SETTINGS)
    assert set(out["sweep"]["method"]) == {"kalman_gain", "random", "oracle"}
    # the gate tuned at the training noise reads it off the study's registry entry (Study.train_level)
    tuned = out["train_gate"]
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


AGAIN = """
    import dataclasses

    from drfkit.study.registry import STUDIES

    pendulum = STUDIES["pendulum"]
    STUDIES.register("pendulum_again", dataclasses.replace(
        pendulum, name="pendulum_again", gating_claim={claim!r},
        all_protocols=pendulum.all_protocols + ("toy_protocol",)))
"""


def test_a_study_is_judged_by_the_gating_claim_its_entry_names(monkeypatch, tmp_path):
    """A study added in one file, on the pendulum's section: its profile keys are bounded by its entry,
    and notebook 06's claim on it is the one its entry names (none: no row)."""
    from drfkit.study.claims import judge
    from drfkit.util.paths import tables_dir

    monkeypatch.setenv("DRF_RESULTS", str(tmp_path / "results"))
    rows = [{"study": "pendulum_again", "protocol": "paper", "seed": seed, "val_fraction": f, "fraction": f,
             "method": method, "picp": 0.9 + 0.001 * seed + (0.02 if method == "oracle" and 0 < f < 1 else 0.0),
             "time_ms": 1.0}
            for seed in (0, 1, 2) for f in (0.0, 0.5, 1.0) for method in ("kalman_gain", "random", "oracle")]
    with extensions(extension_file(tmp_path, "again_c7b", AGAIN.format(claim="C7b"))):
        assert "'toy_protocol'" in allowed_text("pend_protocols")  # the section's protocols are its studies'
        values = load_profile("quick") | {"profile": "tiny", "eval_studies": ["pendulum_again"], "seeds": [0, 1, 2]}
        P = for_notebook("06_competency_gating", values)
        with pytest.raises(ParameterError, match="pend_protocols"):
            for_notebook("06_competency_gating", values | {"pend_protocols": ["paper", "no_such_protocol"]})
        folder = tables_dir(P.profile)
        folder.mkdir(parents=True, exist_ok=True)
        pd.DataFrame(rows).to_csv(folder / "gating_sweep.csv", index=False)
        [(protocol, row)] = judge.judge_gating(P)
        assert protocol == "paper" and row["id"] == "C7b" and row["verdict"] == claims.REPRODUCED  # KG = random
        assert claims.c7_gating(pd.DataFrame(rows), "pendulum_again", claim="C7a")["id"] == "C7a"
    # the same study again, from a file whose entry names no gating claim
    with extensions(extension_file(tmp_path, "again_none", AGAIN.format(claim=""))):
        assert judge.judge_gating(P) == []
        with pytest.raises(ValueError, match="no gating claim on 'pendulum_again'"):
            claims.c7_gating(pd.DataFrame(rows), "pendulum_again")
    assert "'toy_protocol'" not in allowed_text("pend_protocols")


@pytest.mark.slow
def test_an_extension_reaches_the_command_line_and_a_notebooks_start_up(tmp_path):
    """The book's own paths load ``DRFKIT_EXTENSIONS``: ``python -m drfkit train`` trains a model kind that only an
    extension file registers, and a notebook's start-up (``start_notebook``, as make reproduce runs it) accepts its
    parameters and evaluates it into the study's table rows."""
    import os
    import subprocess
    import sys

    from drfkit.study.params import load_profile, write_profile
    from drfkit.util.registry import ENV

    ext = extension_file(tmp_path, "toy_model", TOY_MODEL)
    profile = tmp_path / "tiny.yaml"
    write_profile(profile, load_profile("quick") | PEND_TINY | {"pend_models": ["drf", "toy"]})
    env = {**os.environ, ENV: str(ext), "DRF_RESULTS": str(tmp_path / "results"), "OMP_NUM_THREADS": "1"}
    run = subprocess.run([sys.executable, "-m", "drfkit", "train", "--profile", str(profile), "--study", "pendulum",
                          "--models", "toy", "--seeds", "0", "--threads", "1"], env=env, capture_output=True, text=True)
    assert run.returncode == 0, run.stdout + run.stderr
    assert list((tmp_path / "results" / "tiny" / "models").glob("pendulum-toy-seed0-*-best.pt"))
    code = f"""
from drfkit.study.params import _key_set, load_profile
from drfkit.book.runtime import start_notebook
from drfkit.study import studies
from drfkit.study.evaluate import evaluate_study
values = load_profile({str(profile)!r})  # what papermill injects into the parameters cell, unchecked
P, timer = start_notebook("04_ood_noise_evaluation", {{k: values[k] for k in _key_set("04_ood_noise_evaluation")}})
rows = evaluate_study(P, "pendulum", [0.75], models={{k: m for k, m in studies.trained_models(P, "pendulum").items()}})
print(sorted(set(rows["model"])))
"""
    run = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "['drf', 'toy']" in run.stdout
