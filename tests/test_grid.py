"""The training grid on dask.distributed (``drfkit.book.grid``): every run one task, trained by the
sequential command's own code, so a LocalCluster of 2 workers gives the same checkpoints as
``python -m drfkit train`` run by hand; a failing task is reported and the others go on; a
rerun trains only what is missing and resumes what was cut short.

The cluster tests take about a minute together (worker start-up dominates). Set
DRF_SKIP_SLOW=1 to skip them; ``make test`` runs them.
"""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest
import torch

from drfkit.book import grid
from drfkit.study import studies
from drfkit.study.params import ParameterError, load_profile, write_profile
from drfkit.cli import main as cli

slow = pytest.mark.skipif(bool(os.environ.get("DRF_SKIP_SLOW")), reason="DRF_SKIP_SLOW is set: Dask cluster tests")

# the quick profile, shrunk: one study, one protocol, 3 models x 2 seeds of 2 epochs on 4 sequences
# subprocesses, papermill, Dask or a book build: left out of the edit loop `pytest -m "not slow"`
pytestmark = pytest.mark.slow


TINY = {"profile": "tiny", "pend_train_sequences": 4, "pend_val_sequences": 2, "pend_test_sequences": 2,
        "pend_seq_len": 6, "pend_epochs": 2, "pend_batch_size": 2, "seeds": [0, 1], "pend_protocols": ["paper"]}
RUNS = 6


def _write_profile(path: Path, **extra) -> Path:
    write_profile(path, load_profile("quick") | TINY | extra)
    return path


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    return _write_profile(tmp_path_factory.mktemp("profile") / "tiny.yaml")


@pytest.fixture(scope="module")
def reference(tiny, tmp_path_factory):
    """The tiny grid trained by the sequential command, one thread: the numbers to match."""
    root = tmp_path_factory.mktemp("sequential")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("DRF_RESULTS", str(root))
        assert cli(["train", "--profile", str(tiny), "--study", "pendulum", "--threads", "1"]) == 0
    return root / "tiny"


@pytest.fixture(scope="module")
def cluster():
    """One LocalCluster of 2 single-threaded worker processes, reached by its tcp:// address."""
    from distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True) as c:
        yield c.scheduler_address


@pytest.fixture
def results(tmp_path, monkeypatch):
    monkeypatch.setenv("DRF_RESULTS", str(tmp_path / "results"))
    return tmp_path / "results" / "tiny"


def _tensors_equal(a, b, where):
    if isinstance(a, torch.Tensor):
        assert isinstance(b, torch.Tensor) and torch.equal(a, b), where
    elif isinstance(a, dict):
        assert a.keys() == b.keys(), where
        for k in a:
            _tensors_equal(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            _tensors_equal(x, y, f"{where}[{i}]")


def assert_same_checkpoints(ours: Path, theirs: Path, names=None):
    """Every ``*.pt`` of ``theirs/models`` (or ``names``) holds the same tensors in ``ours``."""
    names = names or sorted(p.name for p in (theirs / "models").glob("*.pt"))
    assert names and names == sorted(n for n in names if (ours / "models" / n).exists()), names
    for name in names:
        a = torch.load(ours / "models" / name, weights_only=False)
        b = torch.load(theirs / "models" / name, weights_only=False)
        if name.endswith("-best.pt"):
            _tensors_equal(a["state_dict"], b["state_dict"], name)
            assert a["meta"]["epoch"] == b["meta"]["epoch"], name
        else:
            for key in ("model", "optimiser", "rng_torch", "best"):
                _tensors_equal(a[key], b[key], f"{name}:{key}")
            assert a["epoch"] == b["epoch"] and a["best_epoch"] == b["best_epoch"], name
            strip = lambda h: [{k: v for k, v in row.items() if k != "seconds"} for row in h]  # noqa: E731
            assert strip(a["history"]) == strip(b["history"]), name


def _stem(profile, kind, seed):
    return studies.checkpoint_stem(grid.study_params(load_profile(profile), "pendulum"), "pendulum", kind, seed)


# ------------------------------------------------------------------------- without a cluster
def test_grid_runs_are_every_study_protocol_model_and_seed_of_the_profile():
    values = load_profile("quick")
    runs = grid.grid_runs(values)
    # pendulum: the paper protocol's 3 models and the book's 5 (it adds the calibrated-gain DRF and the
    # known-dynamics filter) x 2 seeds; pedestrians: 2 protocols x 4 models x 2 seeds, but Monoloco trains one set
    # of runs under both (its published schedule), so its book runs are not tasks again
    assert len(runs) == 6 + 10 + 8 + 6 and len(set(runs)) == len(runs)
    assert "known_dynamics" in {r.kind for r in runs if r.protocol == "book" and r.study == "pendulum"}
    assert "known_dynamics" not in {r.kind for r in runs if r.protocol == "paper"}
    assert {r.kind for r in runs if r.study == "pedestrians" and r.protocol == "book"} == {"drf", "no_dynamics", "lstm"}
    assert grid.grid_runs(values, ["pendulum"], ["lstm"], [1], "book") == [grid.Run("pendulum", "book", "lstm", 1)]
    assert {r.study for r in grid.grid_runs(values, None, ["monoloco"])} == {"pedestrians"}
    assert {r.study for r in grid.grid_runs(values, None, None, None, "book")} == {"pendulum", "pedestrians"}
    one_protocol = values | {"ped_protocols": ["paper"]}
    for bad, message in ((dict(studies=["pendulum"], kinds=["monoloco"]), "not models of the pendulum"),
                         (dict(seeds=[7]), "not among the profile's seeds"),
                         (dict(studies=["pedestrians"], protocol="blackout"), "not a protocol the pedestrians")):
        with pytest.raises(ParameterError, match=message):
            grid.grid_runs(values, **bad)
    with pytest.raises(ParameterError, match="not a protocol the pedestrians study trains in this profile"):
        grid.grid_runs(one_protocol, ["pedestrians"], protocol="book")
    assert {r.study for r in grid.grid_runs(one_protocol, None, None, None, "book")} == {"pendulum"}


def test_scheduler_argument():
    assert grid.parse_scheduler("local:3", 1) == ("local", 3)
    assert grid.parse_scheduler("local", 1) == ("local", max(1, grid.usable_cores()))
    assert grid.parse_scheduler("local", 10_000) == ("local", 1)
    assert grid.parse_scheduler("tcp://head:8786", 1) == ("tcp://head:8786", None)
    for bad in ("local:0", "local:x", "head:8786"):
        with pytest.raises(ParameterError):
            grid.parse_scheduler(bad, 1)


def test_without_scheduler_the_command_still_takes_exactly_one_study(tiny, capsys):
    for args in ([], ["--study", "pendulum", "pedestrians"]):
        with pytest.raises(SystemExit) as exc:
            cli(["train", "--profile", str(tiny), *args])
        assert exc.value.code == 2
    assert "exactly one study" in capsys.readouterr().err
    assert cli(["train", "--profile", str(tiny), "--scheduler", "nowhere"]) == 2


# ---------------------------------------------------------------------------- on a cluster
@slow
def test_local_cluster_of_two_gives_the_sequential_checkpoints(tiny, reference, results, capsys):
    assert cli(["train", "--profile", str(tiny), "--study", "pendulum", "--threads", "1",
                         "--scheduler", "local:2"]) == 0
    out = capsys.readouterr().out
    lines = [line for line in out.splitlines() if line.startswith("[")]
    assert len(lines) == RUNS and all("trained 2 epochs" in line and "best epoch" in line for line in lines), out
    assert "2 worker(s)" in out and f"{RUNS} trained, 0 already trained, 0 failed" in out
    assert_same_checkpoints(results, reference)
    # every run of the study finished, so the training curves are written as the sequential command does
    ours, theirs = (pd.read_csv(r / "tables" / "pendulum_training_curves.csv").drop(columns="seconds")
                    for r in (results, reference))
    pd.testing.assert_frame_equal(ours, theirs)


@slow
def test_a_failing_task_is_reported_and_the_others_go_on(tiny, reference, results, cluster, capsys):
    from drfkit.util.io import exclusive_lock

    corrupt, locked = _stem(tiny, "lstm", 1), _stem(tiny, "no_dynamics", 0)
    corrupt.parent.mkdir(parents=True, exist_ok=True)
    Path(f"{corrupt}-last.pt").write_bytes(b"not a checkpoint")
    args = ["--profile", str(tiny), "--study", "pendulum", "--threads", "1", "--scheduler", cluster]
    with exclusive_lock(locked.parent / f".{locked.name}.lock", "this test"):  # as another trainer would
        assert cli(["train", *args]) == 1
    captured = capsys.readouterr()
    assert f"FAILED (LockedError: checkpoint {locked} is being written by process {os.getpid()}" in captured.out
    assert "FAILED (CorruptArtefactError" in captured.out and f"{RUNS - 2} trained" in captured.out
    assert "error: pendulum/paper lstm seed 1: CorruptArtefactError" in captured.err
    assert not Path(f"{locked}-last.pt").exists()  # the locked run wrote nothing
    done = [p.name for p in (reference / "models").glob("*.pt") if not p.name.startswith((corrupt.name, locked.name))]
    assert len(done) == 2 * (RUNS - 2)
    assert_same_checkpoints(results, reference, sorted(done))


@slow
def test_a_rerun_trains_only_what_is_missing_and_resumes_what_was_cut_short(tiny, reference, results, cluster,
                                                                            capsys):
    from drfkit.methods.train import train_model

    P = grid.study_params(load_profile(tiny), "pendulum")
    torch.set_num_threads(1)
    # one run finished, one cut short after its first epoch, both by the sequential code
    assert cli(["train", "--profile", str(tiny), "--study", "pendulum", "--models", "drf", "--seeds", "0",
                         "--threads", "1"]) == 0
    from drfkit.util.io import param_hash

    train_model(studies.model_config("pendulum", "lstm", P), studies.study_data(P, "pendulum", "train"),
                studies.study_data(P, "pendulum", "val"), studies.train_config(P, "pendulum", "lstm", 1),
                _stem(tiny, "lstm", 1), data_key=param_hash(studies.study_data_key(P, "pendulum")), progress=False,
                stop_after_epochs=1)
    finished = Path(f"{_stem(tiny, 'drf', 0)}-best.pt")
    mtime = finished.stat().st_mtime_ns
    capsys.readouterr()
    assert cli(["train", "--profile", str(tiny), "--study", "pendulum", "--threads", "1", "--scheduler", cluster]) == 0
    out = capsys.readouterr().out
    assert f"{RUNS} runs, 1 already trained, {RUNS - 1} to train" in out
    assert "lstm seed 1: resumed at epoch 1, trained to epoch 2" in out
    assert finished.stat().st_mtime_ns == mtime  # not touched
    assert_same_checkpoints(results, reference)
    assert cli(["train", "--profile", str(tiny), "--study", "pendulum", "--threads", "1", "--scheduler", cluster]) == 0
    assert f"{RUNS} runs, {RUNS} already trained, 0 to train" in capsys.readouterr().out


@slow
def test_pipeline_trains_the_grid_before_the_notebooks_only_when_asked(tiny, reference, results, cluster,
                                                                       monkeypatch, capsys):
    from drfkit.book import pipeline

    calls = []
    monkeypatch.setattr(pipeline, "run", lambda *a, **k: calls.append(a) or 0)
    only = ["--only", "01_pendulum_training", "05_timing"]
    assert cli(["reproduce", "--profile", str(tiny), *only]) == 0  # JOBS=1: sequential, the notebooks train
    assert len(calls) == 1 and not list(results.glob("models/*.pt"))
    assert cli(["reproduce", "--profile", str(tiny), *only, "--scheduler", cluster]) == 0
    assert len(calls) == 2 and f"grid: {RUNS} trained" in capsys.readouterr().out
    assert_same_checkpoints(results, reference)  # threads: 0 in the profile -> one thread per run
    assert cli(["reproduce", "--profile", str(tiny), "--only", "05_timing", "--jobs", "2"]) == 0  # no training notebook
    assert len(calls) == 3


@slow
def test_killing_the_client_mid_grid_and_rerunning_resumes(tmp_path, cluster, capsys):
    """The client (and so its LocalCluster) is killed with SIGKILL while runs train; the workers die
    with it, their locks go, and a rerun resumes the cut runs from their last finished epoch."""
    EPOCHS = 6
    profile = _write_profile(tmp_path / "tiny.yaml", pend_train_sequences=16, pend_seq_len=10, pend_epochs=EPOCHS,
                             pend_batch_size=4, pend_models=["drf", "lstm"], seeds=[0])
    env = dict(os.environ, DRF_RESULTS=str(tmp_path / "results"), OMP_NUM_THREADS="1")
    models = tmp_path / "results" / "tiny" / "models"
    proc = subprocess.Popen([sys.executable, "-m", "drfkit", "train", "--profile", str(profile), "--study", "pendulum",
                             "--threads", "1", "--scheduler", "local:2"], env=env, start_new_session=True,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 120
        while not list(models.glob("*-last.pt")) and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.2)
        assert proc.poll() is None, proc.stdout.read().decode()[-2000:]
        assert list(models.glob("*-last.pt")), "no epoch finished in time"
        os.kill(proc.pid, signal.SIGKILL)  # the client alone; its workers notice and exit
        proc.wait(10)
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:  # wait for the orphaned workers (same session) to be gone
            try:
                os.killpg(proc.pid, 0)
                time.sleep(0.2)
            except ProcessLookupError:
                break
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)  # whatever is left of what this test started
        except ProcessLookupError:
            pass
        proc.stdout.close()
    epochs = {p.name: torch.load(p, weights_only=False)["epoch"] for p in models.glob("*-last.pt")}
    cut = [n for n, e in epochs.items() if e < EPOCHS]
    assert cut, epochs  # killed mid-run
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("DRF_RESULTS", str(tmp_path / "results"))
        assert cli(["train", "--profile", str(profile), "--study", "pendulum", "--threads", "1",
                             "--scheduler", cluster]) == 0
    out = capsys.readouterr().out
    assert out.count("resumed at epoch") == len(cut), out
    assert all(torch.load(p, weights_only=False)["epoch"] == EPOCHS for p in models.glob("*-last.pt"))
    assert len(list(models.glob("*-best.pt"))) == 2
