"""Run the whole book for one profile: ``python -m drfkit.pipeline --profile quick``.

Validates the profile before anything runs, then executes every notebook in order with
papermill (progress bar on), writing executed notebooks to ``results/<profile>/executed/``.
Stops at the first failing notebook and names it. The manifest records each notebook's
duration and the total.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from drfkit.manifest import now_iso, update_manifest
from drfkit.params import NOTEBOOKS, ParameterError, load_profile, notebook_params, parse_overrides
from drfkit.paths import NOTEBOOKS_DIR, results_dir


def notebook_path(name: str) -> Path:
    return NOTEBOOKS_DIR / f"{name}.ipynb"


def run(profile: str, only: list[str] | None = None, kernel: str = "python3",
        overrides: dict | None = None) -> int:
    import papermill as pm

    values = load_profile(profile) | (overrides or {})
    profile_name = values.get("profile", Path(profile).stem)
    names = [n for n in NOTEBOOKS if not only or n in only]
    if only and set(only) - set(NOTEBOOKS):
        raise ParameterError(f"unknown notebook(s) {sorted(set(only) - set(NOTEBOOKS))}; known: {list(NOTEBOOKS)}")
    per_notebook = {name: notebook_params(name, values) for name in names}  # all errors before any run
    out_dir = results_dir(profile_name, "executed")
    started, t0 = now_iso(), time.perf_counter()
    update_manifest(profile_name, profile_file=str(profile), profile_values=values, overrides=overrides or {},
                    pipeline={"started": started, "finished": None, "total_s": None, "status": "running",
                              "notebooks": names})
    durations = {}
    for name in names:
        print(f"== {name} ({profile_name})", flush=True)
        t = time.perf_counter()
        final, partial = out_dir / f"{name}.ipynb", out_dir / f".{name}.partial.ipynb"
        try:
            # papermill rewrites its output after every cell: run into a partial file and move it
            # into place when done, so a killed run never leaves a half-executed notebook behind
            pm.execute_notebook(
                str(notebook_path(name)), str(partial),
                parameters=per_notebook[name], progress_bar=True, kernel_name=kernel,
                cwd=str(NOTEBOOKS_DIR), log_output=False,
            )
        except Exception as exc:  # papermill raises PapermillExecutionError with the cell's traceback
            failed = out_dir / f"{name}.failed.ipynb"
            if partial.exists():
                os.replace(partial, failed)  # complete up to the failing cell, which shows the error
            durations[name] = round(time.perf_counter() - t, 1)
            update_manifest(profile_name, pipeline={
                "started": started, "finished": now_iso(), "total_s": round(time.perf_counter() - t0, 1),
                "status": f"failed in {name}", "durations_s": durations, "notebooks": names})
            print(f"\nFAILED: notebook {name} ({type(exc).__name__}); the executed copy with the error is "
                  f"{failed}\n{exc}", file=sys.stderr)
            return 1
        os.replace(partial, final)
        (out_dir / f"{name}.failed.ipynb").unlink(missing_ok=True)
        durations[name] = round(time.perf_counter() - t, 1)
    total = round(time.perf_counter() - t0, 1)
    update_manifest(profile_name, pipeline={"started": started, "finished": now_iso(), "total_s": total,
                                            "status": "ok", "durations_s": durations, "notebooks": names})
    print(f"== done: {len(names)} notebooks in {total:.0f} s; results in {results_dir(profile_name)}")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--profile", default="paper", help="name in params/ or a path to a YAML file")
    parser.add_argument("--only", nargs="*", help="run only these notebooks (names without .ipynb)")
    parser.add_argument("--set", nargs="*", metavar="KEY=VALUE",
                        help="override profile parameters (YAML values); recorded in the manifest")
    args = parser.parse_args(argv)
    try:
        return run(args.profile, args.only, overrides=parse_overrides(args.set))
    except ParameterError as exc:
        print(f"parameter error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
