"""The training grid on dask.distributed: every missing (study, protocol, model, seed) run of a
profile as one task.

    python -m drfkit train --profile paper --scheduler local:2 --threads 1
    python -m drfkit train --profile paper --study pendulum --scheduler tcp://host:8786

``local[:N]`` starts a ``LocalCluster`` of N single-threaded worker processes (default: the usable
cores // the threads of one run); an address (``tcp://...``) connects to a running Dask scheduler
(a lab cluster, a ``dask_jobqueue.SLURMCluster``), whose workers must import this drfkit and see
the client's results folder at the same path (a shared file system).

A task is the sequential command's own call, ``train_models(P, study, kinds=[kind], seeds=[seed])``,
after ``drfkit.util.device.setup(threads, ...)`` as ``python -m drfkit train`` does: the same
checkpoint files, the same OS lock per checkpoint stem, the same resume, so a run's numbers equal a
sequential run's with the same thread count. Dask only decides where and when each run trains.

What a run is -- its data, configuration and checkpoint name -- comes from ``drfkit.study.studies``.
"""
from __future__ import annotations

import os
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable

from drfkit.study import registry
from drfkit.study import studies as runs_of
from drfkit.study.params import ParameterError
from drfkit.util.tasks import local_cluster, usable_cores


@dataclass(frozen=True)
class Run:
    """One training run of the grid."""

    study: str
    protocol: str
    kind: str
    seed: int

    @property
    def name(self) -> str:
        return f"{self.study}/{self.protocol} {self.kind} seed {self.seed}"

    @property
    def key(self) -> str:  # the task's name on the dashboard (made unique per submission)
        return f"train-{self.study}-{self.protocol}-{self.kind}-seed{self.seed}"


# ------------------------------------------------------------------------------ the grid
def study_params(values: dict[str, Any], study: str):
    """The validated parameters of ``study``'s training notebook from a profile's values."""
    return notebook_values(values, runs_of.TRAINING_NOTEBOOK[study])


def notebook_values(values: dict[str, Any], notebook: str):
    from drfkit.study.params import for_notebook

    return for_notebook(notebook, values)


def study_protocols(P, study: str) -> list[str]:
    """The protocols a profile's training notebook trains for ``study``."""
    return registry.study(study).protocols(P)


def grid_runs(values: dict[str, Any], studies: Iterable[str] | None = None, kinds: list[str] | None = None,
              seeds: list[int] | None = None, protocol: str | None = None) -> list[Run]:
    """Every run of the profile, filtered as the command line says; ``ParameterError`` for a
    filter that names nothing the notebooks would train."""
    studies = list(studies or sorted(runs_of.STUDIES))
    runs, known_models = [], set()
    for study in studies:
        P = study_params(values, study)
        if set(seeds or []) - set(P.seeds):
            raise ParameterError(f"--seeds {sorted(set(seeds) - set(P.seeds))} are not among the "
                                 f"profile's seeds {P.seeds}; the notebooks would never use them")
        candidate_protocols = study_protocols(P, study) if protocol is None else [protocol]
        models = list(dict.fromkeys(k for proto in candidate_protocols if proto in study_protocols(P, study)
                                    for k in runs_of.study_models(P, study, proto)))
        known_models |= set(models)
        if len(studies) == 1 and set(kinds or []) - set(models):
            raise ParameterError(f"--models {sorted(set(kinds) - set(models))} are not models of the {study} "
                                 f"study in this profile; choose from {models}")
        if protocol is None:
            protocols = study_protocols(P, study)
        elif protocol not in study_protocols(P, study):
            if len(studies) == 1:
                raise ParameterError(f"--protocol {protocol!r} is not a protocol the {study} study trains in this "
                                     f"profile; choose from {study_protocols(P, study)}")
            continue
        else:
            protocols = [protocol]
        for i, proto in enumerate(protocols):
            for kind in runs_of.study_models(P, study, proto):
                if kinds and kind not in kinds:
                    continue
                for seed in P.seeds:
                    # a run that an earlier protocol trains already (one checkpoint) is one task
                    if (not seeds or seed in seeds) and not any(
                            runs_of.shared_run(P, study, kind, seed, proto, earlier) for earlier in protocols[:i]):
                        runs.append(Run(study, proto, kind, seed))
    if set(kinds or []) - known_models:
        raise ParameterError(f"--models {sorted(set(kinds) - known_models)} are not models of the studies "
                             f"{studies} in this profile; choose from {sorted(known_models)}")
    return runs


def run_finished_on_disk(P, run: Run) -> bool:
    """Whether ``run``'s checkpoints are complete (a task would be a cache hit). A partial, corrupt
    or differently configured run counts as missing: its task resumes it or reports why it cannot."""
    from drfkit.util.io import CorruptArtefactError, param_hash, torch_load_checked
    from drfkit.methods.train import fingerprint, run_finished

    stem = runs_of.checkpoint_stem(P, run.study, run.kind, run.seed, run.protocol)
    last, best = Path(f"{stem}-last.pt"), Path(f"{stem}-best.pt")
    if not (last.exists() and best.exists()):
        return False
    try:
        state = torch_load_checked(last)
        cfg = runs_of.train_config(P, run.study, run.kind, run.seed, run.protocol)
        fp = fingerprint(runs_of.model_config(run.study, run.kind, P, run.protocol), cfg,
                         param_hash(runs_of.study_data_key(P, run.study, run.protocol)))
        return state.get("fingerprint") == fp and run_finished(state["epoch"], state["best_epoch"], cfg)
    except (CorruptArtefactError, KeyError, TypeError, AttributeError):  # the task says what is wrong
        return False


def train_run(train_models: Callable, notebook: str, values: dict[str, Any], run: Run, threads: int,
              results_root: str) -> dict[str, Any]:
    """The task: one run, exactly as the sequential ``python -m drfkit train`` trains it
    (``train_models``: ``drfkit.study.studies.train_models``; ``notebook``: the study's training notebook)."""
    from drfkit.util.registry import load_extensions

    load_extensions()  # a Dask worker is a process of its own: it loads the extension files the parent named
    from drfkit.util.device import setup

    previous = os.environ.get("DRF_RESULTS")
    os.environ["DRF_RESULTS"] = results_root  # the client's results folder (shared, same path)
    try:
        t0 = time.perf_counter()
        P = notebook_values(values, notebook)
        setup(threads, P.seeds[0], P.device)
        res = train_models(P, run.study, progress=False, kinds=[run.kind], seeds=[run.seed],
                           protocol=run.protocol)[(run.kind, run.seed)]
    finally:
        if previous is None:
            os.environ.pop("DRF_RESULTS", None)
        else:
            os.environ["DRF_RESULTS"] = previous
    try:
        from distributed import get_worker

        worker = get_worker().address
    except (ImportError, ValueError):
        worker = "in-process"
    return {"seconds": time.perf_counter() - t0, "best_epoch": res.best_epoch, "best_val_loss": res.best_val_loss,
            "epochs": len(res.history), "resumed_from": res.resumed_from, "stopped_early": res.stopped_early,
            "best_path": str(res.best_path), "worker": worker}


def describe(result: dict[str, Any]) -> str:
    epochs, start = result["epochs"], result["resumed_from"]
    if epochs == start:
        what = f"already trained ({epochs} epochs)"
    elif start:
        what = f"resumed at epoch {start}, trained to epoch {epochs}"
    else:
        what = f"trained {epochs} epochs"
    early = ", stopped early" if result["stopped_early"] else ""
    return (f"{what}{early} in {result['seconds']:.1f} s, best epoch {result['best_epoch']} "
            f"(val {result['best_val_loss']:.4f}) [{result['worker']}]")


# --------------------------------------------------------------------------- the cluster
def parse_scheduler(scheduler: str, threads: int) -> tuple[str, int | None]:
    """``'local'`` / ``'local:N'`` -> ('local', N); an address -> (address, None)."""
    if scheduler == "local" or scheduler.startswith("local:"):
        n = scheduler.partition(":")[2]
        if n and not (n.isdigit() and int(n) >= 1):
            raise ParameterError(f"--scheduler {scheduler!r}: N in local:N must be an integer >= 1")
        return "local", int(n) if n else max(1, usable_cores() // max(threads, 1))
    if "://" in scheduler:
        return scheduler, None
    raise ParameterError(f"--scheduler {scheduler!r}: use local, local:N or a scheduler address "
                         "such as tcp://host:8786")


class _Connection:
    """A Dask client on a new LocalCluster (closed with it) or on a running scheduler."""

    def __init__(self, scheduler: str, threads: int, n_runs: int):
        from distributed import Client

        address, n_workers = parse_scheduler(scheduler, threads)
        self.cluster = None
        if address == "local":
            self.cluster = local_cluster(min(n_workers, max(n_runs, 1)))
            self.client = Client(self.cluster)
        else:
            self.client = Client(address)

    def dashboard(self) -> str | None:
        import importlib.util

        if self.cluster is not None and importlib.util.find_spec("bokeh") is None:
            return None  # the local scheduler serves no dashboard without bokeh (pip install bokeh)
        try:
            return self.client.dashboard_link if "dashboard" in self.client.scheduler_info()["services"] else None
        except Exception:  # noqa: BLE001 -- an unreachable dashboard is not the grid's problem
            return None

    def close(self) -> None:
        import logging

        self.client.close()
        if self.cluster is not None:
            # a worker that trained often outlives the nanny's 4 s grace at shutdown and is killed, with a
            # warning that says nothing about the runs (their checkpoints were written before)
            quiet = lambda record: "still alive after" not in record.getMessage()  # noqa: E731
            logger = logging.getLogger("distributed.nanny")
            logger.addFilter(quiet)
            try:
                self.cluster.close()
            finally:
                logger.removeFilter(quiet)


def run_grid(values: dict[str, Any], runs: list[Run], scheduler: str, threads: int,
             out: Callable[[str], None] = print, write_curves: bool = False) -> dict[Run, Any]:
    """Train the missing ``runs`` on ``scheduler``; one line per finished run through ``out``.

    Returns ``{run: result dict}`` for the runs that finished (or were already complete) and
    ``{run: exception}`` for those that failed; the others go on when one fails. With
    ``write_curves`` a study's training curves table is written as the sequential command does
    (every run of the study and protocol finished)."""
    from drfkit.util.paths import results_root

    t0 = time.perf_counter()
    outcome: dict[Run, Any] = {}
    params = {study: study_params(values, study) for study in {r.study for r in runs}}
    todo = []
    for run in runs:
        if run_finished_on_disk(params[run.study], run):
            outcome[run] = "done"
        else:
            todo.append(run)
    done_before = len(outcome)
    out(f"grid: {len(runs)} runs, {done_before} already trained, {len(todo)} to train "
        f"({threads} torch thread(s) each)")
    if todo:
        # the data sets once, here: the tasks then read the caches instead of building them side by side
        for study, protocol in sorted({(r.study, r.protocol) for r in todo}):
            for split in ("train", "val"):
                runs_of.study_data(params[study], study, split, None, protocol)
        conn = _Connection(scheduler, threads, len(todo))
        try:
            from distributed import as_completed

            client = conn.client
            workers = len(client.scheduler_info().get("workers", {}))
            dashboard = conn.dashboard()
            out(f"grid: scheduler {client.scheduler.address}, {workers} worker(s)"
                + (f", dashboard {dashboard}" if dashboard else ""))
            root = str(results_root())
            token = uuid.uuid4().hex[:8]
            futures = {client.submit(train_run, runs_of.train_models, runs_of.TRAINING_NOTEBOOK[run.study], values,
                                     run, threads, root, key=f"{run.key}-{token}", pure=False, retries=0): run
                       for run in todo}
            for i, future in enumerate(as_completed(futures), 1):
                run = futures[future]
                if future.status == "error":
                    exc = future.exception()
                    outcome[run] = exc
                    out(f"[{i}/{len(todo)}] {run.name}: FAILED ({type(exc).__name__}: {exc})")
                else:
                    outcome[run] = future.result()
                    out(f"[{i}/{len(todo)}] {run.name}: {describe(outcome[run])}")
        finally:
            conn.close()
    failed = [r for r, v in outcome.items() if isinstance(v, BaseException)]
    out(f"grid: {len(todo) - len(failed)} trained, {done_before} already trained, {len(failed)} failed "
        f"in {time.perf_counter() - t0:.1f} s")
    if write_curves:
        for study, protocol in sorted({(r.study, r.protocol) for r in runs}):
            if not any(r.study == study and r.protocol == protocol for r in failed):
                runs_of.train_models(params[study], study, progress=False, protocol=protocol)  # cache hits
    return outcome


def pretrain(profile: str, overrides: dict[str, Any] | None, only: list[str] | None, scheduler: str,
             threads: int | None = None, out: Callable[[str], None] = print) -> int:
    """What ``python -m drfkit reproduce --jobs N`` does before the notebooks: every missing run of
    the training notebooks it will execute (all, or those in ``only``) on ``scheduler``. The
    notebooks then find the checkpoints and only evaluate. 0 when every run finished, else 1."""
    from drfkit.study.params import NOTEBOOKS, load_profile, notebook_params

    values = load_profile(profile) | (overrides or {})
    for name in NOTEBOOKS:  # every notebook's parameters before an hour of training, as the pipeline does
        if not only or name in only:
            notebook_params(name, values)
    studies = [s for s, nb in runs_of.TRAINING_NOTEBOOK.items() if not only or nb in only]
    if not studies:
        return 0
    runs = grid_runs(values, studies)
    threads = threads or study_params(values, studies[0]).threads or 1
    parse_scheduler(scheduler, threads)
    outcome = run_grid(values, runs, scheduler, threads, out=out)
    return 1 if any(isinstance(v, BaseException) for v in outcome.values()) else 0


__all__ = ["Run", "grid_runs", "run_grid", "train_run", "run_finished_on_disk", "parse_scheduler", "pretrain", "study_params"]
