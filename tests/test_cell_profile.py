"""Per-cell profiles (drfkit.book.cell_profile): kept for the slow cells only, named by cell, off by default."""
import subprocess
import time
from types import SimpleNamespace

import pytest

from drfkit.book import cell_profile
from drfkit.util.paths import REPO_ROOT
from drfkit.cli import main as cli


class FakeEvents:
    def __init__(self):
        self.handlers = {}

    def register(self, name, fn):
        self.handlers[name] = fn


def run_cell(shell, source, count, work):
    shell.events.handlers["pre_run_cell"](SimpleNamespace(raw_cell=source))
    work()
    shell.events.handlers["post_run_cell"](SimpleNamespace(execution_count=count))


def busy(seconds):
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        sum(range(1000))


def test_only_cells_over_the_threshold_leave_a_profile(tmp_path):
    shell = SimpleNamespace(events=FakeEvents())
    assert cell_profile.install("04_ood", tmp_path, threshold=0.2, shell=shell)
    run_cell(shell, "# a comment\nfast = 1\n", 3, lambda: None)
    run_cell(shell, "\n# why\nslow = busy(0.3)\n", 4, lambda: busy(0.3))
    assert [p.name for p in tmp_path.iterdir()] == ["04_ood-cell04.txt"]
    text = (tmp_path / "04_ood-cell04.txt").read_text()
    assert text.splitlines()[1] == "slow = busy(0.3)" and "busy" in text and "cumulative" in text


def test_the_environment_switches_it_on_and_a_bad_value_is_named(monkeypatch):
    monkeypatch.delenv(cell_profile.ENV, raising=False)
    assert cell_profile.threshold_from_env() is None
    monkeypatch.setenv(cell_profile.ENV, "30")
    assert cell_profile.threshold_from_env() == 30.0
    monkeypatch.setenv(cell_profile.ENV, "soon")
    with pytest.raises(ValueError, match="CELL_PROFILE=30"):
        cell_profile.threshold_from_env()


@pytest.mark.slow
def test_make_passes_cell_profile_to_the_pipeline():
    def dry(*extra):
        return subprocess.run(["make", "-n", "reproduce", *extra], cwd=REPO_ROOT, capture_output=True,
                              text=True, check=True).stdout

    assert "--cell-profile 30" in dry("CELL_PROFILE=30") and "--cell-profile" not in dry()


def test_the_pipeline_flag_sets_the_environment_for_the_kernels(monkeypatch):
    import drfkit.book.pipeline as pipeline

    seen = {}
    monkeypatch.setenv(cell_profile.ENV, "")  # main sets it; monkeypatch puts back what was there
    monkeypatch.setattr(pipeline, "run", lambda *a, **k: seen.setdefault("threshold", cell_profile.threshold_from_env()) and 0)
    monkeypatch.setattr(pipeline, "die_with_parent", lambda: None)
    cli(["reproduce", "--profile", "quick", "--cell-profile", "12.5"])
    assert seen["threshold"] == 12.5
