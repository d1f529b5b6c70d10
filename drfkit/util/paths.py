"""Where things live, independent of the working directory.

papermill and nbval start kernels in different folders, so nothing in drfkit uses a
relative path: everything hangs off ``REPO_ROOT`` (or ``$DRF_RESULTS`` for results).
"""
from __future__ import annotations

import os
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]  # drfkit/util/paths.py -> the repository
PARAMS_DIR = REPO_ROOT / "params"
NOTEBOOKS_DIR = REPO_ROOT / "notebooks"


def results_root() -> Path:
    return Path(os.environ.get("DRF_RESULTS", REPO_ROOT / "results")).resolve()


def results_dir(profile: str, *parts: str) -> Path:
    """``results/<profile>/<parts...>``, created on demand."""
    path = results_root().joinpath(profile, *parts)
    path.mkdir(parents=True, exist_ok=True)
    return path


def data_dir(profile: str) -> Path:
    return results_dir(profile, "data")


def models_dir(profile: str) -> Path:
    return results_dir(profile, "models")


def predictions_dir(profile: str) -> Path:
    """The MC-dropout prediction cache (``drfkit.methods.predictions``); not committed."""
    return results_dir(profile, "predictions")


def tables_dir(profile: str) -> Path:
    return results_dir(profile, "tables")


def figures_dir(profile: str) -> Path:
    return results_dir(profile, "figures")


# One pipeline per profile: an OS lock on results/<profile>/.pipeline.lock (drfkit.util.io.exclusive_lock),
# taken by drfkit.book.pipeline and by a notebook started on its own (drfkit.book.runtime.hold_profile); this
# variable, inherited by the pipeline's kernels, names the results folder their parent has locked.
PIPELINE_LOCK = ".pipeline.lock"
PIPELINE_ENV = "DRFKIT_PIPELINE_HOLDS"
