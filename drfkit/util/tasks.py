"""Evaluation tasks on every core: independent (model, input set) evaluations mapped over worker processes.

A notebook cell that evaluates one model after another runs on torch's intra-op threads, which these small
networks cannot keep busy; the same cell as tasks on single-threaded worker processes uses every core it is
given. ``map_tasks(fn, items, shared)`` calls ``fn(*item, shared=shared)`` for every item and returns the
results **in the items' order**, whatever order the workers finish in, so a table built from them is byte
for byte the same at any worker count: every task runs at one torch thread, here or in a worker.

Where the tasks run is the machine's business, not the profile's (the numbers do not depend on it):

    DRF_WORKERS unset or 1   in this process, one task after another (at one torch thread)
    DRF_WORKERS=N            a dask.distributed LocalCluster of N single-threaded worker processes,
                             started on first use and kept for the process's life (the training grid's
                             kind of cluster, ``drfkit.book.grid``)
    DRF_WORKERS=auto         N = the usable cores
    DRF_WORKERS=tcp://...    a running Dask scheduler; its workers must import this drfkit and see the
                             same results folder (a shared file system)

``shared`` (e.g. the trained models) is sent to each worker once per call, not once per task.
"""
from __future__ import annotations

import atexit
import os
from typing import Any, Callable, Sequence

from drfkit.util.progress import steps

ENV = "DRF_WORKERS"
_CLIENTS: dict[str, Any] = {}
# What the tasks of a call read (a test set, say), kept per process so that each process reads it once, not once
# per task; bounded, newest kept, because a worker outlives the calls that filled it.
_MEMO: dict[str, Any] = {}
MEMO_ENTRIES = 16


def memo(key: tuple, make: Callable[[], Any]) -> Any:
    """``make()``, or what it returned for ``key`` in this process (``key``: a picklable tuple naming the value
    completely, e.g. (digest of the profile, study, split, level)). ``forget()`` empties it."""
    name = _digest(key)
    if name not in _MEMO:
        while len(_MEMO) >= MEMO_ENTRIES:
            _MEMO.pop(next(iter(_MEMO)))
        _MEMO[name] = make()
    return _MEMO[name]


def forget() -> None:
    """Empty this process's ``memo`` (a caller that may have changed what a key names, e.g. a test)."""
    _MEMO.clear()


def _digest(obj) -> str:
    import hashlib
    import pickle

    return hashlib.sha256(pickle.dumps(obj)).hexdigest()


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity where the OS has one)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def task_workers(workers: int | str | None = None) -> int | str:
    """The worker setting: ``workers``, else ``DRF_WORKERS``, else 1; 'auto' -> the usable cores; an address
    stays a string. A bad value is refused with the forms that are accepted."""
    value = os.environ.get(ENV, "1") if workers is None else workers
    if isinstance(value, str):
        value = value.strip()
        if "://" in value:
            return value
        if value == "auto":
            return usable_cores()
        if not value.isdigit():
            raise ValueError(f"{ENV}={value!r}: use a number of worker processes (1 = in this process), 'auto' "
                             "(the usable cores) or a Dask scheduler address such as tcp://host:8786")
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f"workers must be an integer >= 1, 'auto' or a scheduler address, got {value!r}")
    return value


_DASK_TRIM, _DASK_TRIM_VALUE = "MALLOC_TRIM_THRESHOLD_", "65536"


def local_cluster(n_workers: int, **kwargs: Any):
    """A dask.distributed LocalCluster of ``n_workers`` single-threaded worker processes, without Dask's default
    ``MALLOC_TRIM_THRESHOLD_=65536`` for its workers: with it glibc hands freed memory back to the OS after every
    large free, and these models' many tensor allocations ran about 3x slower per task in a worker than in this
    process (tools/eval_scaling.py; docs/rerun_time.md). The training grid's cluster is made here too."""
    import dask
    from distributed import LocalCluster

    # a cluster started earlier in this process without this (Dask's own, say) left its value in os.environ, which
    # every later worker would inherit: drop that value (Dask's, not a user's own setting)
    if os.environ.get(_DASK_TRIM) == _DASK_TRIM_VALUE:
        del os.environ[_DASK_TRIM]
    with dask.config.set({f"distributed.nanny.pre-spawn-environ.{_DASK_TRIM}": None}):
        return LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, **kwargs)


def _one_thread() -> None:
    import torch

    torch.set_num_threads(1)


def _client(workers: int | str):
    """A client on a LocalCluster of ``workers`` single-threaded processes (or on a scheduler address), kept
    for later calls of this process and closed at its exit."""
    key = str(workers)
    if key not in _CLIENTS:
        import logging

        from distributed import Client

        if isinstance(workers, str):
            client, cluster = Client(workers), None
        else:
            logging.getLogger("distributed").setLevel(logging.ERROR)  # worker chatter is not the notebook's output
            cluster = local_cluster(workers, dashboard_address=None)
            client = Client(cluster)
        client.run(_one_thread)
        _CLIENTS[key] = client
        if len(_CLIENTS) == 1:
            atexit.register(close_workers)
    return _CLIENTS[key]


def close_workers() -> None:
    """Close the clusters this process started (they are closed at exit otherwise)."""
    while _CLIENTS:
        _, client = _CLIENTS.popitem()
        cluster = getattr(client, "cluster", None)
        client.close()
        if cluster is not None:
            cluster.close()


def _call(fn: Callable, item: tuple, shared: Any) -> Any:
    _one_thread()
    return fn(*item, shared=shared)


def map_tasks(fn: Callable[..., Any], items: Sequence[tuple], shared: Any = None, desc: str = "tasks",
              workers: int | str | None = None) -> list[Any]:
    """``[fn(*item, shared=shared) for item in items]``, each call at one torch thread, on ``workers``
    (``task_workers``: in this process for 1). ``fn`` must be a module-level function and items and shared
    picklable when workers > 1. Results come back in the items' order; progress is reported per task."""
    import torch

    items = [tuple(item) for item in items]
    n = task_workers(workers)
    if n == 1 or len(items) <= 1:
        previous = torch.get_num_threads()
        try:
            return [_call(fn, item, shared) for item in steps(items, desc, len(items))]
        finally:
            torch.set_num_threads(previous)
    from distributed import as_completed

    client = _client(n)
    shared_future = client.scatter(shared, broadcast=True) if shared is not None else None
    futures = [client.submit(_call, fn, item, shared_future, pure=False) for item in items]
    index = {f.key: i for i, f in enumerate(futures)}
    results: list[Any] = [None] * len(items)
    for future in steps(as_completed(futures), desc, len(items)):
        results[index[future.key]] = future.result()  # re-raises a task's error here, with its traceback
    return results


__all__ = ["ENV", "usable_cores", "local_cluster", "task_workers", "map_tasks", "close_workers", "memo", "forget"]
