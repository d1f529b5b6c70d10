"""A profile may name a base (``base: quick``) and hold only what it changes, with the same checks
as a whole profile (``drfkit.study.params.load_profile``)."""
import subprocess
import sys

import pytest

from drfkit.study.params import NOTEBOOKS, SPECS, ParameterError, load_profile, notebook_params
from drfkit.util.paths import REPO_ROOT


def test_a_two_line_profile_overrides_its_base_and_is_complete(tmp_path):
    (tmp_path / "mine.yaml").write_text("base: quick\npendulum:\n  epochs: 20\n")
    mine, quick = load_profile(tmp_path / "mine.yaml"), load_profile("quick")
    assert set(mine) == set(SPECS)
    assert {k for k in mine if mine[k] != quick[k]} == {"pend_epochs", "profile"}
    assert mine["pend_epochs"] == 20 and mine["profile"] == "mine"  # its own results folder, not the base's
    assert mine["pend_book_epochs"] == quick["pend_book_epochs"]    # a sibling key in the same section stays
    for notebook in NOTEBOOKS:
        notebook_params(notebook, mine)


def test_bases_chain_by_relative_path_and_a_value_replaces_the_base_s_whole(tmp_path):
    (tmp_path / "sub").mkdir()
    (tmp_path / "mid.yaml").write_text("base: paper\nprofile: middle\nseeds: [7]\n")
    (tmp_path / "sub" / "top.yaml").write_text("base: ../mid.yaml\npendulum:\n  eval_max_noise: [0.9]\n")
    top = load_profile(tmp_path / "sub" / "top.yaml")
    assert top["seeds"] == [7] and top["pend_eval_max_noise"] == [0.9]  # lists replaced, not merged
    assert top["profile"] == "top" and load_profile(tmp_path / "mid.yaml")["profile"] == "middle"
    assert top["pend_epochs"] == load_profile("paper")["pend_epochs"]


@pytest.mark.parametrize("text, fragment", [
    ("base: quick\npendulum:\n  epohcs: 3\n", "unknown parameter 'pendulum.epohcs'"),  # each file's keys checked
    ("base: quick\npend_epochs: 3\n", "is written as pendulum.epochs"),
    ("base: no_such_profile\n", r"the base of .*mine\.yaml\) does not exist; known profiles"),
    ("base: [quick]\n", "'base' names the profile this one overrides"),
    ("base: mine.yaml\n", "form a circle"),
])
def test_a_bad_override_or_base_is_refused_by_name(tmp_path, text, fragment):
    (tmp_path / "mine.yaml").write_text(text)
    with pytest.raises(ParameterError, match=fragment):
        load_profile(tmp_path / "mine.yaml")


def test_a_circle_through_two_files_is_refused(tmp_path):
    (tmp_path / "a.yaml").write_text("base: b.yaml\n")
    (tmp_path / "b.yaml").write_text("base: a.yaml\n")
    with pytest.raises(ParameterError, match="form a circle"):
        load_profile(tmp_path / "a.yaml")


@pytest.mark.slow
def test_an_overridden_value_meets_the_notebooks_checks(tmp_path):
    (tmp_path / "mine.yaml").write_text("base: quick\npendulum:\n  epochs: many\n")
    with pytest.raises(ParameterError, match="pend_epochs"):
        notebook_params("01_pendulum_training", load_profile(tmp_path / "mine.yaml"))
    proc = subprocess.run([sys.executable, "-m", "drfkit", "reproduce", "--profile", str(tmp_path / "mine.yaml")],
                          cwd=REPO_ROOT, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "pend_epochs" in proc.stderr and "== 00_data_prep" not in proc.stdout
