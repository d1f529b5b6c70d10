"""The run manifest records what is needed to rerun, and notebooks add their own entries."""
import json
from pathlib import Path

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


@pytest.mark.slow
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


@pytest.mark.slow
def test_a_run_s_outputs_do_not_make_a_clean_tree_dirty_but_code_does(tmp_path, monkeypatch):
    """manifest.json's git.dirty: results/ (and $DRF_RESULTS inside the repository) are the run's
    own outputs; a changed or new file anywhere else is a change to the code."""
    import subprocess

    from drfkit.book.manifest import git_commit

    repo = tmp_path / "repo"
    (repo / "drfkit").mkdir(parents=True)
    (repo / "results" / "paper").mkdir(parents=True)
    (repo / "drfkit" / "a.py").write_text("x = 1\n")
    (repo / "results" / "paper" / "claims.csv").write_text("id\nC1\n")

    def git(*args):
        subprocess.run(["git", "-c", "user.name=t", "-c", "user.email=t@t", *args], cwd=repo, check=True,
                       capture_output=True)

    git("init", "-q")
    git("add", ".")
    git("commit", "-q", "-m", "one")
    monkeypatch.setenv("DRF_RESULTS", str(repo / "elsewhere"))
    assert git_commit(repo) == {"commit": git_commit(repo)["commit"], "dirty": False}
    assert len(git_commit(repo)["commit"]) == 40
    # a run rewrites a committed result and adds new ones: still clean
    (repo / "results" / "paper" / "claims.csv").write_text("id\nC2\n")
    (repo / "results" / "quick" / "tables").mkdir(parents=True)
    (repo / "results" / "quick" / "tables" / "t.csv").write_text("a\n1\n")
    (repo / "elsewhere" / "p").mkdir(parents=True)
    (repo / "elsewhere" / "p" / "manifest.json").write_text("{}")
    assert git_commit(repo)["dirty"] is False
    # code changed, or new code: dirty
    (repo / "drfkit" / "a.py").write_text("x = 2\n")
    assert git_commit(repo)["dirty"] is True
    git("checkout", "-q", "--", "drfkit/a.py")
    assert git_commit(repo)["dirty"] is False
    (repo / "drfkit" / "b.py").write_text("y = 1\n")
    assert git_commit(repo)["dirty"] is True


@pytest.mark.slow
def test_cell_times_describe_the_last_run_only(tmp_path, monkeypatch):
    """Rows of a notebook that is not in the run (one since renamed) are dropped, by the pipeline's
    record and by `python -m drfkit manifest --cell-times`, which rebuilds the file."""
    import nbformat
    import pandas as pd

    from drfkit.book.manifest import record_cell_times, update_manifest
    from drfkit.cli import main as cli

    monkeypatch.setenv("DRF_RESULTS", str(tmp_path))
    nb = nbformat.v4.new_notebook()
    nb.cells = [nbformat.v4.new_code_cell("x = 1")]
    nb.cells[0].metadata["papermill"] = {"duration": 2.0}
    executed = tmp_path / "p" / "executed"
    executed.mkdir(parents=True)
    for name in ("00_data_prep", "01_pendulum_training", "02_nuscenes_training"):  # the last: a former name
        nbformat.write(nb, executed / f"{name}.ipynb")
    for name in ("02_nuscenes_training", "00_data_prep"):
        record_cell_times("p", name, executed / f"{name}.ipynb")  # as a run under the former names left it
    path = tmp_path / "p" / "cell_times.csv"
    run = ["00_data_prep", "01_pendulum_training"]
    record_cell_times("p", "01_pendulum_training", executed / "01_pendulum_training.ipynb", run=run)
    assert sorted(set(pd.read_csv(path)["notebook"])) == run
    pd.DataFrame([{"notebook": "04_timing", "cell": 0, "seconds": 1.0, "first_line": "x"}]).to_csv(path, index=False)
    update_manifest("p", pipeline={"notebooks": run})
    assert cli(["manifest", "--cell-times", "p"]) == 0
    table = pd.read_csv(path)
    assert sorted(set(table["notebook"])) == run and table["seconds"].tolist() == [2.0, 2.0]


def test_results_are_checked_against_the_sources_they_were_made_from(tmp_path, monkeypatch):
    """The digest covers drfkit/, notebooks/src/ and params/ (not docs/ or tests/); ``manifest --check`` fails
    unless the profile's manifest recorded the tree's digest, and says what to rerun."""
    import json

    from drfkit.book.manifest import check_results, results_digest

    repo = tmp_path / "repo"
    for rel, text in (("drfkit/a.py", "x = 1\n"), ("notebooks/src/01.py", "# %%\n"), ("params/p.yaml", "a: 1\n"),
                      ("docs/d.md", "words\n")):
        (repo / rel).parent.mkdir(parents=True, exist_ok=True)
        (repo / rel).write_text(text)
    first = results_digest(repo)
    (repo / "docs/d.md").write_text("other words\n")
    assert results_digest(repo) == first
    (repo / "params/p.yaml").write_text("a: 2\n")
    assert results_digest(repo) != first
    monkeypatch.setenv("DRF_RESULTS", str(tmp_path / "results"))
    folder = tmp_path / "results" / "t"
    folder.mkdir(parents=True)
    same, words = check_results("t", repo)
    assert not same and "records no digest" in words
    (folder / "manifest.json").write_text(json.dumps({"environment": {"results_digest": results_digest(repo),
                                                                      "git": {"commit": "abc"}}}))
    assert check_results("t", repo) == (True, "results/t is this tree's (made by abc)")
    (repo / "drfkit/a.py").write_text("x = 2\n")
    same, words = check_results("t", repo)
    assert not same and "made by abc from other sources" in words and "make reproduce PROFILE=t" in words


def test_the_manifest_names_the_cpu_by_family_and_model():
    from drfkit.book.manifest import cpu_identity

    ident = cpu_identity()
    assert ident.get("name")
    if Path("/proc/cpuinfo").exists():
        assert {"vendor", "family", "model"} <= set(ident)


def test_the_check_command_answers_as_check_results(capsys):
    from drfkit.book.manifest import check_results
    from drfkit.cli import main as cli

    same, words = check_results("paper")
    assert cli(["manifest", "--check", "paper"]) == (0 if same else 1)
    assert words in capsys.readouterr().out
