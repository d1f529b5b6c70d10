"""Stopping a run: SIGTERM to ``make reproduce`` stops the whole tree (pipeline, Jupyter kernel),
puts the interrupted notebook's outputs back as they were, and the manifest says so; rerunning
skips the notebooks that had finished with the same parameters and code."""
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from drfkit.book import pipeline
from drfkit.study.params import load_profile, write_profile
from drfkit.util.paths import REPO_ROOT


# subprocesses, papermill, Dask or a book build: left out of the edit loop `pytest -m "not slow"`
pytestmark = pytest.mark.slow


def _tree(pid: int) -> list[int]:
    return pipeline._descendants(pid)


def test_sigterm_to_make_stops_the_tree_and_restores_the_outputs(tmp_path):
    values = load_profile("quick") | {"profile": "stopped"}
    profile = tmp_path / "stopped.yaml"
    write_profile(profile, values)
    root = tmp_path / "results" / "stopped"
    (root / "tables").mkdir(parents=True)
    (root / "tables" / "pendulum_mae.csv").write_text("old,table\n")   # a previous run's output
    env = dict(os.environ, DRF_RESULTS=str(tmp_path / "results"), OMP_NUM_THREADS="1")
    make = subprocess.Popen(["make", "--no-print-directory", "-C", str(REPO_ROOT), "reproduce",
                             f"PROFILE={profile}"], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        partial = root / "executed" / ".00_data_prep.partial.ipynb"
        deadline = time.time() + 180
        while not partial.exists():
            assert make.poll() is None and time.time() < deadline, make.stderr.read().decode()[-2000:]
            time.sleep(0.1)
        time.sleep(2.0)  # the kernel is running a cell
        tree = _tree(make.pid)
        assert len(tree) >= 2, tree  # the pipeline and its kernel
        (root / "tables" / "pendulum_mae.csv").write_text("half,new\n")   # as a cell writing would
        make.send_signal(signal.SIGTERM)
        make.wait(timeout=30)
        deadline = time.time() + 60
        while any(Path(f"/proc/{pid}").exists() for pid in tree) and time.time() < deadline:
            time.sleep(0.2)
        alive = [pid for pid in tree if Path(f"/proc/{pid}").exists()
                 and "zombie" not in Path(f"/proc/{pid}/status").read_text().lower()]
        assert not alive, alive
    finally:
        for pid in _tree(make.pid):
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        if make.poll() is None:
            make.kill()
    manifest = json.loads((root / "manifest.json").read_text())
    assert manifest["pipeline"]["status"] == "interrupted in 00_data_prep"
    assert manifest["notebooks"]["00_data_prep"]["status"] == "interrupted"
    assert (root / "tables" / "pendulum_mae.csv").read_text() == "old,table\n"
    assert not list((root / "executed").glob(".*partial*"))


def test_a_rerun_after_an_interruption_skips_what_finished(tmp_path, monkeypatch):
    monkeypatch.setenv("DRF_RESULTS", str(tmp_path))
    ran = []

    class FakePapermill:
        @staticmethod
        def execute_notebook(src, out, **kw):
            name = Path(src).stem
            ran.append(name)
            if name == "01_pendulum_training" and stop["now"]:
                raise KeyboardInterrupt
            Path(out).write_text("{}")

    stop = {"now": True}
    monkeypatch.setitem(sys.modules, "papermill", FakePapermill)
    only = ["00_data_prep", "01_pendulum_training"]
    assert pipeline.run("quick", only) == 130
    assert json.loads((tmp_path / "quick" / "manifest.json").read_text())["pipeline"]["status"] == \
        "interrupted in 01_pendulum_training"
    stop["now"] = False
    ran.clear()
    assert pipeline.run("quick", only) == 0
    assert ran == ["01_pendulum_training"]          # 00 finished with the same parameters and code
    ran.clear()
    assert pipeline.run("quick", only) == 0
    assert ran == only                              # after a finished pipeline, a rerun runs everything
    ran.clear()
    pipeline.run("quick", only, overrides={"pend_epochs": 2})
    assert ran == only                              # other parameters: nothing is skipped


def test_snapshot_and_restore_leave_checkpoints_alone(tmp_path):
    (tmp_path / "tables").mkdir()
    (tmp_path / "models").mkdir()
    (tmp_path / "tables" / "a.csv").write_text("a")
    before = pipeline.snapshot_outputs(tmp_path)
    (tmp_path / "tables" / "a.csv").write_text("changed")
    (tmp_path / "tables" / "b.csv").write_text("new")
    (tmp_path / "models" / "m-last.pt").write_text("a checkpoint written meanwhile")
    changed = pipeline.restore_outputs(tmp_path, before)
    assert sorted(p.name for p in changed) == ["a.csv", "b.csv"]
    assert (tmp_path / "tables" / "a.csv").read_text() == "a" and not (tmp_path / "tables" / "b.csv").exists()
    assert (tmp_path / "models" / "m-last.pt").exists()


def test_a_changed_code_hash_voids_the_rerun_skip(tmp_path, monkeypatch):
    """After an interruption a finished notebook is skipped only if its code is unchanged: an edit
    to the notebook or to drfkit (a new ``code_hash``) runs it again. Removing the code check from
    ``_resumable`` fails this."""
    monkeypatch.setenv("DRF_RESULTS", str(tmp_path))
    ran, stop = [], {"now": True}

    class FakePapermill:
        @staticmethod
        def execute_notebook(src, out, **kw):
            ran.append(Path(src).stem)
            if Path(src).stem == "01_pendulum_training" and stop["now"]:
                raise KeyboardInterrupt
            Path(out).write_text("{}")

    monkeypatch.setitem(sys.modules, "papermill", FakePapermill)
    only = ["00_data_prep", "01_pendulum_training"]
    assert pipeline.run("quick", only) == 130
    stop["now"], ran[:] = False, []
    real = pipeline.code_hash
    monkeypatch.setattr(pipeline, "code_hash", lambda name: real(name) + "-edited")
    assert pipeline.run("quick", only) == 0
    assert ran == only  # 00 finished before, but with other code: run again
