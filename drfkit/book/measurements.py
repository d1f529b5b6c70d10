"""Slow measurements and deterministic studies done once per machine and code: a cache on disk.

A reader who changes one plot and reruns ``make reproduce`` should not wait minutes for timings
and deterministic studies that cannot have changed. ``cached(profile, fn, *args, timing=...)``
calls ``fn(*args)`` once and stores what it returned under a file named by

    key = fn's qualified name, the content of every argument (tensors and weights by sha256,
          parameters, configs and dataclasses field by field), the sha256 of the sources of fn's
          module and of every drfkit module it imports, transitively (``closure_sha256``), and --
          for a timing (``timing=True``) -- this machine: CPU model, cores, GPU, torch version and
          torch threads.

Change any of these and the name changes, so a stale entry is never read: an edit to a module the
computation imports recomputes it, an edit elsewhere in drfkit (a figure, a claim) or to a notebook
recomputes nothing. A timing is a measurement,
not a fact, so its reuse is said where the reader looks (one line per call, and the
notebook's manifest entry lists what was reused); ``DRFKIT_REMEASURE=1`` in the environment
(``make reproduce REMEASURE=1``, ``python -m drfkit reproduce --remeasure``) measures and
computes everything again and overwrites the entries. Files live in
``results/<profile>/measurements/`` (not committed), written atomically as data-only JSON
(``drfkit.util.io.to_data``: tables, arrays, plain values; reading one can run no code); a damaged
or foreign one is computed again, and said so.

    speed = cached(P.profile, training_step_times, configs, x, y, n_batches_per_epoch=20, timing=True)
"""
from __future__ import annotations

import dataclasses
import functools
import hashlib
import os
import json
import sys
import platform
import time
import types
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Callable

import numpy as np
import torch

from drfkit.study.profile import ProfileSection

from drfkit.util.io import atomic_write_text, from_data, param_hash, to_data
from drfkit.book.manifest import cpu_name, note_reused, reused_measurements as reused
from drfkit.util.paths import REPO_ROOT, results_dir

FORMAT = 2  # 2: JSON data (1 was a pickle, never read again)
REMEASURE_ENV = "DRFKIT_REMEASURE"


def measurements_dir(profile: str) -> Path:
    return results_dir(profile, "measurements")


@functools.lru_cache(maxsize=1)
def code_sha256() -> str:
    """sha256 of every drfkit source file (path and bytes): what a computation's result depends on
    besides its arguments. Read once per process (sources do not change under a running kernel)."""
    digest = hashlib.sha256()
    for path in sorted((REPO_ROOT / "drfkit").rglob("*.py")):
        digest.update(path.relative_to(REPO_ROOT).as_posix().encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()


@functools.lru_cache(maxsize=4)
def import_graph(root: Path = REPO_ROOT) -> dict[str, frozenset[str]]:
    """drfkit module -> the drfkit modules it imports, at module level or inside functions (read once per
    process): what a computation's code closure is made of."""
    import ast

    package = root / "drfkit"
    modules = {".".join(p.relative_to(root).with_suffix("").parts).removesuffix(".__init__"): p
               for p in package.rglob("*.py") if "__pycache__" not in p.parts}
    graph: dict[str, frozenset[str]] = {}
    for name, path in modules.items():
        deps: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                deps |= {a.name for a in node.names if a.name.startswith("drfkit")}
            elif isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("drfkit"):
                deps.add(node.module)
                deps |= {f"{node.module}.{a.name}" for a in node.names if f"{node.module}.{a.name}" in modules}
        graph[name] = frozenset(d for d in deps if d in modules)
    return graph


def closure_sha256(module: str, root: Path = REPO_ROOT) -> str:
    """sha256 of the sources of ``module`` and of every drfkit module it imports, transitively (with the packages
    whose ``__init__`` an import runs): an edit to a module it never imports keeps a cached result."""
    graph = import_graph(root)
    seen, stack = set(), [module]
    while stack:
        name = stack.pop()
        parts = name.split(".")
        for i in range(1, len(parts) + 1):  # importing a.b.c runs a/__init__ and a/b/__init__
            parent = ".".join(parts[:i])
            if parent in graph and parent not in seen:
                seen.add(parent)
                stack.extend(graph[parent])
    digest = hashlib.sha256()
    for name in sorted(seen):
        path = root / Path(*name.split("."))
        path = path / "__init__.py" if path.is_dir() else path.with_suffix(".py")
        digest.update(name.encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()


def _code_key(module: str) -> str:
    """A drfkit function's import closure; any other's (a notebook's, a test's) every drfkit source."""
    return closure_sha256(module) if module.split(".")[0] == "drfkit" else code_sha256()


def machine_fingerprint() -> dict[str, Any]:
    """What a timing depends on besides its arguments: the hardware and the torch that runs it."""
    return {"cpu": cpu_name(), "cpu_count": os.cpu_count(), "arch": platform.machine(),
            "gpu": torch.cuda.get_device_name(0) if torch.cuda.is_available() else None,
            "torch": torch.__version__, "torch_threads": torch.get_num_threads()}


def _bytes_sha256(header: str, data: bytes) -> str:
    return hashlib.sha256(header.encode() + b"|" + data).hexdigest()


def fingerprint(obj: Any) -> Any:
    """A JSON-able stand-in for ``obj`` that two objects share only if they hold the same content.

    Plain values stay as they are; tensors and arrays become the sha256 of dtype, shape and
    bytes; a module the sha256 of its class, configuration, mode and state dict; mappings,
    sequences, dataclasses, namespaces and the typed profile (its declared parameters) are taken apart recursively. Anything else
    (a function, an open file) raises ``TypeError``: its content cannot be keyed, so its result
    must not be cached.
    """
    if obj is None or isinstance(obj, (bool, int, str)):
        return obj
    if isinstance(obj, float):
        return {"float": repr(obj)}  # exact, and nan/inf survive JSON
    if isinstance(obj, (np.integer, np.floating, np.bool_)):
        return fingerprint(obj.item())
    if isinstance(obj, torch.Tensor):
        t = obj.detach().cpu().contiguous()
        return {"tensor": _bytes_sha256(f"{t.dtype}|{tuple(t.shape)}", t.reshape(-1).view(torch.uint8).numpy().tobytes())}
    if isinstance(obj, np.ndarray):
        a = np.ascontiguousarray(obj)
        return {"array": _bytes_sha256(f"{a.dtype}|{a.shape}", a.tobytes())}
    if isinstance(obj, torch.nn.Module):
        digest = hashlib.sha256(f"{type(obj).__module__}.{type(obj).__qualname__}|{obj.training}|".encode())
        digest.update(repr(fingerprint(getattr(obj, "config", None))).encode())
        for name, tensor in sorted(obj.state_dict().items()):
            digest.update(f"{name}|{fingerprint(tensor)['tensor']}|".encode())
        return {"module": digest.hexdigest()}
    if isinstance(obj, Path):
        return {"path": str(obj)}
    if isinstance(obj, torch.device):
        return {"device": str(obj)}
    if isinstance(obj, dict):
        items = [[fingerprint(k), fingerprint(v)] for k, v in obj.items()]
        return {"dict": sorted(items, key=repr)}
    if isinstance(obj, (list, tuple)):
        return {type(obj).__name__: [fingerprint(v) for v in obj]}
    if isinstance(obj, (set, frozenset)):
        return {"set": sorted((fingerprint(v) for v in obj), key=repr)}
    if isinstance(obj, ProfileSection):  # the typed profile: its declared parameters (an undeclared one cannot be read)
        return {"profile": fingerprint(obj.declared())}
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        fields = {f.name: fingerprint(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
        return {"dataclass": f"{type(obj).__module__}.{type(obj).__qualname__}", "fields": fields}
    if isinstance(obj, types.SimpleNamespace):
        return {"namespace": type(obj).__qualname__, "fields": fingerprint(vars(obj))}
    raise TypeError(f"cannot key a {type(obj).__module__}.{type(obj).__qualname__} argument for the measurement "
                    "cache; pass plain values, tensors, modules, dataclasses or containers of them, "
                    "or call the function directly")


def key(fn: Callable, args: tuple, kwargs: dict[str, Any], *, with_machine: bool) -> str:
    """The cache file stem of ``fn(*args, **kwargs)`` (see the module docstring)."""
    return param_hash({"format": FORMAT, "fn": f"{fn.__module__}.{fn.__qualname__}", "args": fingerprint(args),
                       "kwargs": fingerprint(kwargs), "code": _code_key(fn.__module__),
                       "machine": machine_fingerprint() if with_machine else None}, length=24)


def remeasure_requested() -> bool:
    return os.environ.get(REMEASURE_ENV, "").strip() not in ("", "0")


def cached(profile: str | None, fn: Callable, *args: Any, timing: bool, **kwargs: Any) -> Any:
    """``fn(*args, **kwargs)``, or what it returned the last time it was called with the same key.

    timing: True for a timing (the key holds this machine), False for a deterministic result
    (the key holds only code and arguments). ``profile=None`` switches the cache off.
    """
    name = f"{fn.__module__}.{fn.__qualname__}"
    path = None
    if profile is not None:
        path = measurements_dir(profile) / f"{fn.__name__}-{key(fn, args, kwargs, with_machine=timing)}.json"
    if path is not None and path.exists() and not remeasure_requested():
        try:
            stored = json.loads(path.read_text())
            if stored.get("format") == FORMAT and stored.get("fn") == name:
                value = from_data(stored["value"])
                what = "measured on this machine" if timing else "computed with this code"
                print(f"{fn.__name__}: reused, {what} at {stored['when']} in {stored['seconds']:.0f} s "
                      f"({REMEASURE_ENV}=1 or make reproduce REMEASURE=1 to redo it)", flush=True)
                note_reused({"fn": name, "when": stored["when"], "seconds": stored["seconds"],
                                "timing": timing, "file": path.name})
                return value
        except Exception as exc:  # noqa: BLE001 -- a damaged or foreign entry is computed again below
            print(f"warning: measurement cache entry {path} is not a data-only entry of this code "
                  f"({type(exc).__name__}); computing it again", file=sys.stderr)
    t0 = time.perf_counter()
    value = fn(*args, **kwargs)
    seconds = time.perf_counter() - t0
    if path is not None:
        when = datetime.now(timezone.utc).isoformat(timespec="seconds")
        try:
            document = json.dumps({"format": FORMAT, "fn": name, "value": to_data(value), "when": when,
                                   "seconds": round(seconds, 2), "machine": machine_fingerprint()})
        except TypeError as exc:
            print(f"warning: {fn.__name__} returned what the measurement cache cannot store as data ({exc}); "
                  "not cached", file=sys.stderr)
        else:
            atomic_write_text(path, document)
    return value


__all__ = ["cached", "closure_sha256", "code_sha256", "import_graph", "fingerprint", "key", "machine_fingerprint", "measurements_dir", "remeasure_requested",
           "reused"]
