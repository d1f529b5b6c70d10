"""``python -m drfkit.studies`` trains exactly the checkpoints a notebook would use, so a
long profile can be spread over processes or sessions."""
import pytest
import yaml

from drfkit import studies
from drfkit.params import PARAMS_DIR, load_profile, notebook_params, validate


@pytest.fixture
def tiny_profile(tmp_path, monkeypatch):
    monkeypatch.setenv("DRF_RESULTS", str(tmp_path / "results"))
    values = yaml.safe_load((PARAMS_DIR / "quick.yaml").read_text()) | {
        "profile": "tiny", "pend_train_sequences": 4, "pend_val_sequences": 2, "pend_test_sequences": 2,
        "pend_seq_len": 6, "pend_epochs": 1, "pend_batch_size": 2, "seeds": [0, 1]}
    path = tmp_path / "tiny.yaml"
    path.write_text(yaml.safe_dump(values))
    return path


def test_cli_trains_the_selected_checkpoint_that_the_notebook_then_finds(tiny_profile, tmp_path):
    assert studies.main(["--profile", str(tiny_profile), "--study", "pendulum", "--models", "no_dynamics",
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
    assert set(results) == {(k, s) for k in P.pend_models for s in P.seeds}
    assert stem.with_name(stem.name + "-best.pt").stat().st_mtime_ns == mtime
    assert (tmp_path / "results" / "tiny" / "tables" / "pendulum_training_curves.csv").exists()


@pytest.mark.parametrize("args, message", [
    (["--models", "monoloco"], "not models of the pendulum study"),
    (["--seeds", "9"], "not among the profile's seeds"),
])
def test_cli_rejects_what_the_notebooks_would_never_use(tiny_profile, capsys, args, message):
    assert studies.main(["--profile", str(tiny_profile), "--study", "pendulum", *args]) == 2
    assert message in capsys.readouterr().err


def test_cli_rejects_unknown_profile(capsys):
    assert studies.main(["--profile", "no_such_profile", "--study", "pendulum"]) == 2
    assert "known profiles" in capsys.readouterr().err
