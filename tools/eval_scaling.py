"""The evaluation grid's wall time at 1 and N worker processes (``drfkit.util.tasks``), in one run.

    .venv/bin/python tools/eval_scaling.py                            # the paper profile's book-protocol pendulum models
    .venv/bin/python tools/eval_scaling.py --profile quick --sequences 20 --workers 1 2

Loads the profile's committed checkpoints of one (study, protocol) (every model, every seed), then times
``evaluate_study`` at two test levels on the first ``--sequences`` test sequences, once per worker count, each from
an empty prediction cache (a temporary results folder holds the data and the predictions; the checkpoints are read
from the profile's own folder), and checks that every worker count gives the same table, byte for byte. Prints a
table: workers, seconds, speed-up over one worker, and the CPU seconds of this process and its children. Nothing is
written under results/.
"""
from __future__ import annotations

import argparse
import os
import resource
import shutil
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def cpu_seconds() -> float:
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def _nothing(shared=None) -> None:
    return None


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--profile", default="paper")
    ap.add_argument("--study", default="pendulum")
    ap.add_argument("--protocol", default="book")
    ap.add_argument("--sequences", type=int, default=300)
    ap.add_argument("--workers", nargs="+", default=["1", "2"])
    args = ap.parse_args(argv)

    from drfkit.methods.train import load_checkpoint
    from drfkit.study import studies
    from drfkit.study.evaluate import evaluate_study
    from drfkit.study.params import for_notebook, load_profile
    from drfkit.util import tasks
    from drfkit.util.paths import models_dir

    P = for_notebook("04_ood_noise_evaluation", load_profile(args.profile))
    kinds = studies.study_models(P, args.study, args.protocol)
    found = {}
    for kind in kinds:
        for seed in P.seeds:
            stem = studies.checkpoint_stem(P, args.study, kind, seed, protocol=args.protocol)
            path = models_dir(P.profile) / f"{stem.name}-best.pt"
            if not path.exists():
                print(f"skipped {kind} seed {seed}: {path.name} is not trained (python -m drfkit train --profile "
                      f"{args.profile} --study {args.study} --protocol {args.protocol} --models {kind})")
                continue
            found[(kind, seed)] = load_checkpoint(path)
    if not found:
        raise SystemExit("no trained checkpoint of this study and protocol: nothing to time")
    levels = [float(v) for v in (P.pendulum.eval_max_noise if args.study == "pendulum" else P.pedestrians.eval_p)][:2]
    sequences = {float(lv): args.sequences for lv in levels}
    rows, tables = [], {}
    with tempfile.TemporaryDirectory() as tmp:
        os.environ["DRF_RESULTS"] = tmp
        studies.study_data(P, args.study, "test", levels[0])  # the data made once, outside the timings
        for lv in levels[1:]:
            studies.study_data(P, args.study, "test", lv)
        for workers in args.workers:
            shutil.rmtree(Path(tmp) / P.profile / "predictions", ignore_errors=True)
            os.environ[tasks.ENV] = workers
            tasks.task_workers()  # a bad value fails here
            if workers != "1":
                tasks.map_tasks(_nothing, [()] * 2)  # the cluster started outside the timing
            cpu0, t0 = cpu_seconds(), time.perf_counter()
            table = evaluate_study(P, args.study, levels, models=found, sequences=sequences)
            seconds = time.perf_counter() - t0
            tasks.close_workers()
            tables[workers] = table.to_csv(index=False)
            rows.append((workers, seconds, cpu_seconds() - cpu0))
    base = rows[0][1]
    print(f"{args.study}/{args.protocol}: {len(found)} models x {len(levels)} levels, {args.sequences} sequences each, "
          f"{os.cpu_count()} cores")
    print("| workers | seconds | speed-up over the first | CPU seconds (this process and its reaped children) |")
    print("|---|---|---|---|")
    for workers, seconds, cpu in rows:
        print(f"| {workers} | {seconds:.1f} | {base / seconds:.2f}x | {cpu:.1f} |")
    same = len(set(tables.values())) == 1
    print("tables byte for byte the same at every worker count:", same)
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
