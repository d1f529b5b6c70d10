"""``python -m drfkit train`` trains exactly the checkpoints a notebook would use, so a
long profile can be spread over processes or sessions."""
import numpy as np
import pytest

from drfkit.study import pedestrian_runs, studies
from drfkit.study.params import load_profile, notebook_params, validate, write_profile
from drfkit.cli import main as cli


@pytest.fixture
def tiny_profile(tmp_path, monkeypatch):
    monkeypatch.setenv("DRF_RESULTS", str(tmp_path / "results"))
    values = load_profile("quick") | {
        "profile": "tiny", "pend_train_sequences": 4, "pend_val_sequences": 2, "pend_test_sequences": 2,
        "pend_seq_len": 6, "pend_epochs": 1, "pend_batch_size": 2, "seeds": [0, 1]}
    path = tmp_path / "tiny.yaml"
    write_profile(path, values)
    return path


def test_cli_trains_the_selected_checkpoint_that_the_notebook_then_finds(tiny_profile, tmp_path):
    assert cli(["train", "--profile", str(tiny_profile), "--study", "pendulum", "--models", "no_dynamics",
                         "--seeds", "1", "--threads", "1"]) == 0
    models = tmp_path / "results" / "tiny" / "models"
    names = sorted(p.name for p in models.glob("*.pt"))
    assert len(names) == 2 and all(n.startswith("pendulum-no_dynamics-seed1-") for n in names), names
    P = validate("01_pendulum_training", notebook_params("01_pendulum_training", load_profile(tiny_profile)))
    stem = studies.checkpoint_stem(P, "pendulum", "no_dynamics", 1)
    assert stem.with_name(stem.name + "-best.pt").exists()
    # the notebook's call trains the rest and reuses this one without training it again
    mtime = stem.with_name(stem.name + "-best.pt").stat().st_mtime_ns
    results = studies.train_models(P, "pendulum", progress=False)
    assert set(results) == {(k, s) for k in P.pendulum.models for s in P.seeds}
    assert stem.with_name(stem.name + "-best.pt").stat().st_mtime_ns == mtime
    curves = tmp_path / "results" / "tiny" / "tables" / "pendulum_training_curves.csv"
    assert curves.exists()
    # one writer per table: a notebook that uses the runs another trains writes no curves
    curves.unlink()
    assert set(studies.trained_models(P, "pendulum")) == set(results)
    studies.train_models(P, "pendulum", progress=False, write_curves=False)
    assert not curves.exists()
    studies.trained_models(P, "pendulum", write_curves=True)  # the notebook that trains them
    assert curves.exists()


@pytest.mark.parametrize("args, message", [
    (["--models", "monoloco"], "not models of the pendulum study"),
    (["--seeds", "9"], "not among the profile's seeds"),
])
def test_cli_rejects_what_the_notebooks_would_never_use(tiny_profile, capsys, args, message):
    assert cli(["train", "--profile", str(tiny_profile), "--study", "pendulum", *args]) == 2
    assert message in capsys.readouterr().err


def test_cli_set_overrides_the_profile(tiny_profile, tmp_path):
    import torch

    assert cli(["train", "--profile", str(tiny_profile), "--study", "pendulum", "--models", "no_dynamics",
                         "--seeds", "0", "--threads", "1", "--set", "pend_epochs=2"]) == 0
    (last,) = (tmp_path / "results" / "tiny" / "models").glob("pendulum-no_dynamics-seed0-*-last.pt")
    assert torch.load(last, weights_only=False)["epoch"] == 2


@pytest.mark.parametrize("item, message", [
    ("pend_patience=-1", "pend_patience"),
    ("no_such_key=1", "unknown parameter"),
    ("pend_patience", "KEY=VALUE"),
])
def test_cli_rejects_bad_overrides(tiny_profile, capsys, item, message):
    assert cli(["train", "--profile", str(tiny_profile), "--study", "pendulum", "--set", item]) == 2
    assert message in capsys.readouterr().err


def test_cli_rejects_unknown_profile(capsys):
    assert cli(["train", "--profile", "no_such_profile", "--study", "pendulum"]) == 2
    assert "known profiles" in capsys.readouterr().err


def test_patience_does_not_rename_checkpoints(tiny_profile):
    P = validate("01_pendulum_training", notebook_params("01_pendulum_training", load_profile(tiny_profile)))
    patient = validate("01_pendulum_training", notebook_params("01_pendulum_training", load_profile(tiny_profile))
                       | {"pend_patience": 7})
    assert studies.train_config(patient, "pendulum", "drf", 0).patience == 7
    assert studies.checkpoint_stem(P, "pendulum", "drf", 0) == studies.checkpoint_stem(patient, "pendulum", "drf", 0)


def test_monoloco_trains_on_its_published_schedule_and_the_family_on_the_profile(tiny_profile):
    P = validate("03_nuscenes_training", notebook_params("03_nuscenes_training", load_profile(tiny_profile)))
    mono = studies.train_config(P, "pedestrians", "monoloco", 0)
    assert (mono.lr_step, mono.lr_gamma, mono.framewise, mono.grad_clip, mono.select_on) == (20, 0.9, True, None, "l1")
    assert (mono.epochs, mono.lr, mono.batch_size) == (P.monoloco.epochs, P.monoloco.lr, P.monoloco.batch_size)
    drf = studies.train_config(P, "pedestrians", "drf", 0)
    assert (drf.grad_clip, drf.select_on, drf.lr_step, drf.lr) == (10.0, "loss", None, P.pedestrians.lr)
    # the book's protocol: the DRF family on beta-NLL with cosine decay, selected on the validation MAE;
    # Monoloco on its published schedule in every protocol, so its runs are one set
    book = studies.train_config(P, "pedestrians", "lstm", 0, "book")
    assert (book.objective, book.beta, book.lr_schedule, book.select_on) == ("beta_nll", 1.0, "cosine", "l1")
    assert (book.epochs, book.lr, book.batch_size) == (P.pedestrians.epochs, P.pedestrians.lr, P.pedestrians.batch_size)
    assert studies.train_config(P, "pedestrians", "monoloco", 0, "book") == mono
    assert studies.checkpoint_stem(P, "pedestrians", "monoloco", 1, "book") == \
        studies.checkpoint_stem(P, "pedestrians", "monoloco", 1)
    assert studies.checkpoint_stem(P, "pedestrians", "drf", 0, "book") != studies.checkpoint_stem(P, "pedestrians", "drf", 0)
    with pytest.raises(ValueError, match="no training protocol 'blackout'.*'paper', 'book'"):
        studies.train_config(P, "pedestrians", "drf", 0, "blackout")


def test_a_diagnostic_variant_has_its_own_name_and_the_published_model_keeps_its_own(tiny_profile):
    P = validate("03_nuscenes_training", notebook_params("03_nuscenes_training", load_profile(tiny_profile)))
    published = studies.model_config("pedestrians", "monoloco", P)
    detected = studies.model_config("pedestrians", "monoloco", P, options={"inputs": "detected"})
    assert "inputs" not in published and detected == published | {"inputs": "detected"}
    assert studies.checkpoint_stem(P, "pedestrians", "monoloco", 0, options={"inputs": "detected"}) != \
        studies.checkpoint_stem(P, "pedestrians", "monoloco", 0)


def test_target_statistics_read_the_training_split_once(tiny_profile, monkeypatch):
    P = validate("03_nuscenes_training", notebook_params("03_nuscenes_training", load_profile(tiny_profile))
                 | {"ped_n_scenes": 4, "ped_frames_per_scene": 4, "ped_data_seed": 77})
    reads = []
    real = pedestrian_runs.pedestrian_data
    monkeypatch.setattr(pedestrian_runs, "pedestrian_data", lambda *a, **k: reads.append(a[1]) or real(*a, **k))
    first = studies.target_statistics(P)
    assert studies.target_statistics(P) == first and reads == ["train"]
    assert first["target_scale"] > 0


def test_cli_trains_the_book_protocol_under_its_own_names_and_reports_a_held_lock(tiny_profile, tmp_path, capsys):
    from drfkit.util.io import exclusive_lock

    args = ["--profile", str(tiny_profile), "--study", "pendulum", "--models", "drf", "--seeds", "0", "--threads", "1"]
    assert cli(["train", *args, "--protocol", "book"]) == 0
    P = validate("01_pendulum_training", notebook_params("01_pendulum_training", load_profile(tiny_profile)))
    book, paper = studies.checkpoint_stem(P, "pendulum", "drf", 0, "book"), studies.checkpoint_stem(P, "pendulum", "drf", 0)
    assert book.with_name(book.name + "-best.pt").exists() and not paper.with_name(paper.name + "-best.pt").exists()
    with exclusive_lock(paper.parent / f".{paper.name}.lock", "test"):
        import drfkit.methods.train as train_module

        saved, train_module.LOCK_WAIT_S = train_module.LOCK_WAIT_S, 0.0
        try:
            assert cli(["train", *args]) == 3
        finally:
            train_module.LOCK_WAIT_S = saved
    err = capsys.readouterr().err
    assert "is being written by process" in err and "Traceback" not in err
    assert not paper.with_name(paper.name + "-last.pt").exists()


def test_a_study_takes_its_own_noise_kind_or_a_level(tiny_profile):
    from drfkit.data.noise import Noise

    P = validate("01_pendulum_training", notebook_params("01_pendulum_training", load_profile(tiny_profile)))
    assert studies.study_noise(P, "pendulum") == Noise("rkn_uniform", P.pendulum.train_max_noise)
    assert studies.study_noise(P, "pendulum", 0.75) == Noise("rkn_uniform", 0.75)
    assert studies.study_noise(P, "pedestrians", Noise("salt_and_pepper", 0.05)).level == 0.05
    with pytest.raises(ValueError, match="takes salt_and_pepper noise"):
        studies.study_noise(P, "pedestrians", Noise("rkn_uniform", 0.05))


def test_the_book_protocol_trains_with_its_recipe_on_fresh_noise(tiny_profile, monkeypatch):
    """The studies layer gives a book-protocol run the variant's training recipe (objective, schedule,
    windows, selection) on the profile's schedule, and new noise on the same clean frames every epoch,
    seeded by the epoch alone; a protocol without a recipe keeps the model's loss and one draw."""
    import numpy as np

    import dataclasses

    from drfkit.models import MODEL_CLASSES

    # the book's protocol of the second round: each kind's spec names the variant the protocol trains
    for kind, variant in {"drf": "fit_prior_split_book", "no_dynamics": "fit_no_dynamics_blackout",
                          "lstm": "fit_lstm_blackout", "known_dynamics": "fit_known_dynamics"}.items():
        spec = MODEL_CLASSES[kind].spec
        monkeypatch.setattr(MODEL_CLASSES[kind], "spec", dataclasses.replace(spec, protocols=spec.protocols | {"book": variant}))
    P = validate("01_pendulum_training", notebook_params("01_pendulum_training", load_profile(tiny_profile)))
    cfg = studies.train_config(P, "pendulum", "drf", 0, "book")
    assert (cfg.objective, cfg.beta, cfg.lr_schedule, cfg.window, cfg.select_on, cfg.prior_weight) == \
        ("beta_nll", 1.0, "cosine", 25, "l1", 1.0)
    assert (cfg.epochs, cfg.lr, cfg.batch_size) == (P.pendulum.book.epochs, P.pendulum.book.lr, P.pendulum.book.batch_size)
    assert studies.train_config(P, "pendulum", "lstm", 0, "book").prior_weight == 0.0
    assert studies.train_config(P, "pendulum", "drf", 0, "paper").objective == "model"
    fresh = studies.fresh_training(P, "pendulum", "book")
    a, b, a2 = fresh(0), fresh(1), fresh(0)
    assert not np.array_equal(a.inputs.numpy(), b.inputs.numpy()) and np.array_equal(a.inputs.numpy(), a2.inputs.numpy())
    assert np.array_equal(a.targets.numpy(), studies.pendulum_data(P, "train", protocol="book").targets.numpy())
    assert studies.fresh_training(P, "pendulum", "paper") is None
    assert studies.fresh_training(P, "pedestrians", "book") is None
    assert studies.study_data_key(P, "pendulum", "book")["fresh_noise"] is True
    assert "fresh_noise" not in studies.study_data_key(P, "pendulum")


@pytest.mark.slow  # trains a DRF, then the probe's passes: about 5 s
def test_dynamics_probes_a_trained_drf_and_names_the_command_for_a_missing_one(tiny_profile, tmp_path, capsys):
    path = tmp_path / "tiny10.yaml"  # the blackout needs 10 frames
    write_profile(path, load_profile(tiny_profile) | {"profile": "tiny10", "pend_seq_len": 10})
    args = ["--profile", str(path), "--models", "drf", "--seeds", "0", "--threads", "1"]
    assert cli(["dynamics", *args]) == 3
    assert "python -m drfkit train --profile" in capsys.readouterr().out
    assert cli(["train", *args, "--study", "pendulum"]) == 0
    capsys.readouterr()
    assert cli(["dynamics", *args, "--level", "0.5"]) == 0
    out = capsys.readouterr().out
    assert "drf seed 0: epoch 1" in out and "r_noise_spearman" in out and "gain_ratio" in out, out
    # the dissection of the same run, written where asked
    table = tmp_path / "dissection.csv"
    assert cli(["dynamics", *args, "--level", "0.5", "--dissect", "--csv", str(table)]) == 0
    out = capsys.readouterr().out
    assert "e2_over_p" in out and "mae_blackout_clamped" in out and "open_loop_horizon" in out
    import pandas as pd
    row = pd.read_csv(table).iloc[0]
    assert row["model"] == "drf" and row["clamped_gain_max"] == 0.0          # the clamp read back as exactly 0
    assert np.isnan(row["no_dynamics_mae_ood"])                               # no no_dynamics named: no yardstick
    assert row["verdict_ood"] in ("gain", "filtering") and row["verdict_blackout"].startswith(("gain", "transition",
                                                                                               "filtering"))


def test_the_restart_rule_trains_a_replaced_slot_from_its_own_seed_and_checks_every_run(tiny_profile, tmp_path,
                                                                                         capsys):
    """A slot named in the book protocol's ``restarts`` trains from the replacement seed under a name of its own; the
    other slots keep their runs; ``dynamics --restarts`` judges the slot's first run and its replacement on validation."""
    from drfkit.study.params import ParameterError
    from drfkit.study.pendulum_runs import training_seed

    path = tmp_path / "restarts.yaml"
    write_profile(path, load_profile(tiny_profile) | {"pend_book_restarts": {"known_dynamics": {1: 3}}})
    P = validate("01_pendulum_training", notebook_params("01_pendulum_training", load_profile(path)))
    P0 = validate("01_pendulum_training", notebook_params("01_pendulum_training", load_profile(tiny_profile)))
    assert [training_seed(P, "known_dynamics", s, "book") for s in (0, 1)] == [0, 3]
    assert training_seed(P, "drf", 1, "book") == 1 and training_seed(P, "known_dynamics", 1, "paper") == 1
    assert studies.train_config(P, "pendulum", "known_dynamics", 1, "book").seed == 3
    stem = lambda prof, s: studies.checkpoint_stem(prof, "pendulum", "known_dynamics", s, "book").name  # noqa: E731
    assert stem(P, 0) == stem(P0, 0) and stem(P, 1) != stem(P0, 1) and "-seed1-" in stem(P, 1)
    for bad in ({"monoloco": {1: 3}}, {"known_dynamics": {1: 1}}, {"known_dynamics": {0: 3, 1: 3}}):
        write_profile(path, load_profile(tiny_profile) | {"pend_book_restarts": bad})
        with pytest.raises(ParameterError, match="pend_book_restarts"):
            validate("01_pendulum_training", notebook_params("01_pendulum_training", load_profile(path)))

    write_profile(path, load_profile(tiny_profile) | {"profile": "tiny", "pend_book_restarts": {"known_dynamics": {1: 3}}})
    args = ["--profile", str(path), "--models", "known_dynamics", "--threads", "1"]
    assert cli(["train", *args, "--study", "pendulum", "--protocol", "book", "--seeds", "1"]) == 0
    out = tmp_path / "restarts.csv"
    assert cli(["dynamics", *args, "--protocol", "book", "--restarts", str(out)]) == 0
    import pandas as pd
    table = pd.read_csv(out)
    assert table[["slot", "training_seed", "used"]].values.tolist() == [[0, 0, True], [1, 1, False], [1, 3, True]]
    trained = table.set_index("training_seed")
    assert trained.loc[3, "r_level_spearman"] == trained.loc[3, "r_level_spearman"]       # measured (not NaN)
    assert trained.loc[[0, 1], "r_level_spearman"].isna().all() and not trained["failed"].any()  # never trained
