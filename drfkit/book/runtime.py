"""What every notebook does first: validate parameters, fix seeds and threads, pick the
device (``drfkit.util.device``), and open its manifest entry."""
from __future__ import annotations

import atexit
import os
from typing import Any

from drfkit.util.device import setup
from drfkit.book.cell_profile import install, threshold_from_env
from drfkit.book.manifest import NotebookTimer
from drfkit.util.paths import results_dir
from drfkit.study.params import notebook_globals, validate
from drfkit.study.profile import Profile


def start_notebook(notebook: str, namespace: dict[str, Any]) -> tuple[Profile, NotebookTimer]:
    """Validate the parameters defined in ``namespace`` (a notebook's ``globals()``).

    Returns the validated parameters as the typed profile (``P.pendulum.epochs``; the flat names
    exist only in the parameters cell) and a timer whose ``finish()`` the notebook's last
    cell calls. Deterministic algorithms are requested so that a seed fixes the result
    on CPU.
    """
    from drfkit.util.registry import load_extensions

    load_extensions()  # DRFKIT_EXTENSIONS (inherited from make reproduce): the parameters may name what they add
    params = validate(notebook, notebook_globals(namespace))
    setup(params.threads, params.seeds[0], params.device)
    hold_profile(params.profile)
    timer = NotebookTimer(params.profile, notebook, params.as_dict())
    threshold = threshold_from_env()
    if threshold is not None:  # make reproduce CELL_PROFILE=seconds
        install(notebook, results_dir(params.profile, "cell_profiles"), threshold)
    return params, timer


_HELD: dict[str, Any] = {}  # results folder -> the lock a notebook run on its own holds for its kernel's life


def hold_profile(profile: str) -> None:
    """One writer per profile: a notebook run on its own (Jupyter, nbval) takes the profile's
    pipeline lock for the life of its kernel, so a pipeline or another notebook on the same profile
    is refused (``LockedError`` with the holder's PID and host) before anything is written. Under
    ``drfkit.book.pipeline`` the parent already holds it (``DRFKIT_PIPELINE_HOLDS``)."""
    from drfkit.util.paths import PIPELINE_ENV, PIPELINE_LOCK, results_dir

    root = results_dir(profile)
    if os.environ.get(PIPELINE_ENV) == str(root.resolve()) or str(root.resolve()) in _HELD:
        return
    from drfkit.util.io import exclusive_lock

    # silent about a stale holder: a kernel closed with its notebook leaves its name behind, and that
    # is no news to whoever opens the next notebook (a pipeline taking over says so)
    lock = exclusive_lock(root / PIPELINE_LOCK, f"profile {profile} (results {root})", announce_stale=False)
    lock.__enter__()  # released at the kernel's exit, or by the OS with the process (kill -9 included)
    _HELD[str(root.resolve())] = lock
    atexit.register(_release, lock)


def _release(lock) -> None:
    try:
        lock.__exit__(None, None, None)  # empties the holder's name, then releases the flock
    except Exception:  # noqa: BLE001 -- at interpreter exit, a lock file already gone is fine
        pass
