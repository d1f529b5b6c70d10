"""The commands the README and docs offer that no other test runs: each run end to end on the
committed paper profile (copied, so nothing in the repository is written) or on a small profile."""
import shutil

import pytest

from drfkit.cli import main as cli
from drfkit.study.params import load_profile, write_profile
from drfkit.util.paths import REPO_ROOT

PAPER = REPO_ROOT / "results" / "paper"


@pytest.fixture
def paper_copy(tmp_path, monkeypatch):
    """results/paper's tables, figures and top-level files (claims, manifest, timings, budget) under a
    temporary results root."""
    root = tmp_path / "results"
    for name in ("tables", "figures"):
        shutil.copytree(PAPER / name, root / "paper" / name)
    for path in PAPER.iterdir():
        if path.is_file():
            shutil.copy2(path, root / "paper" / path.name)
    monkeypatch.setenv("DRF_RESULTS", str(root))
    return root / "paper"


def test_claims_judges_the_committed_tables_into_the_committed_verdicts(paper_copy, capsys):
    (paper_copy / "claims.csv").unlink()
    (paper_copy / "claims.md").unlink()
    assert cli(["claims", "--profile", "paper"]) == 0
    assert (paper_copy / "claims.csv").read_bytes() == (PAPER / "claims.csv").read_bytes()
    assert (paper_copy / "claims.md").read_bytes() == (PAPER / "claims.md").read_bytes()
    assert "C7a  book   partly" in capsys.readouterr().out


def test_report_writes_the_committed_readme_section_and_report(paper_copy, tmp_path):
    readme = tmp_path / "README.md"
    text = (REPO_ROOT / "README.md").read_text()
    start, end = "<!-- results:start -->", "<!-- results:end -->"
    readme.write_text(text.split(start)[0] + start + "\nstale\n" + end + text.split(end)[1])
    (paper_copy / "report.md").unlink()
    assert cli(["report", "--profiles", "paper", "--readme", str(readme)]) == 0
    assert readme.read_text() == text
    assert (paper_copy / "report.md").read_bytes() == (PAPER / "report.md").read_bytes()
    readme.write_text("no markers")
    with pytest.raises(ValueError, match="lacks the markers"):
        cli(["report", "--profiles", "paper", "--readme", str(readme)])


def test_simstats_prints_the_simulator_tables_of_a_small_profile(tmp_path, capsys):
    path = tmp_path / "small.yaml"
    write_profile(path, load_profile("quick") | {"profile": "small", "ped_n_scenes": 3, "ped_frames_per_scene": 6})
    assert cli(["simstats", "--profile", str(path)]) == 0
    out = capsys.readouterr().out
    assert "profile " in out and "3 scenes x 6 keyframes" in out
    assert "pinhole_mae_m" in out and "|---" in out.replace(":", "-")  # the markdown table
    assert out.count("lag 1 keyframe") == len(load_profile("quick")["ped_eval_p"])


def test_rodbank_draws_like_pil(capsys):
    assert cli(["rodbank", "300", "--seed", "3"]) == 0
    assert "300 random angles drawn by the bank and by PIL: 0 differ" in capsys.readouterr().out
