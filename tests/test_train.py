"""The training loop: determinism, resume after an interruption (including SIGKILL),
non-finite guards and checkpoint loading."""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch

from drfkit.data.noise import Noise
from drfkit.data.pendulum import generate_pendulum
from drfkit.util.io import CorruptArtefactError, torch_load_checked
from drfkit.util.paths import REPO_ROOT
from drfkit.study.studies import model_config
from drfkit.methods.train import NonFiniteLossError, SequenceData, TrainConfig, load_checkpoint, train_model

CONFIG_KIND = "drf"


def tiny_data():
    arrays = generate_pendulum(12, 10, Noise("rkn_uniform", 0.5), seed=3)
    images, targets = torch.from_numpy(arrays["images"]), torch.from_numpy(arrays["targets"])
    return SequenceData(images[:8], targets[:8]), SequenceData(images[8:], targets[8:])


def train_cfg(epochs=4, seed=0):
    return TrainConfig(epochs=epochs, lr=3e-3, batch_size=4, seed=seed)


def state_equal(a, b):
    return all(torch.equal(a[k], b[k]) for k in a)


pytestmark = pytest.mark.usefixtures("one_thread")  # tests/conftest.py


def test_same_seed_same_result_and_resume_equals_uninterrupted(tmp_path):
    train, val = tiny_data()
    cfg = model_config("pendulum", CONFIG_KIND)
    a = train_model(cfg, train, val, train_cfg(), tmp_path / "a", progress=False)
    b = train_model(cfg, train, val, train_cfg(), tmp_path / "b", progress=False)
    assert [h["val_loss"] for h in a.history] == [h["val_loss"] for h in b.history]

    c1 = train_model(cfg, train, val, train_cfg(), tmp_path / "c", progress=False, stop_after_epochs=2)
    assert len(c1.history) == 2
    c2 = train_model(cfg, train, val, train_cfg(), tmp_path / "c", progress=False)
    assert c2.resumed_from == 2
    assert [h["val_loss"] for h in c2.history] == [h["val_loss"] for h in a.history]
    assert state_equal(torch_load_checked(a.last_path)["model"], torch_load_checked(c2.last_path)["model"])
    # a finished run is a cache hit
    assert train_model(cfg, train, val, train_cfg(), tmp_path / "c", progress=False).resumed_from == 4


def test_other_seed_differs(tmp_path):
    train, val = tiny_data()
    cfg = model_config("pendulum", CONFIG_KIND)
    a = train_model(cfg, train, val, train_cfg(epochs=1, seed=0), tmp_path / "a", progress=False)
    b = train_model(cfg, train, val, train_cfg(epochs=1, seed=1), tmp_path / "b", progress=False)
    assert a.history[0]["val_loss"] != b.history[0]["val_loss"]


@pytest.mark.slow
def test_sigkill_mid_training_then_resume_matches(tmp_path):
    epochs = 25  # long enough that the kill lands before the end
    train, val = tiny_data()
    cfg = model_config("pendulum", CONFIG_KIND)
    reference = train_model(cfg, train, val, train_cfg(epochs=epochs), tmp_path / "ref", progress=False)

    stem = tmp_path / "killed"
    env = dict(os.environ, PYTHONPATH=str(REPO_ROOT), OMP_NUM_THREADS="1")
    proc = subprocess.Popen([sys.executable, "-m", "tests._train_worker", str(stem), str(epochs)],
                            cwd=REPO_ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    last = Path(f"{stem}-last.pt")
    deadline = time.time() + 120
    while time.time() < deadline:
        if last.exists() and torch_load_checked(last)["epoch"] >= 2:
            break
        if proc.poll() is not None:
            pytest.fail(f"worker ended early: {proc.stderr.read().decode()[-2000:]}")
        time.sleep(0.02)
    time.sleep(0.05)  # land somewhere inside the next epoch
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    done = torch_load_checked(last)["epoch"]
    assert 2 <= done < epochs, done  # killed before the end, after two epochs
    # the kill may land inside an atomic write: then its temp file is left, never a half checkpoint
    assert len(list(tmp_path.glob(".killed-*.tmp"))) <= 1
    (tmp_path / ".killed-best.pt.x1y2z3.tmp").write_bytes(b"half a checkpoint")  # as such a kill leaves
    resumed = train_model(cfg, train, val, train_cfg(epochs=epochs), stem, progress=False)
    assert not list(tmp_path.glob(".killed-*.tmp"))  # stale temp files are swept on resume
    assert resumed.resumed_from == done
    assert [h["val_loss"] for h in resumed.history] == [h["val_loss"] for h in reference.history]
    assert state_equal(torch_load_checked(reference.best_path)["state_dict"],
                       torch_load_checked(resumed.best_path)["state_dict"])


def test_non_finite_loss_stops_with_step_named_and_keeps_checkpoint(tmp_path, monkeypatch):
    train, val = tiny_data()
    cfg = model_config("pendulum", CONFIG_KIND)
    train_model(cfg, train, val, train_cfg(epochs=1), tmp_path / "r", progress=False)
    from drfkit import models

    real_build = models.build_model
    calls = {"n": 0}

    def poisoned(config):
        model = real_build(config)
        real_loss = model.loss

        def loss(*args, **kwargs):
            calls["n"] += 1
            value = real_loss(*args, **kwargs)
            return value * float("nan") if calls["n"] == 2 else value

        model.loss = loss
        return model

    monkeypatch.setattr(models, "build_model", poisoned)
    with pytest.raises(NonFiniteLossError, match=r"epoch 2, step 1"):
        train_model(cfg, train, val, train_cfg(epochs=3), tmp_path / "r", progress=False)
    assert torch_load_checked(Path(f"{tmp_path / 'r'}-last.pt"))["epoch"] == 1  # last good one kept


def test_load_checkpoint_round_trip_and_corruption(tmp_path):
    train, val = tiny_data()
    res = train_model(model_config("pendulum", CONFIG_KIND), train, val, train_cfg(epochs=1), tmp_path / "m",
                      progress=False)
    model = load_checkpoint(res.best_path)
    assert not model.training
    mean, sigma = model(val.inputs)
    assert mean.shape == val.targets.shape and (sigma > 0).all()
    with pytest.raises(CorruptArtefactError, match="resume state"):
        load_checkpoint(res.last_path)
    res.best_path.write_bytes(res.best_path.read_bytes()[:100])
    with pytest.raises(CorruptArtefactError, match="m-best.pt"):
        load_checkpoint(res.best_path)


def test_changed_configuration_does_not_resume_silently(tmp_path):
    train, val = tiny_data()
    cfg = model_config("pendulum", CONFIG_KIND)
    train_model(cfg, train, val, train_cfg(epochs=1), tmp_path / "x", progress=False)
    with pytest.raises(CorruptArtefactError, match="different configuration"):
        train_model(cfg, train, val, TrainConfig(epochs=1, lr=1e-2, batch_size=4, seed=0), tmp_path / "x",
                    progress=False)


@pytest.mark.parametrize("make, fragment", [
    (lambda: SequenceData(torch.full((2, 3, 17, 3), float("nan")), torch.zeros(2, 3, 1)), "NaN"),
    (lambda: SequenceData(torch.zeros(2, 4, 24, 24, dtype=torch.uint8), torch.zeros(2, 3, 2)), "disagree"),
    (lambda: SequenceData(torch.zeros(0, 3, 17, 3), torch.zeros(0, 3, 1)), "empty"),
    (lambda: SequenceData(torch.zeros(2, 3, 17, 3), torch.zeros(2, 3, 1), torch.ones(2, 4, dtype=torch.bool)),
     "mask"),
])
def test_bad_data_is_rejected_early(make, fragment):
    with pytest.raises(ValueError, match=fragment):
        make()


def test_frames_flattens_only_real_frames():
    mask = torch.tensor([[True, True, False], [True, False, False]])
    data = SequenceData(torch.arange(6.0).reshape(2, 3, 1, 1).expand(2, 3, 17, 3).clone(),
                        torch.arange(6.0).reshape(2, 3, 1), mask)
    frames = data.frames()
    assert frames.targets.shape == (3, 1, 1)
    assert frames.targets.flatten().tolist() == [0.0, 1.0, 3.0]
    assert np.all(frames.inputs[:, 0, 0, 0].numpy() == [0.0, 1.0, 3.0])


def test_patience_stops_after_no_improvement_and_a_rerun_is_a_cache_hit(tmp_path, monkeypatch):
    import drfkit.methods.train as train_mod

    train, val = tiny_data()
    cfg = model_config("pendulum", "no_dynamics")
    val_losses = iter([1.0, 0.5, 0.7, 0.6, 0.9, 0.1, 0.05, 0.01])  # best at epoch 2, then 2 worse epochs
    monkeypatch.setattr(train_mod, "evaluate_loss", lambda *a, **k: next(val_losses))
    patient = TrainConfig(epochs=8, lr=3e-3, batch_size=4, seed=0, patience=2)
    res = train_model(cfg, train, val, patient, tmp_path / "p", progress=False)
    assert len(res.history) == 4 and res.best_epoch == 2 and res.stopped_early
    assert load_checkpoint(res.best_path).checkpoint_meta["epoch"] == 2
    again = train_model(cfg, train, val, patient, tmp_path / "p", progress=False)
    assert again.resumed_from == 4 and len(again.history) == 4 and again.stopped_early  # nothing retrained
    # patience is a stopping rule, not part of the run: without it the same run goes on to 8 epochs
    longer = train_model(cfg, train, val, TrainConfig(epochs=8, lr=3e-3, batch_size=4, seed=0), tmp_path / "p",
                         progress=False)
    assert longer.resumed_from == 4 and len(longer.history) == 8 and longer.best_epoch == 8
    assert not longer.stopped_early


def test_history_records_the_device_of_every_epoch(tmp_path):
    from drfkit.methods.train import history_frame

    train, val = tiny_data()
    res = train_model(model_config("pendulum", "no_dynamics"), train, val, train_cfg(epochs=2), tmp_path / "d",
                      progress=False)
    frame = history_frame(res.history + [{"epoch": 3, "train_loss": 0.0, "val_loss": 0.0, "lr": 0.1, "seconds": 1}])
    assert frame["device"].tolist() == ["cpu", "cpu", "cpu"]  # the last row predates the field


@pytest.mark.parametrize("patience", [-1, 1.5, True])
def test_bad_patience_is_rejected(patience):
    with pytest.raises(ValueError, match="patience"):
        TrainConfig(epochs=2, lr=1e-3, batch_size=2, seed=0, patience=patience)


def test_selection_audit_finds_best_epoch_and_longest_wait():
    import pandas as pd

    from drfkit.methods.train import selection_audit

    val = [3.0, 2.0, 2.5, 2.6, 1.0, 1.5, 1.6, 1.7]  # improvements at epochs 1, 2, 5: longest wait 3
    curves = pd.DataFrame({"model": "drf", "seed": 0, "epoch": range(1, 9), "val_loss": val,
                           "seconds": [10, 30, 20, 20, 1, 2, 3, 4], "device": ["cpu"] * 4 + ["cuda (X)"] * 4})
    row = selection_audit(curves, patience=4).iloc[0]
    assert (row["epochs"], row["best_epoch"], row["best_val_loss"], row["final_val_loss"]) == (8, 5, 1.0, 1.7)
    assert row["longest_wait"] == 3
    assert row["epoch_s_by_device"] == "cpu: 4 epochs, median 20 s; cuda (X): 4 epochs, median 2.5 s"


def test_load_latest_gives_the_last_epoch_weights(tmp_path, monkeypatch):
    import drfkit.methods.train as train_mod
    from drfkit.methods.train import load_latest

    train, val = tiny_data()
    val_losses = iter([1.0, 2.0, 3.0])  # best is epoch 1, training ends at 3
    monkeypatch.setattr(train_mod, "evaluate_loss", lambda *a, **k: next(val_losses))
    res = train_model(model_config("pendulum", "no_dynamics"), train, val, train_cfg(epochs=3), tmp_path / "l",
                      progress=False)
    best, last = load_checkpoint(res.best_path), load_latest(tmp_path / "l")
    assert best.checkpoint_meta["epoch"] == 1 and last.checkpoint_meta["epoch"] == 3 and not last.training
    assert state_equal(last.state_dict(), torch_load_checked(res.last_path)["model"])
    assert not state_equal(last.state_dict(), best.state_dict())


@pytest.mark.slow
def test_a_second_process_on_a_training_checkpoint_is_refused_and_writes_nothing(tmp_path):
    """Two real processes on one checkpoint: the second is refused with the holder named, the
    first's temp files are never swept from under it, and the first finishes normally."""
    from drfkit.util.io import LockedError

    epochs = 25
    stem = tmp_path / "shared"
    env = dict(os.environ, PYTHONPATH=str(REPO_ROOT), OMP_NUM_THREADS="1")
    proc = subprocess.Popen([sys.executable, "-m", "tests._train_worker", str(stem), str(epochs)],
                            cwd=REPO_ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        last = Path(f"{stem}-last.pt")
        deadline = time.time() + 120
        while not (last.exists() and torch_load_checked(last)["epoch"] >= 1):
            if proc.poll() is not None or time.time() > deadline:
                pytest.fail(f"worker ended early: {proc.stderr.read().decode()[-2000:]}")
            time.sleep(0.02)
        train, val = tiny_data()
        before = torch_load_checked(last)["epoch"]
        import drfkit.methods.train as train_module

        with pytest.raises(LockedError, match=f"process {proc.pid} on"):
            train_module.LOCK_WAIT_S, saved = 0.0, train_module.LOCK_WAIT_S
            try:
                train_model(model_config("pendulum", CONFIG_KIND), train, val, train_cfg(epochs=epochs), stem,
                            progress=False)
            finally:
                train_module.LOCK_WAIT_S = saved
        assert torch_load_checked(last)["epoch"] >= before
        assert proc.wait(timeout=300) == 0, proc.stderr.read().decode()[-2000:]
    finally:
        if proc.poll() is None:
            proc.kill()
    assert torch_load_checked(last)["epoch"] == epochs
    # once the first has finished, the same call is a cache hit
    train, val = tiny_data()
    assert train_model(model_config("pendulum", CONFIG_KIND), train, val, train_cfg(epochs=epochs), stem,
                       progress=False).resumed_from == epochs


@pytest.mark.parametrize("damage", ["delete", "truncate"])
def test_a_lost_or_corrupt_best_checkpoint_is_restored_from_last(tmp_path, damage):
    train, val = tiny_data()
    cfg = model_config("pendulum", CONFIG_KIND)
    res = train_model(cfg, train, val, train_cfg(epochs=2), tmp_path / "r", progress=False)
    good = torch_load_checked(res.best_path)
    if damage == "delete":
        res.best_path.unlink()
    else:
        res.best_path.write_bytes(res.best_path.read_bytes()[:100])
    again = train_model(cfg, train, val, train_cfg(epochs=2), tmp_path / "r", progress=False)
    assert again.resumed_from == 2   # nothing retrained
    assert state_equal(good["state_dict"], load_checkpoint(again.best_path).state_dict())
    # a -last.pt from before the best weights were kept in it: the message says what to delete
    state = torch_load_checked(res.last_path)
    del state["best"]
    torch.save(state, res.last_path)
    res.best_path.unlink()
    with pytest.raises(CorruptArtefactError, match="delete .*-last.pt too"):
        train_model(cfg, train, val, train_cfg(epochs=2), tmp_path / "r", progress=False)
    # a corrupt -last.pt: the same clear error type, naming the file
    res.last_path.write_bytes(b"not a checkpoint")
    with pytest.raises(CorruptArtefactError, match="r-last.pt is truncated or corrupt"):
        train_model(cfg, train, val, train_cfg(epochs=2), tmp_path / "r", progress=False)


def test_an_unfinished_run_resumes_only_with_its_thread_count(tmp_path):
    from drfkit.methods.train import ResumeMismatchError

    train, val = tiny_data()
    cfg = model_config("pendulum", CONFIG_KIND)
    train_model(cfg, train, val, train_cfg(epochs=3), tmp_path / "t", progress=False, stop_after_epochs=1)
    torch.set_num_threads(2)
    with pytest.raises(ResumeMismatchError, match=r"trained with 1 torch thread\(s\) and would resume with 2.*--threads 1"):
        train_model(cfg, train, val, train_cfg(epochs=3), tmp_path / "t", progress=False)
    torch.set_num_threads(1)
    assert train_model(cfg, train, val, train_cfg(epochs=3), tmp_path / "t", progress=False).resumed_from == 1


def test_selection_on_validation_l1_keeps_the_epoch_with_the_lowest_l1(tmp_path):
    train, val = tiny_data()
    cfg = model_config("pendulum", "no_dynamics")
    res = train_model(cfg, train, val, TrainConfig(epochs=4, lr=3e-3, batch_size=4, seed=0, select_on="l1"),
                      tmp_path / "l1", progress=False)
    l1 = [h["val_l1"] for h in res.history]
    assert res.best_epoch == int(np.argmin(l1)) + 1 and res.best_val_loss == min(l1)
    from drfkit.methods.train import history_frame

    assert history_frame(res.history)["val_l1"].tolist() == l1  # the training curves keep it
    model = load_checkpoint(res.best_path)
    with torch.no_grad():
        mean, _ = model(val.inputs)
    assert float((mean - val.targets).abs().mean()) == pytest.approx(min(l1), rel=1e-5)
    with pytest.raises(ValueError, match="select_on"):
        TrainConfig(epochs=1, lr=1e-3, batch_size=1, seed=0, select_on="mae")


def test_later_fields_at_their_defaults_leave_names_and_fingerprints_as_before():
    from drfkit.util.io import param_hash
    from drfkit.methods.train import fingerprint, naming_fields

    cfg = train_cfg()
    later = ("select_on", "objective", "beta", "mse_warmup", "lr_schedule", "weight_decay", "window", "prior_weight",
             "obs_weight", "skip_spans", "skip_fraction")
    before = {k: v for k, v in vars(cfg).items() if k not in later}  # a run made before these fields existed
    assert naming_fields(cfg) == {k: v for k, v in before.items() if k != "patience"}
    assert fingerprint({}, cfg, "d") == param_hash({"model": {}, "train": {k: v for k, v in before.items()
                                                                            if k not in ("epochs", "patience")},
                                                     "data": "d"})
    assert naming_fields(TrainConfig(epochs=4, lr=3e-3, batch_size=4, seed=0, select_on="l1"))["select_on"] == "l1"


def test_no_gradient_clipping_when_grad_clip_is_none(tmp_path, monkeypatch):
    seen = []
    real = torch.nn.utils.clip_grad_norm_
    monkeypatch.setattr(torch.nn.utils, "clip_grad_norm_", lambda params, max_norm: seen.append(max_norm) or
                        real(params, max_norm))
    train, val = tiny_data()
    train_model(model_config("pendulum", "no_dynamics"), train, val,
                TrainConfig(epochs=1, lr=3e-3, batch_size=4, seed=0, grad_clip=None), tmp_path / "n", progress=False)
    assert seen and all(m == float("inf") for m in seen)


def test_checkpoint_records_its_recipe_and_a_finished_run_loads_without_data(tmp_path):
    from drfkit.methods.train import finished_run

    train, val = tiny_data()
    config = model_config("pendulum", "no_dynamics")
    recipe = {"protocol": "book", "train_blackouts": None, "pend_train_max_noise": 0.5, "fresh_noise": True}
    stem = tmp_path / "run"
    assert finished_run(config, train_cfg(epochs=2), stem, data_key="k") is None      # nothing there yet
    res = train_model(config, train, val, train_cfg(epochs=2), stem, data_key="k", progress=False, recipe=recipe)
    assert torch_load_checked(res.best_path)["meta"]["recipe"] == recipe
    assert torch_load_checked(res.last_path)["recipe"] == recipe
    done = finished_run(config, train_cfg(epochs=2), stem, data_key="k")
    assert done is not None and done.best_epoch == res.best_epoch and done.best_path == res.best_path
    assert finished_run(config, train_cfg(epochs=3), stem, data_key="k") is None       # unfinished at 3 epochs
    assert finished_run(config, train_cfg(epochs=2), stem, data_key="other") is None   # other data
