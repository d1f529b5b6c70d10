"""tools/slow_cells.py, the script behind docs/rerun_time.md's tables, on a small results folder."""
import json

import pandas as pd
import pytest


def test_it_lists_each_notebook_and_only_the_cells_over_the_threshold(tmp_path, load_tool):
    manifest = {"environment": {"git": {"commit": "abcdef0123", "dirty": False}},
                "pipeline": {"started": "2026-01-01T00:00:00", "durations_s": {"00_a": 10.0, "01_b": 90.0}}}
    (tmp_path / "manifest.json").write_text(json.dumps(manifest))
    pd.DataFrame({"notebook": ["00_a", "01_b", "01_b"], "cell": [1, 1, 2], "seconds": [10.0, 31.0, 29.0],
                  "first_line": ["x = 1", "y = f(a | b)", "z = 2"]}).to_csv(tmp_path / "cell_times.csv", index=False)
    text = load_tool("slow_cells").slow_cells(tmp_path, over=30)
    assert "total 100 s" in text and "commit abcdef0," in text
    assert "| 01_b | 90 | 90% | | | 1 |" in text and "| 00_a | 10 | 10% | | | 0 |" in text  # no CPU recorded
    assert "| 01_b | 1 | 31 | `y = f(a \\| b)` |" in text and "z = 2" not in text


def test_a_folder_without_a_run_names_the_command(tmp_path, load_tool):
    with pytest.raises(SystemExit, match="make reproduce"):
        load_tool("slow_cells").slow_cells(tmp_path)


def test_it_reports_the_cpu_seconds_and_the_cores_each_notebook_kept_busy(tmp_path, load_tool):
    manifest = {"environment": {"git": {"commit": "abcdef0123"}},
                "pipeline": {"durations_s": {"00_a": 10.0, "01_b": 90.0}, "cpu_s": {"00_a": 9.0, "01_b": 171.0},
                             "cores": 2}}
    (tmp_path / "manifest.json").write_text(json.dumps(manifest))
    pd.DataFrame({"notebook": ["00_a"], "cell": [1], "seconds": [1.0], "first_line": ["x"]}).to_csv(
        tmp_path / "cell_times.csv", index=False)
    text = load_tool("slow_cells").slow_cells(tmp_path, over=30)
    assert "| 01_b | 90 | 90% | 171 | 1.90 of 2 | 0 |" in text and "| 00_a | 10 | 10% | 9 | 0.90 of 2 | 0 |" in text


@pytest.mark.slow
def test_the_pipeline_counts_a_childs_cpu_seconds():
    """cpu_seconds includes a child process the pipeline waited for (a notebook's kernel is one)."""
    import subprocess
    import sys

    from drfkit.book.pipeline import cpu_seconds

    before = cpu_seconds()
    subprocess.run([sys.executable, "-c", "import time\nt = time.process_time()\nwhile time.process_time() - t < 0.5: pass"],
                   check=True)
    assert cpu_seconds() - before >= 0.45
