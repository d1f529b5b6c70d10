"""The run manifest records what is needed to rerun, and notebooks add their own entries."""
import json

import pytest

from drfkit.book.manifest import NotebookTimer, read_manifest, update_manifest
from drfkit.study.params import load_profile, NOTEBOOKS
from drfkit.book.runtime import start_notebook


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
    timer = NotebookTimer("p", "05_timing", {"seeds": [0]})
    assert read_manifest("p")["notebooks"]["05_timing"]["status"] == "running"
    timer.finish()
    entry = read_manifest("p")["notebooks"]["05_timing"]
    assert entry["status"] == "ok" and entry["duration_s"] >= 0 and entry["params"] == {"seeds": [0]}


def test_start_notebook_validates_and_records(results):
    quick = load_profile("quick")
    namespace = {k: quick[k] for k in NOTEBOOKS["05_timing"]} | {"profile": "nb"}
    params, timer = start_notebook("05_timing", dict(namespace, json=json))  # modules are not parameters
    assert params.uncertainty.n_samples == quick["n_samples"]
    entry = read_manifest("nb")["notebooks"]["05_timing"]
    assert entry["params"]["seeds"] == quick["seeds"]


def test_cell_times_name_cells_by_code_and_replace_a_notebooks_rows(tmp_path, monkeypatch):
    import nbformat
    import pandas as pd

    from drfkit.book.manifest import cell_times, record_cell_times

    monkeypatch.setenv("DRF_RESULTS", str(tmp_path))
    nb = nbformat.v4.new_notebook()
    nb.cells = [nbformat.v4.new_markdown_cell("# title"),
                nbformat.v4.new_code_cell("# NBVAL_IGNORE_OUTPUT\nx = slow()\n"),
                nbformat.v4.new_code_cell("y = 1")]
    nb.cells[1].metadata["papermill"] = {"duration": 12.345}
    nb.cells[2].metadata["papermill"] = {"duration": 0.01}
    path = tmp_path / "nb.ipynb"
    nbformat.write(nb, path)
    assert cell_times(path) == [{"cell": 1, "seconds": 12.35, "first_line": "x = slow()"},
                                {"cell": 2, "seconds": 0.01, "first_line": "y = 1"}]
    record_cell_times("p", "01_a", path)
    record_cell_times("p", "02_b", path)
    record_cell_times("p", "01_a", path)           # a rerun replaces its own rows only
    table = pd.read_csv(tmp_path / "p" / "cell_times.csv")
    assert table.groupby("notebook").size().to_dict() == {"01_a": 2, "02_b": 2}
    (tmp_path / "bad.ipynb").write_text("{}")
    record_cell_times("p", "03_c", tmp_path / "bad.ipynb")  # unreadable: no rows, no error
    assert set(pd.read_csv(tmp_path / "p" / "cell_times.csv")["notebook"]) == {"01_a", "02_b"}
