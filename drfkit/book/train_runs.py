"""``python -m drfkit train``: train (or resume) exactly the checkpoints a profile's notebooks
would use, one study at a time in this process or every missing run on a Dask grid
(``drfkit.book.grid``). The command's wiring lives in the book layer because it reaches the grid;
what a run is (its data, config and checkpoint name) is ``drfkit.study.studies``'.
"""
from __future__ import annotations

from drfkit.book.grid import main_grid
from drfkit.methods.protocols import PROTOCOLS
from drfkit.methods.train import ResumeMismatchError
from drfkit.study import studies
from drfkit.study.params import ParameterError, for_notebook, load_profile, parse_overrides
from drfkit.study.registry import STUDIES
from drfkit.util.device import setup
from drfkit.util.io import CorruptArtefactError, LockedError


def main(argv: list[str] | None = None) -> int:
    """``python -m drfkit train --profile paper --study pendulum --models drf --seeds 0``

    Trains (or resumes) the checkpoints a profile's training notebook would train, and
    nothing else: the notebook later finds them and only evaluates. Run several of these
    with ``--threads 1`` on a multi-core machine, or one per session, to spread a long
    profile; a killed run resumes from its last finished epoch.
    """
    import argparse
    import sys

    parser = argparse.ArgumentParser(description=main.__doc__.splitlines()[0])
    parser.add_argument("--profile", default="paper", help="name in params/ or a path to a YAML file")
    parser.add_argument("--study", nargs="+", choices=sorted(STUDIES),
                        help="the study to train (one; with --scheduler any number, default all)")
    parser.add_argument("--models", nargs="*", help="model kinds (default: the profile's)")
    parser.add_argument("--seeds", nargs="*", type=int, help="model seeds (default: the profile's)")
    parser.add_argument("--threads", type=int, help="torch threads (default: the profile's)")
    parser.add_argument("--protocol", choices=sorted(PROTOCOLS),
                        help="training protocol (drfkit.methods.protocols): the paper's (the default) or the book's; "
                             "with --scheduler the default is every protocol the profile's notebooks train")
    parser.add_argument("--set", nargs="*", metavar="KEY=VALUE",
                        help="override profile values (VALUE in YAML), e.g. pend_patience=0 to train "
                             "runs that the early stop ended on to the last epoch")
    parser.add_argument("--scheduler", metavar="local[:N]|tcp://HOST:PORT",
                        help="train every missing run as one task on dask.distributed (drfkit.book.grid): "
                             "local[:N] starts N single-threaded workers here (default cores // threads), "
                             "an address connects to a running Dask scheduler")
    args = parser.parse_args(argv)
    if args.scheduler:
        return main_grid(args)
    if not args.study or len(args.study) != 1:
        parser.error("--study takes exactly one study without --scheduler")
    args.study, args.protocol = args.study[0], args.protocol or "paper"
    notebook = studies.TRAINING_NOTEBOOK[args.study]
    try:
        values = load_profile(args.profile) | parse_overrides(args.set)
        P = for_notebook(notebook, values)
        known = studies.study_models(P, args.study, args.protocol)
        unknown = sorted(set(args.models or []) - set(known))
        if unknown:
            raise ParameterError(f"--models {unknown} are not models of the {args.study} study under the "
                                 f"{args.protocol} protocol in this profile; choose from {known}")
        if set(args.seeds or []) - set(P.seeds):
            raise ParameterError(f"--seeds {sorted(set(args.seeds) - set(P.seeds))} are not among the "
                                 f"profile's seeds {P.seeds}; the notebooks would never use them")
    except ParameterError as exc:
        print(f"parameter error: {exc}", file=sys.stderr)
        return 2
    setup(args.threads or P.threads, P.seeds[0], P.device)
    try:
        results = studies.train_models(P, args.study, progress=True, kinds=args.models or None, seeds=args.seeds or None,
                               protocol=args.protocol)
    except (LockedError, CorruptArtefactError, ResumeMismatchError) as exc:  # said in one line, with the fix
        print(f"error: {exc}", file=sys.stderr)
        return 3
    for (kind, seed), res in results.items():
        print(f"{args.study} {kind} seed {seed}: {res.best_path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
