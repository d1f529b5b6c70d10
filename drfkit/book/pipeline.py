"""Run the whole book for one profile: ``python -m drfkit reproduce --profile quick``.

Validates the profile before anything runs, then executes every notebook in order with
papermill (progress bar on), writing executed notebooks to ``results/<profile>/executed/``.
Stops at the first failing notebook and names it. The manifest records each notebook's
duration and the total.

A notebook's outputs are all or nothing: if it fails or is stopped (Ctrl-C, SIGTERM, SIGHUP), every
output file it changed is put back as it was before it started (checkpoints and data caches
excepted: they are written atomically and resume), its kernel and children are stopped, and the
manifest says ``interrupted in <notebook>`` or ``failed in <notebook>``. ``cell_times.csv`` holds
the seconds of every cell of the last run's notebooks (no other notebook's rows). Rerunning the same
command after that skips the notebooks that finished with the same parameters and code.

``--jobs N`` (N > 1, ``make reproduce JOBS=N``) or ``--scheduler ADDRESS`` first trains the missing
runs of the training notebooks it will execute on Dask (``drfkit.book.grid``); the notebooks then only
evaluate. The default trains inside the notebooks, one run after another.
"""
from __future__ import annotations

import hashlib
import os
import signal
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

from drfkit.util.io import atomic_write_bytes, exclusive_lock, param_hash
from drfkit.book.manifest import now_iso, read_manifest, record_cell_times, record_notebook, update_manifest
from drfkit.study.params import NOTEBOOKS, ParameterError, load_profile, notebook_params
from drfkit.util.paths import NOTEBOOKS_DIR, PIPELINE_ENV, PIPELINE_LOCK, REPO_ROOT, results_dir
from drfkit.util.progress import Echo

# What a notebook run may leave half-rewritten: everything under results/<profile>/ except the
# checkpoints (written atomically per epoch and resumable), the data caches (hashed by their
# parameters) and the manifest (which records the interruption itself).
UNSNAPSHOTTED = ("models", "data", "ablation", "predictions", "measurements", "manifest.json", ".snapshot",
                 ".pipeline.lock")


@contextmanager
def ipc_kernels():
    """The traitlets config under which the pipeline's Jupyter kernels run (and ``make notebooks``'):
    over IPC, Unix sockets in a private temporary folder (mode 0700, removed after), instead of TCP
    ports on localhost. Nothing listens on a port, only this user can connect, and ipykernel's
    "Kernel is running over TCP without encryption" warning, which every notebook printed into the
    terminal, has no cause left (it is not silenced: a kernel started over TCP would still say so)."""
    from traitlets.config import Config

    with tempfile.TemporaryDirectory(prefix="drfkit-kernel-") as folder:
        config = Config()
        config.KernelManager.transport = "ipc"
        config.KernelManager.ip = os.path.join(folder, "kernel")  # the sockets: kernel-<n>
        yield config


def notebook_path(name: str) -> Path:
    return NOTEBOOKS_DIR / f"{name}.ipynb"


def code_hash(name: str) -> str:
    """The notebook and every drfkit source: what a finished notebook's outputs depend on besides
    its parameters."""
    digest = hashlib.sha256(notebook_path(name).read_bytes())
    for path in sorted((REPO_ROOT / "drfkit").rglob("*.py")):
        digest.update(path.relative_to(REPO_ROOT).as_posix().encode() + path.read_bytes())
    return digest.hexdigest()[:16]


def snapshot_outputs(root: Path) -> dict[Path, bytes]:
    """The bytes of every output file under ``root`` (UNSNAPSHOTTED left out): a few MB."""
    if not root.exists():
        return {}
    return {p: p.read_bytes() for p in root.rglob("*")
            if p.is_file() and p.relative_to(root).parts[0] not in UNSNAPSHOTTED}


def restore_outputs(root: Path, snapshot: dict[Path, bytes]) -> list[Path]:
    """Put ``root``'s outputs back as ``snapshot`` had them (files added since are removed);
    returns the paths that changed. A notebook stopped half-way leaves the previous outputs whole."""
    changed = []
    for path in (snapshot_outputs(root).keys() - snapshot.keys()):
        path.unlink(missing_ok=True)
        changed.append(path)
    for path, data in snapshot.items():
        if not path.exists() or path.read_bytes() != data:
            atomic_write_bytes(path, data)
            changed.append(path)
    return changed


class Interrupted(Exception):
    """SIGTERM or SIGHUP reached the pipeline (Ctrl-C arrives as KeyboardInterrupt)."""


def _raise_interrupted(signum, frame):
    raise Interrupted(signal.Signals(signum).name)


def _descendants(pid: int) -> list[int]:
    """Every live descendant of ``pid`` (Linux /proc): the Jupyter kernel and what it started."""
    children: dict[int, list[int]] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        children.setdefault(int(fields[1]), []).append(int(stat.parent.name))
    out, todo = [], [pid]
    while todo:
        for child in children.get(todo.pop(), []):
            out.append(child)
            todo.append(child)
    return out


def _stop_descendants() -> None:
    for pid in _descendants(os.getpid()):
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


def _resumable(manifest: dict, name: str, params_key: str, code: str) -> bool:
    """After an interrupted or failed pipeline: a notebook that finished with the same parameters
    and code is not run again."""
    status = str(manifest.get("pipeline", {}).get("status", ""))
    entry = manifest.get("pipeline", {}).get("finished_notebooks", {}).get(name, {})
    return (status.startswith(("interrupted", "failed", "killed")) and entry.get("params") == params_key
            and entry.get("code") == code)


def run(profile: str, only: list[str] | None = None, kernel: str = "python3",
        overrides: dict | None = None) -> int:
    import papermill as pm

    values = load_profile(profile) | (overrides or {})
    profile_name = values.get("profile", Path(profile).stem)
    names = [n for n in NOTEBOOKS if not only or n in only]
    if only and set(only) - set(NOTEBOOKS):
        raise ParameterError(f"unknown notebook(s) {sorted(set(only) - set(NOTEBOOKS))}; known: {list(NOTEBOOKS)}")
    # every notebook's values checked, not only those run: a bad --set is an error before any work, whichever
    # notebook declares the key
    checked = {name: notebook_params(name, values) for name in NOTEBOOKS}
    per_notebook = {name: checked[name] for name in names}
    root, out_dir = results_dir(profile_name), results_dir(profile_name, "executed")
    previous, finished = {}, {}  # read under the lock, after a killed run was undone
    started, t0 = now_iso(), time.perf_counter()
    durations: dict[str, float] = {}
    cpu: dict[str, float] = {}  # user + system CPU seconds per notebook (its kernel and every process it waited for)

    def record(status: str, finished_at: str | None = None) -> None:
        update_manifest(profile_name, profile_file=str(profile), profile_values=values, overrides=overrides or {},
                        pipeline={"started": started, "finished": finished_at, "status": status,
                                  "total_s": round(time.perf_counter() - t0, 1) if finished_at else None,
                                  "durations_s": durations, "cpu_s": cpu, "cores": os.cpu_count(),
                                  "workers": os.environ.get("DRF_WORKERS", "1"),
                                  "notebooks": names, "finished_notebooks": finished})

    with exclusive_lock(root / PIPELINE_LOCK, f"profile {profile_name} (results {root})", announce_stale=True):
        recover_after_kill(root, profile_name)
        previous = read_manifest(profile_name)
        finished.update(previous.get("pipeline", {}).get("finished_notebooks", {}))
        os.environ[PIPELINE_ENV] = str(root.resolve())  # the notebooks' kernels run under this lock
        try:
            return _run_locked(profile, profile_name, names, per_notebook, values, overrides, kernel, pm,
                               root, out_dir, previous, finished, started, t0, durations, record, cpu)
        finally:
            os.environ.pop(PIPELINE_ENV, None)


SNAPSHOT_DIR = ".snapshot"  # the outputs before the running notebook, on disk until it ends


def save_snapshot(root: Path, name: str, snapshot: dict[Path, bytes]) -> Path:
    """Write ``snapshot`` to ``root/.snapshot/<name>.zip`` (atomically), so that a pipeline killed
    with SIGKILL can still be undone by the next start (``recover_after_kill``)."""
    import io
    import zipfile

    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for path, data in snapshot.items():
            zf.writestr(path.relative_to(root).as_posix(), data)
    return atomic_write_bytes(root / SNAPSHOT_DIR / f"{name}.zip", buf.getvalue())


def recover_after_kill(root: Path, profile_name: str) -> str | None:
    """At the start of a pipeline (lock held): a snapshot left on disk, or a manifest left
    ``running``, means the previous pipeline was killed (SIGKILL, out of memory) mid-notebook. Put
    that notebook's outputs back from its snapshot, mark it ``killed`` in the manifest, say so in one
    line; returns the notebook's name, or None if nothing was left."""
    import zipfile

    snapshots = sorted((root / SNAPSHOT_DIR).glob("*.zip"))
    manifest = read_manifest(profile_name)
    running = [n for n, e in manifest.get("notebooks", {}).items() if e.get("status") == "running"]
    if not snapshots and not running:
        return None
    name = snapshots[0].stem if snapshots else running[0]
    restored = ""
    if snapshots:
        with zipfile.ZipFile(snapshots[0]) as zf:
            before = {root / member: zf.read(member) for member in zf.namelist()}
        restore_outputs(root, before)
        snapshots[0].unlink()
        restored = "its outputs were put back from the snapshot taken before it started; "
    (root / "executed" / f".{name}.partial.ipynb").unlink(missing_ok=True)
    if name in manifest.get("notebooks", {}):
        record_notebook(profile_name, name, status="killed", finished=None)
    pipeline = manifest.get("pipeline")
    if pipeline and pipeline.get("status") == "running":
        update_manifest(profile_name, pipeline=pipeline | {"status": f"killed in {name}"})
    print(f"== the previous run on profile {profile_name} was killed in {name}: {restored}continuing",
          file=sys.stderr, flush=True)
    return name


def cpu_seconds() -> float:
    """User + system CPU seconds of this process and of every child it has waited for (a notebook's kernel, and the
    processes the kernel waited for: Dask workers, data loaders), so far: the difference over a notebook is what it
    used of the machine's cores."""
    import resource

    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def _run_locked(profile, profile_name, names, per_notebook, values, overrides, kernel, pm, root, out_dir,
                previous, finished, started, t0, durations, record, cpu) -> int:
    record("running")
    handlers = {sig: signal.signal(sig, _raise_interrupted) for sig in (signal.SIGTERM, signal.SIGHUP)}
    try:
        for name in names:
            params_key, code = param_hash(per_notebook[name]), code_hash(name)
            if _resumable(previous, name, params_key, code) and (out_dir / f"{name}.ipynb").exists():
                print(f"== {name} ({profile_name}): finished before with these parameters and code, skipped",
                      flush=True)
                continue
            finished.pop(name, None)
            print(f"== {name} ({profile_name})", flush=True)
            t, cpu0 = time.perf_counter(), cpu_seconds()
            final, partial = out_dir / f"{name}.ipynb", out_dir / f".{name}.partial.ipynb"
            before = snapshot_outputs(root)
            save_snapshot(root, name, before)
            try:
                # papermill rewrites its output after every cell: run into a partial file and move it
                # into place when done, so a killed run never leaves a half-executed notebook behind;
                # the long evaluations inside report to the terminal through drfkit.util.progress
                with Echo(out_dir / f".{name}.progress.log"), ipc_kernels() as kernel_config:
                    pm.execute_notebook(
                        str(notebook_path(name)), str(partial),
                        parameters=per_notebook[name], progress_bar=True, kernel_name=kernel,
                        cwd=str(NOTEBOOKS_DIR), log_output=False, config=kernel_config,
                    )
            except (KeyboardInterrupt, Interrupted) as exc:
                _stop_descendants()
                partial.unlink(missing_ok=True)
                restore_outputs(root, before)
                (root / SNAPSHOT_DIR / f"{name}.zip").unlink(missing_ok=True)
                durations[name] = round(time.perf_counter() - t, 1)
                record_notebook(profile_name, name, status="interrupted", finished=now_iso())
                record(f"interrupted in {name}", now_iso())
                print(f"\nINTERRUPTED ({exc or 'SIGINT'}) in notebook {name}: its outputs were put back as they "
                      f"were before it started; the notebooks before it are complete. Rerun the same command to "
                      f"continue from {name}.", file=sys.stderr)
                return 130
            except Exception as exc:  # papermill raises PapermillExecutionError with the cell's traceback
                failed = out_dir / f"{name}.failed.ipynb"
                if partial.exists():
                    os.replace(partial, failed)  # complete up to the failing cell, which shows the error
                restore_outputs(root, before | {failed: failed.read_bytes()} if failed.exists() else before)
                (root / SNAPSHOT_DIR / f"{name}.zip").unlink(missing_ok=True)
                durations[name] = round(time.perf_counter() - t, 1)
                record_notebook(profile_name, name, status="failed", finished=now_iso())
                record(f"failed in {name}", now_iso())
                print(f"\nFAILED: notebook {name} ({type(exc).__name__}); the executed copy with the error is "
                      f"{failed}; the other outputs are as they were before it started\n{exc}", file=sys.stderr)
                return 1
            os.replace(partial, final)
            (root / SNAPSHOT_DIR / f"{name}.zip").unlink(missing_ok=True)
            record_cell_times(profile_name, name, final, run=names)
            (out_dir / f"{name}.failed.ipynb").unlink(missing_ok=True)
            durations[name] = round(time.perf_counter() - t, 1)
            cpu[name] = round(cpu_seconds() - cpu0, 1)
            finished[name] = {"params": params_key, "code": code, "at": now_iso()}
            record("running")
    finally:
        for sig, handler in handlers.items():
            signal.signal(sig, handler)
    record("ok", now_iso())
    print(f"== done: {len(names)} notebooks in {time.perf_counter() - t0:.0f} s; results in {root}")
    return 0


def die_with_parent() -> None:
    """Ask Linux to send us SIGTERM when our parent dies: ``make`` does not pass a SIGTERM it receives
    on to its children, so without this a killed ``make reproduce`` would leave the pipeline running."""
    try:
        import ctypes

        PR_SET_PDEATHSIG = 1
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
    except (OSError, AttributeError):  # not Linux: Ctrl-C and a SIGTERM sent to the pipeline still work
        pass
