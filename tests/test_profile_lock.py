"""One pipeline per profile, and what the next start does after a SIGKILL: real processes.

A second pipeline on a profile that a running pipeline holds is refused with the holder's PID
and host, having written nothing; after the first is killed with SIGKILL mid-notebook, the next
start says so in one line, puts that notebook's outputs back from the snapshot on disk, and goes
on. Fails on a pipeline without the profile lock (both run) or without the on-disk snapshot (the
half-written table stays)."""
import json
import os
import signal
import socket
import subprocess
import sys
import time

import pytest

from drfkit.book import pipeline
from drfkit.util.io import LockedError, exclusive_lock
from drfkit.study.params import load_profile, write_profile


# subprocesses, papermill, Dask or a book build: left out of the edit loop `pytest -m "not slow"`
pytestmark = pytest.mark.slow


def _pipeline(profile, env, *extra):
    return subprocess.Popen([sys.executable, "-m", "drfkit", "reproduce", "--profile", str(profile), "--only",
                             "00_data_prep", *extra], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)


def test_a_second_pipeline_is_refused_and_a_killed_one_is_undone_on_the_next_start(tmp_path, monkeypatch):
    # many more training sequences than the quick profile: the data prep (frames gathered from the rod bank,
    # fast) runs long enough to be caught
    values = load_profile("quick") | {"profile": "locked", "pend_train_sequences": 12000}
    profile = tmp_path / "locked.yaml"
    write_profile(profile, values)
    root = tmp_path / "results" / "locked"
    (root / "tables").mkdir(parents=True)
    (root / "tables" / "pendulum_mae.csv").write_text("old,table\n")
    monkeypatch.setenv("DRF_RESULTS", str(tmp_path / "results"))
    env = dict(os.environ, OMP_NUM_THREADS="1")
    env.pop(pipeline.PIPELINE_ENV, None)
    first = _pipeline(profile, env)
    try:
        lock, deadline = root / pipeline.PIPELINE_LOCK, time.time() + 120
        while not (lock.exists() and lock.read_text().strip()):  # the first holds the profile
            assert first.poll() is None and time.time() < deadline, first.stderr.read()[-2000:]
            time.sleep(0.05)
        second = _pipeline(profile, env)
        out, err = second.communicate(timeout=120)
        assert first.poll() is None, "the first pipeline ended before the second started: make it slower"
        assert second.returncode != 0
        assert f"process {first.pid} on {socket.gethostname()}" in err, err[-1500:]
        # the refused run wrote nothing: a pipeline that starts records its own start first
        started = json.loads((root / "manifest.json").read_text())["pipeline"]["started"]

        partial = root / "executed" / ".00_data_prep.partial.ipynb"

        def kernel_started():
            try:
                entry = json.loads((root / "manifest.json").read_text())["notebooks"]["00_data_prep"]
            except (OSError, ValueError, KeyError):
                return False
            return entry.get("status") == "running"

        while not (partial.exists() and kernel_started()):
            assert first.poll() is None and time.time() < deadline + 120, first.stderr.read()[-2000:]
            time.sleep(0.1)
        assert json.loads((root / "manifest.json").read_text())["pipeline"]["started"] == started
        assert (root / pipeline.SNAPSHOT_DIR / "00_data_prep.zip").exists()
        (root / "tables" / "pendulum_mae.csv").write_text("half,new\n")  # as a cell writing would
        first.send_signal(signal.SIGKILL)
        first.wait(timeout=30)
    finally:
        if first.poll() is None:
            first.kill()
    time.sleep(1.0)  # the kernel follows its parent
    assert json.loads((root / "manifest.json").read_text())["notebooks"]["00_data_prep"]["status"] == "running"
    # the next start: the lock is free (it died with its holder); the killed notebook is undone
    with exclusive_lock(root / pipeline.PIPELINE_LOCK, "test", announce_stale=False):
        pass  # and free again
    name = pipeline.recover_after_kill(root, "locked")
    assert name == "00_data_prep"
    assert (root / "tables" / "pendulum_mae.csv").read_text() == "old,table\n"
    assert not (root / pipeline.SNAPSHOT_DIR / "00_data_prep.zip").exists()
    manifest = json.loads((root / "manifest.json").read_text())
    assert manifest["notebooks"]["00_data_prep"]["status"] == "killed"
    assert manifest["pipeline"]["status"] == "killed in 00_data_prep"
    assert pipeline.recover_after_kill(root, "locked") is None  # said once


def test_a_stale_lock_is_taken_over_with_a_message(tmp_path, capsys):
    lock = tmp_path / ".pipeline.lock"
    lock.write_text("process 999999 on elsewhere")  # a holder that died without releasing
    with exclusive_lock(lock, "profile x", announce_stale=True):
        assert "process" in lock.read_text() and str(os.getpid()) in lock.read_text()
    assert "taking over the lock" in capsys.readouterr().err and "999999" not in lock.read_text()
    assert lock.read_text() == ""  # released normally: nothing to report next time


def test_a_notebook_on_its_own_holds_the_profile(tmp_path, monkeypatch):
    from drfkit.book import runtime

    monkeypatch.setenv("DRF_RESULTS", str(tmp_path))
    monkeypatch.delenv(pipeline.PIPELINE_ENV, raising=False)
    monkeypatch.setattr(runtime, "_HELD", {})
    holder = subprocess.Popen([sys.executable, "-c", "import time; from drfkit.book import runtime; "
                               "runtime.hold_profile('solo'); print('held', flush=True); time.sleep(60)"],
                              env=dict(os.environ), stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        try:
            runtime.hold_profile("solo")
            raise AssertionError("a second writer on the profile was not refused")
        except LockedError as exc:
            assert f"process {holder.pid}" in str(exc)
    finally:
        holder.kill()
        holder.wait()
