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
    assert "| 01_b | 90 | 90% | 1 |" in text and "| 00_a | 10 | 10% | 0 |" in text
    assert "| 01_b | 1 | 31 | `y = f(a \\| b)` |" in text and "z = 2" not in text


def test_a_folder_without_a_run_names_the_command(tmp_path, load_tool):
    with pytest.raises(SystemExit, match="make reproduce"):
        load_tool("slow_cells").slow_cells(tmp_path)
