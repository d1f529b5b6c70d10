"""Atomic writes and parameter-hashed caching.

Every file a run writes goes through here: the bytes land in a temporary file in the
same folder and are moved over the target with ``os.replace``, so a killed run never
leaves a half-written file that a later step would trust.
"""
from __future__ import annotations

import contextlib
import errno
import fcntl
import hashlib
import io
import json
import os
import re
import socket
import tempfile
import time
import zipfile
from pathlib import Path
from typing import Any, Callable

import numpy as np


_UMASK = os.umask(0)
os.umask(_UMASK)


class CorruptArtefactError(RuntimeError):
    """A cached file or checkpoint exists but cannot be read."""


class LockedError(RuntimeError):
    """Another process holds the lock of a file this process would write."""


@contextlib.contextmanager
def exclusive_lock(path: str | os.PathLike, what: str, wait_s: float = 0.0, announce_stale: bool = False):
    """Hold an OS lock (``flock``) on ``path`` for the block; if another process holds it after
    ``wait_s`` seconds, raise ``LockedError`` naming that process (PID and host). The lock dies with
    its process (kill -9 included), so a crashed writer never leaves a lock behind; the file stays,
    harmless. The file names the holder while the lock is held and is emptied on a normal exit, so a
    holder's name found on taking the lock means that process died holding it (``announce_stale``:
    say so in one line on stderr)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fh = open(path, "a+")
    deadline = time.monotonic() + wait_s
    try:
        while True:
            try:
                fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if time.monotonic() >= deadline:
                    fh.seek(0)
                    holder = fh.read().strip() or "an unknown process"
                    raise LockedError(f"{what} is being written by {holder} (lock {path}); wait until it has "
                                      "finished or stop it -- this process wrote nothing") from None
                time.sleep(0.2)
        fh.seek(0)
        stale = fh.read().strip()
        if stale and announce_stale:
            import sys

            print(f"{what}: taking over the lock {path} from {stale}, which stopped without releasing it "
                  "(killed?)", file=sys.stderr, flush=True)
        fh.seek(0)
        fh.truncate()
        fh.write(f"process {os.getpid()} on {socket.gethostname()}")
        fh.flush()
        yield
        fh.seek(0)
        fh.truncate()  # released normally: nobody to report next time
    finally:
        fh.close()  # closing the file releases the lock


class DiskFullError(OSError):
    """A write ran out of space (ENOSPC); the previous file is intact."""


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (temp file in the same folder + rename)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp makes 0600; results are meant to be shared
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        if os.path.exists(tmp):
            os.unlink(tmp)
        if isinstance(exc, OSError) and exc.errno == errno.ENOSPC:
            raise DiskFullError(errno.ENOSPC, f"no space left on the device while writing {path}; the previous "
                                f"version of it (if any) is intact and nothing half-written was left. Free space "
                                f"(df -h {path.parent}) and rerun the same command") from exc
        raise
    return path


def atomic_write_text(path: str | os.PathLike, text: str) -> Path:
    return atomic_write_bytes(path, text.encode("utf-8"))


def atomic_write_json(path: str | os.PathLike, obj: Any) -> Path:
    return atomic_write_text(path, json.dumps(obj, indent=2, sort_keys=True, default=_json_default) + "\n")


def atomic_write_csv(path: str | os.PathLike, frame) -> Path:
    """Write a pandas DataFrame as CSV atomically (no index column)."""
    return atomic_write_text(path, frame.to_csv(index=False, float_format="%.6g"))


def atomic_savefig(path: str | os.PathLike, fig, dpi: int = 120) -> Path:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    return atomic_write_bytes(path, buf.getvalue())


def atomic_torch_save(path: str | os.PathLike, obj: Any) -> Path:
    import torch

    buf = io.BytesIO()
    torch.save(obj, buf)
    return atomic_write_bytes(path, buf.getvalue())


class UnsafeArtefactError(RuntimeError):
    """A file holds something a data-only loader refuses (code to run on load); it was not run."""


def torch_load_checked(path: str | os.PathLike) -> Any:
    """Load a checkpoint, resume state or cache entry with PyTorch's safe loader.

    ``weights_only=True``: only tensors, plain Python values and containers of them are rebuilt;
    a pickled object that would import a global or call a function on load (an ``os.system`` in a
    ``__reduce__``) is refused before anything runs, with ``UnsafeArtefactError`` naming the file
    and what was refused. A missing file raises ``FileNotFoundError``, a damaged one
    ``CorruptArtefactError``. Every file the book writes holds plain data and loads here.
    """
    import pickle

    import torch

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"checkpoint {path} does not exist")
    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as exc:
        text = str(exc)
        # a refused import (GLOBAL opcode) is code the file wants to run; other unpickling errors of the
        # safe loader ("Unsupported operand ...") are damaged bytes
        if re.search(r"GLOBAL|Unsupported global|Unsupported class|not an allowed global", text):
            refused = next((line.strip() for line in text.splitlines() if "GLOBAL" in line or "global" in line),
                           text.splitlines()[0] if text else "an object that is not plain data")
            raise UnsafeArtefactError(
                f"refused to load {path}: it holds more than tensors and plain values ({refused}); "
                "nothing in it was run. Only load files you trust; the book's own files never need this -- "
                "delete it and rerun what wrote it") from None
        raise CorruptArtefactError(
            f"checkpoint {path} is truncated or corrupt (UnpicklingError: {exc}); "
            "delete it and rerun the notebook that wrote it") from exc
    except Exception as exc:  # truncated zip, ...
        raise CorruptArtefactError(
            f"checkpoint {path} is truncated or corrupt ({type(exc).__name__}: {exc}); "
            "delete it and rerun the notebook that wrote it"
        ) from exc


# ------------------------------------------------------------------ data-only JSON documents
# The measurement cache stores tables, arrays and plain values as JSON (never pickle): reading a
# file rebuilds data and can run nothing. Floats are written with repr, so a value comes back
# bit for bit (nan and inf included, as JSON's NaN / Infinity extension).

def to_data(obj: Any) -> Any:
    """A JSON-able tagged form of plain values, lists, tuples, dicts, numpy arrays and scalars,
    torch tensors (CPU), pandas DataFrames and Series; anything else raises ``TypeError``."""
    import pandas as pd

    if obj is None or isinstance(obj, (bool, int, str)):
        return obj
    if isinstance(obj, float):
        return obj
    if isinstance(obj, np.generic):
        return {"__scalar__": obj.dtype.str, "value": to_data(obj.item())}
    if type(obj).__module__ == "torch" and type(obj).__name__ == "Tensor":
        array = obj.detach().cpu().numpy()
        return {"__tensor__": to_data(array)}
    if isinstance(obj, np.ndarray):
        if obj.dtype.kind not in "biufU":
            raise TypeError(f"cannot store an array of dtype {obj.dtype} as data")
        return {"__array__": obj.dtype.str, "shape": list(obj.shape), "values": [to_data(v) for v in obj.reshape(-1).tolist()]}
    if isinstance(obj, pd.DataFrame):
        return {"__frame__": {"columns": [to_data(c) for c in obj.columns], "dtypes": [str(d) for d in obj.dtypes],
                              "index": to_data(obj.index.to_frame(index=False).to_dict("list") if obj.index.nlevels > 1
                                               else obj.index.tolist()),
                              "index_names": [to_data(n) for n in obj.index.names], "multi": obj.index.nlevels > 1,
                              "values": [to_data(obj.iloc[:, i].tolist()) for i in range(obj.shape[1])]}}
    if isinstance(obj, pd.Series):
        return {"__series__": to_data(obj.to_frame(name=obj.name if obj.name is not None else "__value__"))}
    if isinstance(obj, tuple):
        return {"__tuple__": [to_data(v) for v in obj]}
    if isinstance(obj, list):
        return [to_data(v) for v in obj]
    if isinstance(obj, dict):
        return {"__dict__": [[to_data(k), to_data(v)] for k, v in obj.items()]}
    raise TypeError(f"cannot store a {type(obj).__module__}.{type(obj).__qualname__} as data")


def from_data(obj: Any) -> Any:
    """The inverse of ``to_data``; an unknown tag raises ``CorruptArtefactError``."""
    import pandas as pd

    if isinstance(obj, list):
        return [from_data(v) for v in obj]
    if not isinstance(obj, dict):
        return obj
    if "__tuple__" in obj:
        return tuple(from_data(v) for v in obj["__tuple__"])
    if "__dict__" in obj:
        return {_hashable(from_data(k)): from_data(v) for k, v in obj["__dict__"]}
    if "__tensor__" in obj:
        import torch

        return torch.from_numpy(np.ascontiguousarray(from_data(obj["__tensor__"])))
    if "__scalar__" in obj:
        return np.dtype(obj["__scalar__"]).type(from_data(obj["value"]))
    if "__array__" in obj:
        return np.array(from_data(obj["values"]), dtype=np.dtype(obj["__array__"])).reshape(obj["shape"])
    if "__frame__" in obj:
        f = obj["__frame__"]
        columns = [_hashable(from_data(c)) for c in f["columns"]]
        data = {i: pd.Series(from_data(v), dtype=d if d != "object" else object)
                for i, (v, d) in enumerate(zip(f["values"], f["dtypes"]))}
        frame = pd.DataFrame(data) if data else pd.DataFrame(index=range(len(from_data(f["index"]))))
        index = from_data(f["index"])
        names = [from_data(n) for n in f["index_names"]]
        frame.index = (pd.MultiIndex.from_frame(pd.DataFrame(index), names=names) if f["multi"]
                       else pd.Index(index, name=names[0]))
        frame.columns = (pd.MultiIndex.from_tuples(columns) if columns and all(isinstance(c, tuple) for c in columns)
                         else pd.Index(columns))
        return frame
    if "__series__" in obj:
        frame = from_data(obj["__series__"])
        series = frame.iloc[:, 0]
        return series.rename(None if frame.columns[0] == "__value__" else frame.columns[0])
    raise CorruptArtefactError(f"unknown data tag in {sorted(obj)[:3]}")


def _hashable(value: Any) -> Any:
    return tuple(_hashable(v) for v in value) if isinstance(value, list) else value


def atomic_save_npz(path: str | os.PathLike, **arrays: np.ndarray) -> Path:
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    return atomic_write_bytes(path, buf.getvalue())


def load_npz_checked(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Load every array of an ``.npz`` into memory, or raise ``CorruptArtefactError``."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            return {k: data[k] for k in data.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError, KeyError) as exc:
        raise CorruptArtefactError(
            f"cached file {path} is truncated or corrupt ({type(exc).__name__}: {exc}); "
            "delete it and rerun (it is rebuilt from its parameters)"
        ) from exc


def param_hash(params: dict[str, Any], length: int = 10) -> str:
    """Stable short hash of a JSON-serialisable parameter dict (key order does not matter)."""
    blob = json.dumps(params, sort_keys=True, default=_json_default).encode()
    return hashlib.sha256(blob).hexdigest()[:length]


def cached_npz(
    cache_dir: str | os.PathLike,
    name: str,
    params: dict[str, Any],
    build: Callable[[], dict[str, np.ndarray]],
) -> dict[str, np.ndarray]:
    """Return the arrays built by ``build()``, cached as ``<cache_dir>/<name>-<hash>.npz``.

    The hash covers ``params``, so changing any parameter builds a new file. A corrupt
    cache file is rebuilt (and said so on stderr) rather than trusted.
    """
    path = Path(cache_dir) / f"{name}-{param_hash(params)}.npz"
    if path.exists():
        try:
            return load_npz_checked(path)
        except CorruptArtefactError as exc:
            import sys

            print(f"warning: {exc}; rebuilding it", file=sys.stderr)
    arrays = build()
    atomic_save_npz(path, **arrays)
    meta = path.with_suffix(".json")
    atomic_write_json(meta, {"name": name, "params": params, "file": path.name})
    return arrays


def _json_default(obj: Any) -> Any:
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.floating,)):
        return float(obj)
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")
