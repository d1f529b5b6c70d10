"""tools/bench_evaluation.py, the evaluation speed-ups' benchmark docs/rerun_time.md quotes, runs."""
import pytest


@pytest.mark.slow  # the whole tool: about 4 s
def test_evaluation_benchmark_runs_and_prints_every_row(capsys, load_tool):
    bench = load_tool("bench_evaluation")
    assert bench.main(["--sequences", "2", "--min-run-time", "0.01"]) == 0
    out = capsys.readouterr().out
    for row in ("F.max_pool2d", "max_pool_2x2", "bernoulli_ per rate", "shared uniforms",
                "predict_rates known_dynamics, 2 seq", "former", "now", "batch 1024"):
        assert row in out
