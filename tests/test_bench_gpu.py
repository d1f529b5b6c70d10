"""tools/bench_gpu.py, the accelerator measurement prepared for a machine with a GPU, runs here on the
CPU rows and computes its GPU/CPU ratios from a table that has both."""
import pytest
import pandas as pd


@pytest.mark.slow  # the whole tool, a training included: about 12 s
def test_the_gpu_benchmark_runs_its_cpu_rows(capsys, tmp_path, load_tool):
    tool = load_tool("bench_gpu")
    out = tmp_path / "gpu.csv"
    assert tool.main(["--devices", "cpu", "--sequences", "2", "--train-sequences", "32", "--min-run-time", "0.01",
                      "--no-cpu-capture", "--out", str(out)]) == 0
    table = pd.read_csv(out)
    assert set(table["device"]) == {"cpu, 1 thread", "cpu, 2 threads"}
    assert set(table["what"]) == {"train drf", "train no_dynamics", "eval drf (eager step)",
                                  "filter loop drf (checked step)",
                                  "C6: Monoloco published / DRF 25 batched, batch 1"}
    assert (table["ms"] > 0).all() and (table.loc[table["what"] == "train drf", "epoch_s"] > 0).all()
    assert "no GPU seen" in capsys.readouterr().out or table["device"].str.startswith("cuda").any()


def test_gpu_ratios_divide_the_two_thread_cpu_time_by_the_gpu_time(load_tool):
    table = pd.DataFrame({"what": ["train drf", "train drf", "train drf", "eval drf (captured step)"],
                          "device": ["cpu, 1 thread", "cpu, 2 threads", "cuda (X)", "cuda (X)"],
                          "ms": [30.0, 20.0, 4.0, 1.0]})
    ratios = load_tool("bench_gpu").gpu_ratios(table)
    assert ratios["gpu_over_cpu2"].iloc[0] == 5.0 and pd.isna(ratios["gpu_over_cpu2"].iloc[1])
