"""The run manifest records what is needed to rerun, and notebooks add their own entries."""
import json

import pytest

from drfkit.manifest import NotebookTimer, read_manifest, update_manifest
from drfkit.params import load_profile, NOTEBOOKS
from drfkit.runtime import start_notebook


@pytest.fixture
def results(tmp_path, monkeypatch):
    monkeypatch.setenv("DRF_RESULTS", str(tmp_path))
    return tmp_path


def test_manifest_records_environment_and_pipeline(results):
    update_manifest("p", pipeline={"status": "running"})
    m = json.loads((results / "p" / "manifest.json").read_text())
    env = m["environment"]
    assert env["packages"]["torch"].startswith("2.13.0")
    assert env["torch_threads"] >= 1 and env["cpu"] and env["python"]
    assert "commit" in env["git"] and m["pipeline"]["status"] == "running"


def test_notebook_entry_has_params_and_duration(results):
    timer = NotebookTimer("p", "04_timing", {"seeds": [0]})
    assert read_manifest("p")["notebooks"]["04_timing"]["status"] == "running"
    timer.finish()
    entry = read_manifest("p")["notebooks"]["04_timing"]
    assert entry["status"] == "ok" and entry["duration_s"] >= 0 and entry["params"] == {"seeds": [0]}


def test_start_notebook_validates_and_records(results):
    quick = load_profile("quick")
    namespace = {k: quick[k] for k in NOTEBOOKS["04_timing"]} | {"profile": "nb"}
    params, timer = start_notebook("04_timing", dict(namespace, json=json))  # modules are not parameters
    assert params.n_samples == quick["n_samples"]
    entry = read_manifest("nb")["notebooks"]["04_timing"]
    assert entry["params"]["seeds"] == quick["seeds"]
