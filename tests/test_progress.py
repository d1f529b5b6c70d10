"""Progress lines reach the pipeline's terminal through a file, and nothing is written without it."""
from __future__ import annotations

import io
import os
import subprocess
import sys

import pytest

from drfkit.util import progress


def test_steps_write_nothing_without_the_variable(tmp_path, monkeypatch):
    monkeypatch.delenv(progress.ENV, raising=False)
    monkeypatch.chdir(tmp_path)
    assert list(progress.steps(range(3), "x")) == [0, 1, 2]
    assert list(tmp_path.iterdir()) == []


def test_steps_report_counts_and_the_last_step(tmp_path, monkeypatch):
    path = tmp_path / "p.log"
    monkeypatch.setenv(progress.ENV, str(path))
    assert list(progress.steps(iter("abcd"), "letters", total=4, every_s=0.0)) == list("abcd")
    lines = path.read_text().splitlines()
    assert [line.split("(")[0].strip() for line in lines] == [f"letters: {k}/4" for k in range(1, 5)]
    assert "left" in lines[0] and "left" not in lines[-1]
    path.unlink()
    list(progress.steps(range(5), "slow", every_s=3600))  # only the last step within the interval
    assert path.read_text().count("\n") == 1 and "slow: 5/5" in path.read_text()


@pytest.mark.slow
def test_echo_copies_a_child_process_lines_and_cleans_up(tmp_path):
    stream, path = io.StringIO(), tmp_path / ".nb.progress.log"
    code = ("from drfkit.util.progress import steps\n"
            "for _ in steps(range(2), 'child', every_s=0.0): pass\n")
    with progress.Echo(path, stream, poll_s=0.01):
        assert os.environ[progress.ENV] == str(path)
        subprocess.run([sys.executable, "-c", code], check=True)
    assert "child: 1/2" in stream.getvalue() and "child: 2/2" in stream.getvalue()
    assert not path.exists() and progress.ENV not in os.environ
