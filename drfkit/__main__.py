"""``python -m drfkit <command> [args]``: every command of the book, one entry point.

Each command is the ``main(argv)`` of one module, imported only when it runs (so ``--help`` here
loads nothing heavy, and this file adds no import edge to the package's graph);
``python -m drfkit.<package>.<module>`` runs the same ``main``.
"""
from __future__ import annotations

import importlib
import sys

# command -> (module whose main(argv) runs it, one line of help)
COMMANDS: dict[str, tuple[str, str]] = {
    "reproduce": ("drfkit.book.pipeline", "run every notebook of a profile (make reproduce)"),
    "train": ("drfkit.book.train_runs", "train or resume a profile's checkpoints, here or on a Dask grid"),
    "budget": ("drfkit.book.budget", "how long a profile's training takes on this machine"),
    "manifest": ("drfkit.book.manifest", "rebuild cell_times.csv from a profile's executed notebooks"),
    "regime": ("drfkit.book.regime_map", "the noise-regime map: train, evaluate, write its tables and figure"),
    "report": ("drfkit.report.writers", "regenerate the README's results section and report.md"),
    "claims": ("drfkit.study.claims.judge", "judge every claim again from a profile's tables (claims.csv, claims.md)"),
    "ablation": ("drfkit.study.ablation", "the protocol ablation on validation data"),
    "dynamics": ("drfkit.study.dynamics", "is the filter filtering: a run's mechanism diagnostics"),
    "bench": ("drfkit.study.bench", "the inference benchmark (make bench), results/<profile>/timing.csv"),
    "simstats": ("drfkit.study.sim_stats", "statistics of the simulated pedestrian source"),
    "nuscenes": ("drfkit.data.nuscenes", "nuScenes: write salt-and-pepper noisy copies of the images"),
    "rodbank": ("drfkit.data.rod_bank", "check the pendulum's rod bank against PIL's drawing on N random angles"),
}


def usage() -> str:
    width = max(map(len, COMMANDS))
    lines = ["usage: python -m drfkit <command> [args]   (python -m drfkit <command> --help: its options)",
             "", "commands:"]
    lines += [f"  {name:<{width}}  {text}" for name, (_, text) in COMMANDS.items()]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help", "help"):
        print(usage())
        return 0 if argv else 2
    name, rest = argv[0], argv[1:]
    if name not in COMMANDS:
        print(f"unknown command {name!r}\n\n{usage()}", file=sys.stderr)
        return 2
    module = importlib.import_module(COMMANDS[name][0])
    saved, sys.argv = sys.argv, [f"python -m drfkit {name}", *rest]  # argparse's prog in its messages
    try:
        return module.main(rest)
    finally:
        sys.argv = saved


if __name__ == "__main__":
    raise SystemExit(main())
