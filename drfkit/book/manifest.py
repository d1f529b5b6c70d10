"""The run manifest: everything needed to rerun a profile and to trust its numbers.

``results/<profile>/manifest.json`` holds the machine, package versions, torch build and
threads, the git commit, and one entry per notebook (its validated parameters, start,
end, duration). Notebooks add their own entry when they start and finish, so a notebook
run alone (nbval, papermill by hand) is recorded as well as a full ``make reproduce``.
"""
from __future__ import annotations

import json
import os
import platform
import subprocess
import time
from datetime import datetime, timezone
from importlib import metadata
from pathlib import Path
from typing import Any

from drfkit.util.io import atomic_write_json
from drfkit.util.paths import REPO_ROOT, results_dir, results_root

PACKAGES = ("torch", "numpy", "pandas", "matplotlib", "opencv-python-headless", "papermill", "nbval",
            "PyYAML", "tqdm", "jupyter", "nbclient", "ipykernel", "pytest")


def now_iso() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


def _outputs_inside(repo: Path) -> list[str]:
    """The folders runs write to that lie inside ``repo`` (results/, and $DRF_RESULTS if elsewhere
    in it), as paths relative to it."""
    out = []
    for folder in {repo / "results", results_root()}:
        try:
            rel = folder.resolve().relative_to(repo.resolve()).as_posix()
        except ValueError:  # outside the repository: git does not see it
            continue
        if rel != ".":
            out.append(rel)
    return sorted(out)


def git_commit(repo: Path = REPO_ROOT) -> dict[str, Any]:
    """The commit and whether the code differs from it: ``dirty`` counts changes to tracked or new
    files outside the run's outputs (results/: every run rewrites them, so counting them would call
    every tree dirty after its first run)."""
    def run(*args: str) -> str:
        try:
            return subprocess.run(["git", *args], cwd=repo, capture_output=True, text=True,
                                  timeout=10).stdout.strip()
        except (OSError, subprocess.SubprocessError):
            return ""

    outputs = [f":(exclude){folder}" for folder in _outputs_inside(repo)]
    return {"commit": run("rev-parse", "HEAD") or None,
            "dirty": bool(run("status", "--porcelain", "--", ".", *outputs))}


# what a profile's results are computed from: the library, the notebooks' sources and the profiles
RESULT_SOURCES = ("drfkit/**/*.py", "notebooks/src/*.py", "params/*.yaml")


def results_digest(repo: Path = REPO_ROOT) -> str:
    """sha256 of every file a profile's results depend on (``RESULT_SOURCES``: path and bytes, in path order):
    two trees with the same digest compute the same results; a docs/ or tests/ edit leaves it."""
    import hashlib

    digest = hashlib.sha256()
    files = sorted({f for pattern in RESULT_SOURCES for f in repo.glob(pattern) if f.is_file()
                    and "__pycache__" not in f.parts})
    for f in files:
        digest.update(f.relative_to(repo).as_posix().encode() + b"\0" + f.read_bytes() + b"\0")
    return digest.hexdigest()


def cpu_identity() -> dict[str, str]:
    """The CPU as /proc/cpuinfo names it: model name, vendor, family, model, stepping (a virtual machine's
    model name can be as vague as 'AMD EPYC'; family and model tell its generation)."""
    fields = {"model name": "name", "vendor_id": "vendor", "cpu family": "family", "model": "model",
              "stepping": "stepping"}
    out: dict[str, str] = {}
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                key, _, value = line.partition(":")
                key = key.strip()
                if key in fields and fields[key] not in out:
                    out[fields[key]] = value.strip()
                if not line.strip() and out:
                    break
    except OSError:
        pass
    return out or {"name": platform.processor() or platform.machine()}


def check_results(profile: str, repo: Path = REPO_ROOT) -> tuple[bool, str]:
    """Whether ``results/<profile>`` is the code's: its manifest's ``results_digest`` (recorded by the run that
    made it) against the tree's now. Returns (same, a sentence saying so and what to do)."""
    env = read_manifest(profile).get("environment", {})
    recorded, now = env.get("results_digest"), results_digest(repo)
    commit = (env.get("git") or {}).get("commit") or "an unknown commit"
    if recorded is None:
        return False, (f"results/{profile} records no digest of its sources (made by {commit} before digests were "
                       f"recorded): rerun `make reproduce PROFILE={profile}` to make it the code's")
    if recorded != now:
        return False, (f"results/{profile} was made by {commit} from other sources than this tree's (drfkit/, "
                       f"notebooks/src/, params/ differ): rerun `make reproduce PROFILE={profile}`")
    return True, f"results/{profile} is this tree's (made by {commit})"


def cpu_name() -> str:
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def environment() -> dict[str, Any]:
    import torch

    versions = {}
    for name in PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    gpu = torch.cuda.get_device_name(0) if torch.cuda.is_available() else None
    return {
        "python": platform.python_version(),
        "platform": platform.platform(),
        "cpu": cpu_name(),
        "cpu_id": cpu_identity(),
        "cpu_count": os.cpu_count(),
        "gpu": gpu,
        "torch_threads": torch.get_num_threads(),
        "torch_build": torch.__config__.show().strip().splitlines()[:6],
        "packages": versions,
        "git": git_commit(),
        "results_digest": results_digest(),
    }


def manifest_path(profile: str):
    return results_dir(profile) / "manifest.json"


def read_manifest(profile: str) -> dict[str, Any]:
    path = manifest_path(profile)
    if path.exists():
        try:
            return json.loads(path.read_text())
        except json.JSONDecodeError:
            pass  # written atomically, so this is a hand-edit: start afresh
    return {"profile": profile, "notebooks": {}}


def update_manifest(profile: str, **fields: Any) -> dict[str, Any]:
    manifest = read_manifest(profile)
    manifest.update(fields)
    manifest["environment"] = environment()
    manifest["updated"] = now_iso()
    atomic_write_json(manifest_path(profile), manifest)
    return manifest


def record_notebook(profile: str, notebook: str, **fields: Any) -> None:
    """Merge ``fields`` into the manifest entry of ``notebook``."""
    manifest = read_manifest(profile)
    entry = manifest.setdefault("notebooks", {}).setdefault(notebook, {})
    entry.update(fields)
    manifest["environment"] = environment()
    manifest["updated"] = now_iso()
    atomic_write_json(manifest_path(profile), manifest)


_REUSED: list[dict[str, Any]] = []  # measurement-cache entries this process reused (drfkit.book.measurements)


def note_reused(entry: dict[str, Any]) -> None:
    _REUSED.append(entry)


def reused_measurements(clear: bool = False) -> list[dict[str, Any]]:
    """The measurement-cache entries this process has reused so far (``clear``: and forget them)."""
    out = list(_REUSED)
    if clear:
        _REUSED.clear()
    return out


class NotebookTimer:
    """Records a notebook's start in the manifest; ``finish()`` records end and duration."""

    def __init__(self, profile: str, notebook: str, params: dict[str, Any]):
        self.profile, self.notebook = profile, notebook
        self.t0 = time.perf_counter()
        record_notebook(profile, notebook, params=params, started=now_iso(), finished=None,
                        duration_s=None, status="running")

    def finish(self, **extra: Any) -> float:
        """Record the end, the duration and the measurement-cache entries this notebook reused
        (``drfkit.book.measurements``: their timings were measured before, not in this run)."""
        duration = time.perf_counter() - self.t0
        record_notebook(self.profile, self.notebook, finished=now_iso(), duration_s=round(duration, 2),
                        status="ok", reused_measurements=reused_measurements(clear=True), **extra)
        return duration


def cell_times(executed_notebook) -> list[dict[str, Any]]:
    """Seconds of every code cell of a notebook executed by papermill (its ``papermill.duration``
    cell metadata), with the cell's first line of code (comments skipped) to name it."""
    import nbformat

    nb = nbformat.read(str(executed_notebook), as_version=4)
    rows = []
    for index, cell in enumerate(nb.cells):
        seconds = cell.metadata.get("papermill", {}).get("duration")
        if cell.cell_type != "code" or seconds is None:
            continue
        code = [line for line in cell.source.splitlines() if line.strip() and not line.lstrip().startswith("#")]
        rows.append({"cell": index, "seconds": round(float(seconds), 2), "first_line": (code[0] if code else "")[:90]})
    return rows


def record_cell_times(profile: str, notebook: str, executed_notebook, run: list[str] | None = None) -> None:
    """Replace ``notebook``'s rows of ``results/<profile>/cell_times.csv`` (notebook, cell,
    seconds, first_line): where a profile's time goes, cell by cell. ``run``: the notebooks of the
    run this belongs to (the pipeline's list, ``notebook`` among them); the rows of any other
    notebook are dropped, so the file describes that run only, never a notebook since renamed."""
    import pandas as pd

    from drfkit.util.io import atomic_write_csv

    path = results_dir(profile) / "cell_times.csv"
    try:
        rows = cell_times(executed_notebook)
    except Exception as exc:  # a record of times must never fail the run it describes
        print(f"note: no cell times for {notebook} ({type(exc).__name__}: {exc})")
        return
    new = pd.DataFrame(rows, columns=["cell", "seconds", "first_line"]).assign(notebook=notebook)
    old = pd.read_csv(path) if path.exists() else new.iloc[:0]
    keep = old["notebook"] != notebook
    if run is not None:
        keep &= old["notebook"].isin(run)
    table = pd.concat([old[keep], new], ignore_index=True).sort_values(["notebook", "cell"])
    atomic_write_csv(path, table[["notebook", "cell", "seconds", "first_line"]])
