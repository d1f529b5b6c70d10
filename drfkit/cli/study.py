"""The study and report layers' commands: ``report`` (the README's results section), ``claims``
(every verdict again from a profile's tables), ``ablation`` (protocol variants on validation
data), ``dynamics`` (is the filter filtering), ``bench`` (the inference benchmark) and
``simstats`` (the simulated pedestrian source's statistics)."""
from __future__ import annotations

import sys

from drfkit.cli import parser


def report(argv: list[str]) -> int:
    """``python -m drfkit report --profiles paper``: regenerate the README's results section (and
    each profile's report.md) from results/."""
    from drfkit.report.writers import update_readme

    ap = parser("report")
    ap.add_argument("--profiles", nargs="+", default=["paper"])
    ap.add_argument("--readme", help="the README whose results section is rewritten (default: the repository's)")
    args = ap.parse_args(argv)
    update_readme([(p, "make reproduce" if p == "paper" else f"make reproduce PROFILE={p}", p == "paper")
                   for p in args.profiles], args.readme)
    return 0


def claims(argv: list[str]) -> int:
    """``python -m drfkit claims --profile paper``: judge every claim again from the profile's tables
    (each claim with its notebook's parameters) and rewrite claims.csv and claims.md. Claims of the
    extension files named by ``DRFKIT_EXTENSIONS`` are judged with the book's."""
    from drfkit.study.claims.judge import write
    from drfkit.study.claims.table import CLAIMS
    from drfkit.study.params import for_notebook, load_profile
    from drfkit.util.registry import load_extensions

    load_extensions()
    ap = parser("claims", claims.__doc__, profile="paper")
    ap.add_argument("--ids", nargs="+", default=list(CLAIMS), choices=list(CLAIMS), help="the claims to judge")
    args = ap.parse_args(argv)
    values = load_profile(args.profile)
    table = None
    for notebook in dict.fromkeys(CLAIMS[i].notebook for i in args.ids):
        ids = [i for i in args.ids if CLAIMS[i].notebook == notebook]
        table = write(for_notebook(notebook, values), ids)
    for _, r in table[table["id"].isin(args.ids)].iterrows():
        print(f"{r['id']:4s} {r['protocol']:6s} {r['verdict']}")
    return 0


def _known_variants(names: list[str]) -> bool:
    """Whether every name is a variant (``drfkit.methods.protocols.variant_spec``); prints the error if not."""
    from drfkit.methods.protocols import variant_spec

    for name in names:
        try:
            variant_spec(name)
        except ValueError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return False
    return True


def screen(argv: list[str]) -> int:
    """``python -m drfkit screen --profile paper --budget fit --variants V --seeds 0 1 [--csv F]``: train (or load) the protocol
    ablation's runs of the variants and judge them by the screening rule on the validation split at the
    training noise only (``drfkit.study.dissection.screen_variants``); prints the table, writes it to --csv."""
    import torch

    from drfkit.methods.protocols import ABLATION_BUDGETS, VARIANTS
    from drfkit.study.dissection import screen_variants
    from drfkit.study.params import for_command
    from drfkit.util.io import atomic_write_csv

    ap = parser("screen", "Judge variants by the calibrated-gain screen (validation at the training noise only).",
                profile="paper")
    ap.add_argument("--budget", default="fit", choices=sorted(ABLATION_BUDGETS))
    ap.add_argument("--variants", nargs="+", required=True, help=f"from {sorted(VARIANTS)}")
    ap.add_argument("--seeds", nargs="*", type=int, default=[0, 1])
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", default=None, help="the ablation's folder (default results/<profile>/ablation)")
    ap.add_argument("--csv", default=None, help="also write the table here")
    ap.add_argument("--per-seed", action="store_true",
                    help="one row per seed, with 'failed' (r does not follow the noise) and the failure rate")
    ap.add_argument("--rule", default="calibrated", choices=["calibrated", "both_halves"],
                    help="the fourth round's calibrated-gain rule, or the fifth round's (a calibrated gain AND an "
                         "open loop that predicts; needs --reference)")
    ap.add_argument("--reference", default=None, metavar="VARIANT",
                    help="with --rule both_halves: the yardstick, a variant of the fourth round's calibrated-gain screen "
                         "(its row of results/<profile>/tables/pendulum_calibrated_screen.csv gives the MAE bound)")
    args = ap.parse_args(argv)
    if not _known_variants(args.variants) or (P := for_command("02_pendulum_dynamics", args.profile)) is None:
        return 2
    reference_mae = None
    if args.rule == "both_halves":
        import pandas as pd

        from drfkit.util.paths import results_dir

        path = results_dir(P.profile) / "tables" / "pendulum_calibrated_screen.csv"
        rows = pd.read_csv(path) if path.exists() else None
        if rows is None or args.reference not in set(rows["variant"]):
            print(f"--rule both_halves needs --reference naming a variant of {path} (the calibrated-gain screen: "
                  f"python -m drfkit screen --profile {args.profile} --variants ... --csv {path}); got "
                  f"{args.reference!r}")
            return 2
        reference_mae = float(rows.loc[rows["variant"] == args.reference, "mae"].iloc[0])
    torch.set_num_threads(args.threads)
    table = screen_variants(P, args.variants, args.seeds, args.budget, args.out, per_seed=args.per_seed,
                            rule=args.rule, reference_mae=reference_mae)
    print(table.round(4).to_string(index=False))
    if args.per_seed:
        for variant, rows in table.groupby("variant", sort=False):
            print(f"{variant}: {int(rows['failed'].sum())} of {len(rows)} seeds fail (validation rho(r, level) < 0.5)")
    if args.csv:
        atomic_write_csv(args.csv, table)
    return 0


def ablation(argv: list[str]) -> int:
    """``python -m drfkit ablation --profile paper --budget fit --variants V --seeds 0 1``: train and judge protocol
    variants on validation data (``drfkit.study.ablation``; resumable), or with ``--summary`` print
    the finished rows' summary."""
    import time

    import torch

    from drfkit.methods.protocols import ABLATION_BUDGETS, VARIANTS, summarise_ablation
    from drfkit.study.ablation import ROUNDS, ablation_table, run_variant, summary_markdown
    from drfkit.study.params import for_command

    ap = parser("ablation", "Train and judge protocol variants on validation data.", profile="paper")
    ap.add_argument("--budget", default="small", choices=sorted(ABLATION_BUDGETS))
    ap.add_argument("--variants", nargs="*", default=list(VARIANTS), help=f"from {sorted(VARIANTS)}")
    ap.add_argument("--seeds", nargs="*", type=int, default=[0, 1])
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", default=None, help="folder (default results/<profile>/ablation)")
    ap.add_argument("--summary", action="store_true", help="print the finished rows' summary and train nothing")
    ap.add_argument("--markdown", action="store_true", help="with --summary: as the markdown table docs/ quote")
    ap.add_argument("--round", type=int, choices=sorted(ROUNDS), help="with --summary: that round's variants only")
    args = ap.parse_args(argv)
    if (P := for_command("02_pendulum_dynamics", args.profile)) is None:
        return 2
    if args.summary:
        table = ablation_table(P, args.budget, args.out)
        if args.round is not None and len(table):
            table = table[table["variant"].isin(list(ROUNDS[args.round]))]
        summary = summarise_ablation(table)
        print(summary_markdown(summary) if args.markdown else summary.to_string(index=False))
        return 0
    if not _known_variants(args.variants):
        return 2
    torch.set_num_threads(args.threads)
    for name in args.variants:
        for seed in args.seeds:
            t0 = time.perf_counter()
            row = run_variant(P, name, seed, args.budget, args.out)
            print(f"{name} seed {seed}: mae 0.5 {row['mae_0.5']:.4f}  0.75 {row['mae_0.75']:.4f}  "
                  f"blackout {row['mae_blackout']:.4f}  r~noise {row['r_noise_spearman']:.2f}  "
                  f"gain pure/clean {row.get('gain_ratio_blackout', float('nan')):.2f}  "
                  f"prior {row.get('prior_ratio', float('nan')):.2f}  ({time.perf_counter() - t0:.0f} s)",
                  flush=True)
    return 0


def dynamics(argv: list[str]) -> int:
    """``python -m drfkit dynamics --profile paper --protocol book --models drf --seeds 0 [--last] [--dissect]``

    Prints the mechanism checks (rank correlation of r with the frame's noise, gains on clean and
    pure-noise frames, prediction ratio) and the blackout MAE of trained pendulum runs on the
    validation split, from their selected checkpoints or (``--last``) the last epoch of a run
    still training; ``--dissect`` adds the dissection (``drfkit.study.dissection.dissect_filters``).
    """
    import pandas as pd

    from drfkit.methods.protocols import PROTOCOLS
    from drfkit.methods.train import load_checkpoint, load_latest
    from drfkit.study import studies
    from drfkit.study.dynamics import probe
    from drfkit.study.params import for_command
    from drfkit.util.device import setup

    ap = parser("dynamics", profile="paper")
    ap.add_argument("--protocol", default="paper", choices=sorted(PROTOCOLS))
    ap.add_argument("--models", nargs="*", default=["drf"])
    ap.add_argument("--seeds", nargs="*", type=int, default=[0])
    ap.add_argument("--level", type=float, default=0.75, help="max noise of the mechanism checks")
    ap.add_argument("--split", default="val", choices=["val", "test"])
    ap.add_argument("--last", action="store_true", help="the last epoch's weights, not the selected ones")
    ap.add_argument("--dissect", action="store_true",
                    help="also the dissection (drfkit.study.dissection): variances against their errors per noise "
                         "level, the open loop by horizon and the oracle gain; name no_dynamics among --models "
                         "for its yardstick")
    ap.add_argument("--csv", default=None, help="with --dissect: write the interventions table here, and the horizons, "
                                                 "oracle-gain and calibration tables beside it (<stem>_horizons.csv, "
                                                 "<stem>_oracle_gain.csv, <stem>_calibration.csv)")
    ap.add_argument("--restarts", default=None, metavar="CSV",
                    help="only the validation-only restart rule on each --models kind's runs (every seed slot, the "
                         "replaced run too), written here (drfkit.study.dissection.restart_check)")
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args(argv)
    P = for_command("02_pendulum_dynamics", args.profile)
    if P is None:
        return 2
    setup(args.threads, P.seeds[0], "cpu")
    if args.restarts:
        from drfkit.study.dissection import restart_check
        from drfkit.util.io import atomic_write_csv

        table = pd.concat([restart_check(P, kind, args.protocol).assign(model=kind) for kind in args.models])
        with pd.option_context("display.width", 200, "display.max_columns", 30, "display.precision", 3):
            print(table.to_string(index=False))
        atomic_write_csv(args.restarts, table)
        return 0
    models = {}
    for kind in args.models:
        for seed in args.seeds:
            stem = studies.checkpoint_stem(P, "pendulum", kind, seed, args.protocol)
            if not (stem.parent / f"{stem.name}-best.pt").exists():
                print(f"error: no checkpoint {stem}-best.pt; train it with python -m drfkit train --profile "
                      f"{args.profile} --study pendulum --protocol {args.protocol} --models {kind} --seeds {seed}")
                return 3
            models[(kind, seed)] = load_latest(stem) if args.last else load_checkpoint(f"{stem}-best.pt")
            print(f"{kind} seed {seed}: epoch {models[(kind, seed)].checkpoint_meta.get('epoch')}")
    with pd.option_context("display.width", 200, "display.max_columns", 30, "display.precision", 3):
        filters = {k: m for k, m in models.items() if hasattr(m, "filter_diagnostics")}
        if filters and not args.dissect:  # the dissection measures what the probe does and more
            print(probe(P, filters, args.level, args.split).to_string(index=False))
        if args.dissect:
            from drfkit.study.dissection import calibration_summary, dissect_filters
            from drfkit.util.io import atomic_write_csv

            calibration, interventions, horizons, gains = dissect_filters(P, models, split=args.split)
            if len(calibration):
                print(calibration_summary(calibration).to_string())
            print(interventions.to_string(index=False))
            if len(horizons):
                print(horizons.pivot_table(index="h", columns=["model", "seed"], values="mae_clamped").round(4).to_string())
            if args.csv:
                from pathlib import Path

                path = Path(args.csv)
                atomic_write_csv(path, interventions)
                for suffix, table in (("horizons", horizons), ("oracle_gain", gains), ("calibration", calibration)):
                    atomic_write_csv(path.with_name(f"{path.stem}_{suffix}.csv"), table)
    return 0


def bench(argv: list[str]) -> int:
    """``python -m drfkit bench --profile quick|paper|path.yaml``: run the inference benchmark with
    the profile's n_samples and timing_* keys, print the table and write results/<profile>/bench/timing.csv
    and bench/manifest.json (``drfkit.book.bench_store``; notebook 05 reads them)."""
    import math

    import pandas as pd
    import torch

    from drfkit.book.bench_store import bench_dir, describe, write_bench
    from drfkit.study.bench import device_ratios
    from drfkit.study.params import for_notebook, load_profile

    ap = parser("bench", bench.__doc__, profile="quick")
    args = ap.parse_args(argv)
    P = for_notebook("bench", load_profile(args.profile))
    if P.threads:
        torch.set_num_threads(P.threads)
    table, record = write_bench(P, progress=lambda msg: print(f"timing {msg}", file=sys.stderr, flush=True))
    fmt = lambda v: "nan" if math.isnan(v) else f"{v:.4g}"  # noqa: E731
    print(f"devices measured: {', '.join(sorted(table['device'].astype(str).unique()))} "
          f"(torch {torch.__version__}; CUDA {'available' if torch.cuda.is_available() else 'not available'})")
    with pd.option_context("display.width", 200, "display.max_rows", None, "display.max_columns", None):
        print(table.to_string(index=False, float_format=fmt))
        ratios = device_ratios(table)
        if len(ratios):
            print("GPU over CPU (time per frame, CPU / GPU):")
            print(ratios.to_string(index=False, float_format=fmt))
    print(f"wrote {bench_dir(P.profile)}/timing.csv and manifest.json: {describe(record)}")
    return 0


def simstats(argv: list[str]) -> int:
    """``python -m drfkit simstats --profile paper``: the simulator's statistics at the profile's
    evaluation noise levels (markdown tables on stdout)."""
    from drfkit.data.sim_stats import body_span_m, dataset_size, error_autocorrelation, simulator_table
    from drfkit.study.params import for_notebook, load_profile
    from drfkit.study.sim_stats import simulate_profile

    ap = parser("simstats", profile="paper")
    args = ap.parse_args(argv)
    P = for_notebook("simstats", load_profile(args.profile))
    truth, records = simulate_profile(P)
    print(f"profile {args.profile}: {P.pedestrians.n_scenes} scenes x {P.pedestrians.frames_per_scene} keyframes, seed "
          f"{P.pedestrians.data_seed}; body span of the pinhole estimate {body_span_m(truth):.3f} m\n")
    for p, rec in records.items():
        print(f"p = {p:g}: " + ", ".join(f"{k} {v}" for k, v in dataset_size(truth, rec).items()))
    print()
    table = simulator_table(truth, records)
    cols = ["p", "bin", "n_true", "miss_rate", "height_px", "kp_miss_rate", "err_px_median", "err_rel_median",
            "gross_rate", "conf_mean", "pinhole_mae_m", "pinhole_bias_m"]
    print(table[cols].to_markdown(index=False, floatfmt=".3f"))
    print()
    for p, rec in records.items():
        ac = error_autocorrelation(truth, rec)
        print(f"p = {p:g}, lag 1 keyframe: keypoint error correlation {ac['keypoint']:+.4f} "
              f"({ac['n_keypoint_pairs']} keypoint pairs), pinhole relative depth error correlation "
              f"{ac['pinhole_rel']:+.3f} ({ac['n_pairs']} detection pairs)")
    return 0
