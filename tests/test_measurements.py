"""The measurement cache: a second call with the same key computes nothing and returns the same
value; any change to the arguments, the drfkit code or (for a timing) the machine misses;
REMEASURE forces a new measurement; a damaged entry is computed again."""
from __future__ import annotations

import subprocess

import pandas as pd
import pytest
import torch

import drfkit.book.measurements as measurements
from drfkit.book.manifest import NotebookTimer, read_manifest
from drfkit.book.measurements import cached, fingerprint
from drfkit.models import build_model, default_config
from drfkit.util.paths import REPO_ROOT
from drfkit.methods.train import SequenceData, TrainConfig
from drfkit.cli import main as cli

torch.set_num_threads(1)
CALLS: list[tuple] = []


def slow_study(x: torch.Tensor, cfg: dict, scale: float = 1.0) -> pd.DataFrame:
    CALLS.append((x.sum().item(), scale))
    return pd.DataFrame({"value": (x.double() * scale).tolist(), "name": [cfg["name"]] * len(x)})


@pytest.fixture(autouse=True)
def results_in_tmp(tmp_path, monkeypatch):
    monkeypatch.setenv("DRF_RESULTS", str(tmp_path))
    monkeypatch.setenv(measurements.REMEASURE_ENV, "")  # and restored after the test, whatever it sets
    CALLS.clear()
    measurements.reused(clear=True)
    yield
    measurements.reused(clear=True)


def entries(profile="p"):
    return sorted(measurements.measurements_dir(profile).glob("*.json"))


def test_a_second_call_reuses_the_value_exactly_and_says_so(capsys):
    x = torch.tensor([0.1, 0.2, 1 / 3])
    first = cached("p", slow_study, x, {"name": "a"}, scale=2.0, timing=True)
    again = cached("p", slow_study, x.clone(), {"name": "a"}, scale=2.0, timing=True)
    assert len(CALLS) == 1 and len(entries()) == 1
    pd.testing.assert_frame_equal(first, again, check_exact=True)
    pd.testing.assert_frame_equal(again, slow_study(x, {"name": "a"}, scale=2.0), check_exact=True)
    out = capsys.readouterr().out
    assert "slow_study: reused, measured on this machine" in out and "REMEASURE=1" in out
    (entry,) = measurements.reused()
    assert entry["fn"].endswith("slow_study") and entry["timing"] is True


@pytest.mark.parametrize("change", ["tensor", "dict", "float"])
def test_any_change_of_an_argument_misses(change):
    x, cfg, scale = torch.tensor([1.0, 2.0]), {"name": "a"}, 1.0
    cached("p", slow_study, x, cfg, scale=scale, timing=False)
    if change == "tensor":
        x = torch.tensor([1.0, 2.001])
    elif change == "dict":
        cfg = {"name": "b"}
    elif change == "float":
        scale = 1.0 + 1e-12
    cached("p", slow_study, x, cfg, scale=scale, timing=False)
    assert len(CALLS) == 2 and len(entries()) == 2


def test_the_machine_is_in_the_key_of_a_timing_only(monkeypatch):
    x = torch.ones(2)
    cached("p", slow_study, x, {"name": "a"}, timing=True)
    cached("p", slow_study, x, {"name": "a"}, timing=False)
    assert len(CALLS) == 2
    other = dict(measurements.machine_fingerprint(), torch_threads=99)
    monkeypatch.setattr(measurements, "machine_fingerprint", lambda: other)
    cached("p", slow_study, x, {"name": "a"}, timing=False)
    assert len(CALLS) == 2  # a deterministic result does not depend on the machine
    cached("p", slow_study, x, {"name": "a"}, timing=True)
    assert len(CALLS) == 3  # a timing does


def test_a_change_of_the_drfkit_code_misses(monkeypatch):
    cached("p", slow_study, torch.ones(2), {"name": "a"}, timing=False)
    monkeypatch.setattr(measurements, "code_sha256", lambda: "edited")
    cached("p", slow_study, torch.ones(2), {"name": "a"}, timing=False)
    assert len(CALLS) == 2


def test_code_hash_covers_every_drfkit_source():
    import hashlib

    digest = hashlib.sha256()
    for path in sorted((REPO_ROOT / "drfkit").rglob("*.py")):
        digest.update(path.relative_to(REPO_ROOT).as_posix().encode() + b"\0" + path.read_bytes())
    assert measurements.code_sha256() == digest.hexdigest()


def test_remeasure_measures_again_and_overwrites(monkeypatch):
    x = torch.ones(2)
    cached("p", slow_study, x, {"name": "a"}, timing=True)
    monkeypatch.setenv(measurements.REMEASURE_ENV, "1")
    cached("p", slow_study, x, {"name": "a"}, timing=True)
    assert len(CALLS) == 2 and len(entries()) == 1
    monkeypatch.setenv(measurements.REMEASURE_ENV, "0")
    cached("p", slow_study, x, {"name": "a"}, timing=True)
    assert len(CALLS) == 2


def test_a_damaged_entry_is_computed_again():
    x = torch.ones(2)
    cached("p", slow_study, x, {"name": "a"}, timing=False)
    (path,) = entries()
    path.write_bytes(path.read_bytes()[:20])
    value = cached("p", slow_study, x, {"name": "a"}, timing=False)
    assert len(CALLS) == 2 and value["value"].tolist() == [1.0, 1.0]
    cached("p", slow_study, x, {"name": "a"}, timing=False)
    assert len(CALLS) == 2  # and stored whole again


def test_profile_none_switches_the_cache_off(tmp_path):
    cached(None, slow_study, torch.ones(2), {"name": "a"}, timing=False)
    cached(None, slow_study, torch.ones(2), {"name": "a"}, timing=False)
    assert len(CALLS) == 2 and not list(tmp_path.rglob("*.json"))


def test_fingerprint_follows_content():
    torch.manual_seed(0)
    a = build_model(default_config("drf", "keypoints", 1)).eval()
    torch.manual_seed(0)
    b = build_model(default_config("drf", "keypoints", 1)).eval()
    assert fingerprint({("drf", 0): a}) == fingerprint({("drf", 0): b})
    with torch.no_grad():
        next(b.parameters()).view(-1)[0] += 1e-6
    assert fingerprint(a) != fingerprint(b)
    assert fingerprint(a) != fingerprint(a.train())  # dropout on: another computation
    data = SequenceData(torch.zeros(2, 3, 4), torch.zeros(2, 3, 1))
    assert fingerprint(data) != fingerprint(SequenceData(torch.zeros(2, 3, 4), torch.ones(2, 3, 1)))
    cfg = TrainConfig(epochs=1, lr=1e-3, batch_size=2, seed=0)
    assert fingerprint(cfg) != fingerprint(TrainConfig(epochs=2, lr=1e-3, batch_size=2, seed=0))
    assert fingerprint([1, 2]) != fingerprint((1, 2)) and fingerprint(1) != fingerprint(1.0)
    with pytest.raises(TypeError, match="cannot key a builtins.function"):
        fingerprint({"callback": lambda: 0})


def test_the_notebook_manifest_lists_what_was_reused():
    x = torch.ones(2)
    cached("p", slow_study, x, {"name": "a"}, timing=True)
    timer = NotebookTimer("p", "01_pendulum_training", {})
    cached("p", slow_study, x, {"name": "a"}, timing=True)
    timer.finish()
    (entry,) = read_manifest("p")["notebooks"]["01_pendulum_training"]["reused_measurements"]
    assert entry["fn"].endswith("slow_study") and entry["timing"] and entry["seconds"] >= 0
    assert measurements.reused() == []  # the next notebook starts with an empty list


@pytest.mark.slow
def test_make_passes_remeasure_to_the_pipeline():
    def dry(*extra):
        return subprocess.run(["make", "-n", "reproduce", *extra], cwd=REPO_ROOT, capture_output=True,
                              text=True, check=True).stdout

    assert "--remeasure" in dry("REMEASURE=1") and "--remeasure" not in dry() + dry("REMEASURE=0")


def test_the_pipeline_flag_sets_the_environment_for_the_kernels(monkeypatch):
    import drfkit.book.pipeline as pipeline

    seen = {}

    def fake_run(*args, **kwargs):
        seen["env"] = measurements.remeasure_requested()
        return 0

    monkeypatch.setattr(pipeline, "run", fake_run)
    monkeypatch.setattr(pipeline, "die_with_parent", lambda: None)
    cli(["reproduce", "--profile", "quick", "--remeasure"])
    assert seen["env"] is True


def test_a_drfkit_computation_is_keyed_by_its_import_closure(tmp_path):
    """An edit to a module the computation imports (directly, inside a function, or through a package's
    __init__) changes its key; an edit to a module it never imports does not."""
    files = {"drfkit/__init__.py": "", "drfkit/a/__init__.py": "", "drfkit/a/study.py":
             "from drfkit.b.maths import f\n\ndef g():\n    from drfkit.b import later\n    return f()\n",
             "drfkit/b/__init__.py": "", "drfkit/b/maths.py": "def f():\n    return 1\n",
             "drfkit/b/later.py": "x = 1\n", "drfkit/c/__init__.py": "", "drfkit/c/figure.py": "y = 1\n"}
    for rel, text in files.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text)

    def key():
        measurements.import_graph.cache_clear()
        return measurements.closure_sha256("drfkit.a.study", tmp_path)
    first = key()
    (tmp_path / "drfkit/c/figure.py").write_text("y = 2\n")
    assert key() == first                      # never imported
    for rel in ("drfkit/b/maths.py", "drfkit/b/later.py", "drfkit/b/__init__.py", "drfkit/__init__.py"):
        before = key()
        (tmp_path / rel).write_text((tmp_path / rel).read_text() + "# edited\n")
        assert key() != before, rel
    assert measurements._code_key("tests.test_measurements") == measurements.code_sha256()
