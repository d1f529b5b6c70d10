"""The book layer's commands: ``reproduce`` (the notebooks of a profile), ``train`` (a profile's
checkpoints, here or on a Dask grid), ``budget``, ``manifest`` and ``regime``.

Every library call takes explicit arguments; the profile is read here (and in the notebooks).
"""
from __future__ import annotations

import os
import sys

from drfkit.cli import parser
from drfkit.study.params import ParameterError, load_profile, parse_overrides


def reproduce(argv: list[str]) -> int:
    """``python -m drfkit reproduce --profile quick``: every notebook of the profile with papermill
    into results/<profile>/executed/ (``drfkit.book.pipeline.run``)."""
    from drfkit.book import pipeline

    ap = parser("reproduce", profile="paper")
    ap.add_argument("--only", nargs="*", help="run only these notebooks (names without .ipynb)")
    ap.add_argument("--set", nargs="*", metavar="KEY=VALUE",
                    help="override profile parameters (YAML values); recorded in the manifest")
    ap.add_argument("--jobs", type=int, default=1,
                    help="N > 1: first train the training notebooks' missing runs on a Dask LocalCluster "
                         "of N workers (drfkit.book.grid), then run the notebooks; 1 (default): sequential")
    ap.add_argument("--scheduler", help="like --jobs, on this Dask scheduler (tcp://host:8786) or local:N")
    ap.add_argument("--remeasure", action="store_true",
                    help="measure the timings and compute the cached deterministic studies again "
                         "(drfkit.book.measurements) instead of reusing them")
    ap.add_argument("--workers", metavar="N|auto|tcp://HOST:PORT",
                    help="the evaluations as tasks on N single-threaded worker processes (drfkit.util.tasks; "
                         "auto: the usable cores; default: $DRF_WORKERS, else 1, in each notebook's kernel); "
                         "the tables are the same at any N")
    ap.add_argument("--cell-profile", type=float, metavar="SECONDS",
                    help="run every cell under cProfile and keep the profile of each cell slower than SECONDS "
                         "in results/<profile>/cell_profiles/ (drfkit.book.cell_profile)")
    args = ap.parse_args(argv)
    if args.cell_profile is not None:
        from drfkit.book.cell_profile import ENV as CELL_PROFILE_ENV

        if not args.cell_profile >= 0:
            ap.error("--cell-profile: seconds >= 0")
        os.environ[CELL_PROFILE_ENV] = str(args.cell_profile)  # the notebooks' kernels inherit it
    if args.workers is not None:
        from drfkit.util.tasks import ENV as WORKERS_ENV, task_workers

        try:
            task_workers(args.workers)
        except ValueError as exc:
            ap.error(f"--workers: {exc}")
        os.environ[WORKERS_ENV] = args.workers  # the notebooks' kernels inherit it
    if args.remeasure:
        from drfkit.book.measurements import REMEASURE_ENV

        os.environ[REMEASURE_ENV] = "1"  # the notebooks' kernels inherit it
    pipeline.die_with_parent()
    try:
        overrides = parse_overrides(args.set)
        if args.jobs > 1 or args.scheduler:
            from drfkit.book.grid import pretrain

            if pretrain(args.profile, overrides, args.only, args.scheduler or f"local:{args.jobs}",
                        out=lambda line: print(line, flush=True)) != 0:
                print("FAILED: training grid (the runs above); no notebook was run. Rerun the same command "
                      "to train what is missing", file=sys.stderr)
                return 1
        return pipeline.run(args.profile, args.only, overrides=overrides)
    except ParameterError as exc:
        print(f"parameter error: {exc}", file=sys.stderr)
        return 2


def train(argv: list[str]) -> int:
    """``python -m drfkit train --profile paper --study pendulum --models drf --seeds 0``

    Trains (or resumes) the checkpoints a profile's training notebook would train, and nothing
    else: the notebook later finds them and only evaluates. Run several of these with
    ``--threads 1`` on a multi-core machine, or one per session, to spread a long profile; a killed
    run resumes from its last finished epoch. With ``--scheduler`` every missing run is one task
    on dask.distributed (``drfkit.book.grid``).
    """
    from drfkit.methods.protocols import PROTOCOLS
    from drfkit.methods.train import ResumeMismatchError
    from drfkit.study import studies
    from drfkit.study.params import for_notebook
    from drfkit.study.registry import STUDIES
    from drfkit.util.device import setup
    from drfkit.util.io import CorruptArtefactError, LockedError

    ap = parser("train", train.__doc__.strip().splitlines()[0], profile="paper")
    ap.add_argument("--study", nargs="+", choices=sorted(STUDIES),
                    help="the study to train (one; with --scheduler any number, default all)")
    ap.add_argument("--models", nargs="*", help="model kinds (default: the profile's)")
    ap.add_argument("--seeds", nargs="*", type=int, help="model seeds (default: the profile's)")
    ap.add_argument("--threads", type=int, help="torch threads (default: the profile's)")
    ap.add_argument("--protocol", choices=sorted(PROTOCOLS),
                    help="training protocol (drfkit.methods.protocols): the paper's (the default) or the book's; "
                         "with --scheduler the default is every protocol the profile's notebooks train")
    ap.add_argument("--set", nargs="*", metavar="KEY=VALUE",
                    help="override profile values (VALUE in YAML), e.g. pend_patience=0 to train "
                         "runs that the early stop ended on to the last epoch")
    ap.add_argument("--scheduler", metavar="local[:N]|tcp://HOST:PORT",
                    help="train every missing run as one task on dask.distributed (drfkit.book.grid): "
                         "local[:N] starts N single-threaded workers here (default cores // threads), "
                         "an address connects to a running Dask scheduler")
    args = ap.parse_args(argv)
    if args.scheduler:
        return _train_on_grid(args)
    if not args.study or len(args.study) != 1:
        ap.error("--study takes exactly one study without --scheduler")
    study, protocol = args.study[0], args.protocol or "paper"
    try:
        values = load_profile(args.profile) | parse_overrides(args.set)
        P = for_notebook(studies.TRAINING_NOTEBOOK[study], values)
        known = studies.study_models(P, study, protocol)
        unknown = sorted(set(args.models or []) - set(known))
        if unknown:
            raise ParameterError(f"--models {unknown} are not models of the {study} study under the "
                                 f"{protocol} protocol in this profile; choose from {known}")
        if set(args.seeds or []) - set(P.seeds):
            raise ParameterError(f"--seeds {sorted(set(args.seeds) - set(P.seeds))} are not among the "
                                 f"profile's seeds {P.seeds}; the notebooks would never use them")
    except ParameterError as exc:
        print(f"parameter error: {exc}", file=sys.stderr)
        return 2
    setup(args.threads or P.threads, P.seeds[0], P.device)
    try:
        results = studies.train_models(P, study, progress=True, kinds=args.models or None, seeds=args.seeds or None,
                                       protocol=protocol)
    except (LockedError, CorruptArtefactError, ResumeMismatchError) as exc:  # said in one line, with the fix
        print(f"error: {exc}", file=sys.stderr)
        return 3
    for (kind, seed), res in results.items():
        print(f"{study} {kind} seed {seed}: {res.best_path}")
    return 0


def _train_on_grid(args) -> int:
    """``python -m drfkit train ... --scheduler ...``: every missing run of the parsed selection on
    the grid; 0 when all finished, 1 when one failed (each named), 2 on a parameter error."""
    from drfkit.book.grid import grid_runs, parse_scheduler, run_grid, study_params

    try:
        values = load_profile(args.profile) | parse_overrides(args.set)
        runs = grid_runs(values, args.study, args.models or None, args.seeds or None, args.protocol)
        threads = args.threads or study_params(values, runs[0].study if runs else "pendulum").threads or 1
        parse_scheduler(args.scheduler, threads)
    except ParameterError as exc:
        print(f"parameter error: {exc}", file=sys.stderr)
        return 2
    outcome = run_grid(values, runs, args.scheduler, threads, out=lambda line: print(line, flush=True),
                       write_curves=not args.models and not args.seeds)
    failed = [r for r, v in outcome.items() if isinstance(v, BaseException)]
    for run in failed:
        print(f"error: {run.name}: {type(outcome[run]).__name__}: {outcome[run]}", file=sys.stderr)
    return 1 if failed else 0


def budget(argv: list[str]) -> int:
    """``python -m drfkit budget --profile paper``: the measured training time of every model of
    the profile on this machine (``drfkit.book.budget``), printed and written to
    results/<profile>/training_budget.csv."""
    import torch

    from drfkit.book.budget import training_budget
    from drfkit.study import registry
    from drfkit.study.params import notebook_params
    from drfkit.study.profile import build_profile
    from drfkit.util.io import atomic_write_csv
    from drfkit.util.paths import results_dir

    ap = parser("budget", profile="paper")
    ap.add_argument("--min-run-time", type=float, default=1.0, help="seconds of timing per model")
    ap.add_argument("--threads", type=int, help="torch threads (default: the profile's)")
    args = ap.parse_args(argv)
    values = load_profile(args.profile)
    keys = set().union(*(notebook_params(s.training_notebook, values) for s in registry.STUDIES.values()))
    P = build_profile({k: values[k] for k in keys}, "python -m drfkit budget")
    if args.threads or P.threads:
        torch.set_num_threads(args.threads or P.threads)
    table = training_budget(P, args.min_run_time)
    print(table.to_string(index=False, float_format=lambda v: f"{v:.3g}"))
    print(f"total: {table['hours'].sum():.1f} hours of training on this machine, {table['hours_left'].sum():.1f} "
          f"left after the epochs in results/{P.profile}/models ({torch.get_num_threads()} torch threads)")
    path = atomic_write_csv(results_dir(P.profile) / "training_budget.csv", table)
    print(f"wrote {path}")
    return 0


def manifest(argv: list[str]) -> int:
    """``python -m drfkit manifest --cell-times PROFILE``: rebuild ``cell_times.csv`` from the
    executed notebooks of a profile's last pipeline run (the manifest's ``pipeline.notebooks``; the
    pipeline writes it after each notebook), dropping every other notebook's rows. ``--check PROFILE``:
    exit 1 unless the profile's results were made from this tree's sources (``manifest.check_results``)."""
    from drfkit.book.manifest import read_manifest, record_cell_times
    from drfkit.util.paths import NOTEBOOKS_DIR, results_dir

    ap = parser("manifest")
    ap.add_argument("--cell-times", metavar="PROFILE")
    ap.add_argument("--check", metavar="PROFILE",
                    help="exit 1 unless results/PROFILE was made from this tree's drfkit/, notebooks/src/ and params/")
    args = ap.parse_args(argv)
    if args.check:
        from drfkit.book.manifest import check_results

        same, words = check_results(args.check)
        print(words)
        return 0 if same else 1
    if not args.cell_times:
        ap.error("name --cell-times PROFILE or --check PROFILE")
    # the last pipeline's notebooks, else every notebook of the book (their sources' names)
    run = read_manifest(args.cell_times).get("pipeline", {}).get("notebooks") \
        or sorted(p.stem for p in NOTEBOOKS_DIR.glob("[0-9][0-9]_*.ipynb"))
    executed = [results_dir(args.cell_times, "executed") / f"{name}.ipynb" for name in run]
    executed = [p for p in executed if p.is_file()]
    if not executed:
        print(f"no executed notebooks under results/{args.cell_times}/executed/; run the pipeline first")
        return 1
    for path in executed:
        record_cell_times(args.cell_times, path.stem, path, run=[p.stem for p in executed])
    print(f"wrote results/{args.cell_times}/cell_times.csv from {len(executed)} notebooks: "
          f"{', '.join(p.stem for p in executed)}")
    return 0


def regime(argv: list[str]) -> int:
    """``python -m drfkit regime --profile paper``: train what the profile's regime map misses
    (one thread), evaluate it, write its tables and figure (as notebook 02 does) and print the
    seed-mean summary."""
    import matplotlib
    import pandas as pd
    import torch

    from drfkit.book.regime_map import write_outputs
    from drfkit.study.params import for_command
    from drfkit.study.regime import profile_map

    ap = parser("regime", profile="paper")
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args(argv)
    P = for_command("02_pendulum_dynamics", args.profile)
    if P is None:
        return 2
    torch.set_num_threads(args.threads)
    matplotlib.use("Agg")  # a command writes the figure, it shows nothing
    table = profile_map(P, progress=True)
    summary = write_outputs(P, table)
    with pd.option_context("display.width", 200, "display.max_columns", 30, "display.precision", 4):
        print(summary.to_string(index=False))
    return 0
