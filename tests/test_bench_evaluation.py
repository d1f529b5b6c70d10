"""tools/bench_evaluation.py, the evaluation speed-ups' benchmark docs/rerun_time.md quotes, runs."""
import importlib.util

from drfkit.util.paths import REPO_ROOT


def test_evaluation_benchmark_runs_and_prints_every_row(capsys):
    spec = importlib.util.spec_from_file_location("bench_evaluation", REPO_ROOT / "tools" / "bench_evaluation.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    assert bench.main(["--sequences", "2", "--min-run-time", "0.01"]) == 0
    out = capsys.readouterr().out
    for row in ("F.max_pool2d", "max_pool_2x2", "bernoulli_ per rate", "shared uniforms",
                "predict_rates known_dynamics, 2 seq", "former", "now", "batch 1024"):
        assert row in out
