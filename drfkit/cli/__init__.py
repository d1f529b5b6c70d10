"""``python -m drfkit <command> [args]``: every command line of the book, and only here.

Each command is a function ``command(argv) -> exit code`` in one module of this package, grouped by
the layer it drives: ``book`` (reproduce, train, budget, manifest, regime), ``study`` (report,
claims, ablation, dynamics, bench, simstats) and ``data`` (nuscenes, rodbank). The library below
takes explicit arguments and holds no argparse; a command parses, reads the profile, calls into the
library and prints. A module is imported only when one of its commands runs, so ``--help`` here
loads nothing heavy and this file adds no import edge to the package's graph.
"""
from __future__ import annotations

import argparse
import importlib
import sys
from typing import Callable

# command -> (module of drfkit.cli that defines it, one line of help)
COMMANDS: dict[str, tuple[str, str]] = {
    "reproduce": ("book", "run every notebook of a profile (make reproduce)"),
    "train": ("book", "train or resume a profile's checkpoints, here or on a Dask grid"),
    "budget": ("book", "how long a profile's training takes on this machine"),
    "manifest": ("book", "rebuild cell_times.csv from a profile's executed notebooks"),
    "regime": ("book", "the noise-regime map: train, evaluate, write its tables and figure"),
    "report": ("study", "regenerate the README's results section and report.md"),
    "claims": ("study", "judge every claim again from a profile's tables (claims.csv, claims.md)"),
    "ablation": ("study", "the protocol ablation on validation data"),
    "dynamics": ("study", "is the filter filtering: a run's mechanism diagnostics"),
    "screen": ("study", "the calibrated-gain screen: variants judged on in-distribution validation only"),
    "bench": ("study", "the inference benchmark (make bench), results/<profile>/timing.csv"),
    "simstats": ("study", "statistics of the simulated pedestrian source"),
    "nuscenes": ("data", "nuScenes: write salt-and-pepper noisy copies of the images"),
    "rodbank": ("data", "check the pendulum's rod bank against PIL's drawing on N random angles"),
}


def parser(command: str, description: str | None = None, profile: str | None = None) -> argparse.ArgumentParser:
    """The parser of one command: its usage line says ``python -m drfkit <command>``, its
    description is the command's one line of help unless ``description`` is given; with
    ``profile``, a ``--profile`` option of that default (every command reads a profile the same way)."""
    ap = argparse.ArgumentParser(prog=f"python -m drfkit {command}", description=description or COMMANDS[command][1])
    if profile is not None:
        ap.add_argument("--profile", default=profile, help=f"a profile name in params/ or a YAML path (default {profile})")
    return ap


def command(name: str) -> Callable[[list[str]], int]:
    """The function that runs ``python -m drfkit <name>`` (imports its module)."""
    if name not in COMMANDS:
        raise KeyError(f"unknown command {name!r}; known: {sorted(COMMANDS)}")
    return getattr(importlib.import_module(f"drfkit.cli.{COMMANDS[name][0]}"), name)


def usage() -> str:
    width = max(map(len, COMMANDS))
    lines = ["usage: python -m drfkit <command> [args]   (python -m drfkit <command> --help: its options)",
             "", "commands:"]
    lines += [f"  {name:<{width}}  {text}" for name, (_, text) in COMMANDS.items()]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """``python -m drfkit <command> [args]``: runs the command, returns its exit code (2: no or an
    unknown command)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help", "help"):
        print(usage())
        return 0 if argv else 2
    name, rest = argv[0], argv[1:]
    if name not in COMMANDS:
        print(f"unknown command {name!r}\n\n{usage()}", file=sys.stderr)
        return 2
    from drfkit.util.registry import load_extensions

    load_extensions()  # DRFKIT_EXTENSIONS: every command sees the models, noise kinds, studies and claims they add
    return command(name)(rest)


__all__ = ["COMMANDS", "command", "main", "parser", "usage"]
