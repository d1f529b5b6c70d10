"""The training-time estimate: measured step times scaled by batches, epochs and seeds."""
import pandas as pd
import pytest

from drfkit.book import budget
from drfkit.study.params import load_profile, write_profile
from drfkit.cli import main as cli


def test_budget_covers_every_model_and_scales_with_epochs_and_seeds(tmp_path, monkeypatch):
    monkeypatch.setenv("DRF_RESULTS", str(tmp_path))
    values = load_profile("quick")
    values.update(profile="tiny", pend_train_sequences=6, pend_val_sequences=2, pend_test_sequences=2,
                  pend_seq_len=8, ped_n_scenes=4, ped_frames_per_scene=4, pend_epochs=3, seeds=[0, 1, 2])
    path = tmp_path / "tiny.yaml"
    write_profile(path, values)
    assert cli(["budget", "--profile", str(path), "--min-run-time", "0.01"]) == 0
    table = pd.read_csv(tmp_path / "tiny" / "training_budget.csv")
    assert set(zip(table["study"], table["model"])) == (
        {("pendulum", m) for m in values["pend_models"]} | {("pedestrians", m) for m in values["ped_models"]})
    pend = table[(table["study"] == "pendulum") & (table["model"] == "drf")].iloc[0]
    assert pend["batches_per_epoch"] == 1 and pend["epochs"] == 3 and pend["seeds"] == 3
    assert pend["hours"] == pytest.approx(pend["step_s"] * 1 * 3 * 3 / 3600, rel=1e-4)  # CSV keeps 6 digits
    pend_rows = table[table["study"] == "pendulum"].set_index("model")
    assert (pend_rows["ratio_to"] == "no_dynamics").all() and pend_rows.loc["no_dynamics", "step_ratio"] == 1.0
    assert (pend_rows["rounds"] >= 5).all() and (pend_rows["step_ratio"] > 0).all()
    # the DRF and the LSTM do the no_dynamics step's products and those of their recursion
    assert pend_rows.loc["no_dynamics", "flop_ratio"] == 1.0
    assert pend_rows.loc["drf", "flop_ratio"] > pend_rows.loc["lstm", "flop_ratio"] > 1.0
    mono = table[table["model"] == "monoloco"].iloc[0]
    assert mono["ratio_to"] == "monoloco" and mono["step_ratio"] == 1.0  # timed alone (single frames)
    assert mono["frames_per_item"] == 1 and mono["epochs"] == values["monoloco_epochs"]  # single frames
    assert (table["epochs_done"] == 0).all() and (table["hours_left"] == table["hours"]).all()


def test_budget_counts_the_epochs_already_in_checkpoints(tmp_path, monkeypatch):
    from drfkit.study import studies
    from drfkit.study.params import notebook_params, validate

    monkeypatch.setenv("DRF_RESULTS", str(tmp_path))
    values = load_profile("quick")
    values.update(profile="tiny", pend_train_sequences=4, pend_val_sequences=2, pend_test_sequences=2,
                  pend_seq_len=6, pend_batch_size=2, ped_n_scenes=4, ped_frames_per_scene=4, pend_epochs=2,
                  seeds=[0, 1])
    path = tmp_path / "tiny.yaml"
    write_profile(path, values)
    # one of the two no_dynamics seeds fully trained: 2 of 4 epochs done, half the hours left
    assert cli(["train", "--profile", str(path), "--study", "pendulum", "--models", "no_dynamics",
                         "--seeds", "1"]) == 0
    assert cli(["budget", "--profile", str(path), "--min-run-time", "0.01"]) == 0
    row = pd.read_csv(tmp_path / "tiny" / "training_budget.csv").set_index(["study", "model"])
    assert row.loc[("pendulum", "no_dynamics"), "epochs_done"] == 2
    assert row.loc[("pendulum", "no_dynamics"), "hours_left"] == pytest.approx(
        row.loc[("pendulum", "no_dynamics"), "hours"] / 2, rel=1e-4)
    assert row.loc[("pendulum", "drf"), "epochs_done"] == 0


def test_budget_counts_a_run_stopped_by_patience_as_finished(tmp_path, monkeypatch):
    from drfkit.study import studies
    import torch

    monkeypatch.setenv("DRF_RESULTS", str(tmp_path))
    values = load_profile("quick")
    values.update(profile="tiny", pend_train_sequences=4, pend_val_sequences=2, pend_test_sequences=2,
                  pend_seq_len=6, pend_batch_size=2, ped_n_scenes=4, ped_frames_per_scene=4, pend_epochs=5,
                  pend_patience=1, seeds=[0])
    path = tmp_path / "tiny.yaml"
    write_profile(path, values)
    from drfkit.study.params import notebook_params, validate

    P = validate("01_pendulum_training", notebook_params("01_pendulum_training", load_profile(str(path))))
    stem = studies.checkpoint_stem(P, "pendulum", "no_dynamics", 0)
    stem.parent.mkdir(parents=True, exist_ok=True)
    # a resume state at epoch 3 whose best was epoch 2: patience 1 is used up, so nothing is left
    torch.save({"epoch": 3, "best_epoch": 2}, stem.with_name(f"{stem.name}-last.pt"))
    assert budget.epochs_done(P, "pendulum", "no_dynamics") == (3, 0)
    torch.save({"epoch": 3, "best_epoch": 3}, stem.with_name(f"{stem.name}-last.pt"))
    assert budget.epochs_done(P, "pendulum", "no_dynamics") == (3, 2)
    assert studies.train_config(P, "pendulum", "no_dynamics", 0).patience == 1
