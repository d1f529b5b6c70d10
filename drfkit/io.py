"""Atomic writes and parameter-hashed caching.

Every file a run writes goes through here: the bytes land in a temporary file in the
same folder and are moved over the target with ``os.replace``, so a killed run never
leaves a half-written file that a later step would trust.
"""
from __future__ import annotations

import contextlib
import fcntl
import hashlib
import io
import json
import os
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
def exclusive_lock(path: str | os.PathLike, what: str, wait_s: float = 0.0):
    """Hold an OS lock (``flock``) on ``path`` for the block; if another process holds it after
    ``wait_s`` seconds, raise ``LockedError`` naming that process. The lock dies with its process
    (kill -9 included), so a crashed writer never leaves a lock behind; the file stays, harmless."""
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
        fh.truncate()
        fh.write(f"process {os.getpid()} on {socket.gethostname()}")
        fh.flush()
        yield
    finally:
        fh.close()  # closing the file releases the lock


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
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
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


def torch_load_checked(path: str | os.PathLike) -> Any:
    """``torch.load`` that turns a missing or damaged file into one clear error."""
    import torch

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"checkpoint {path} does not exist")
    try:
        return torch.load(path, map_location="cpu", weights_only=False)
    except Exception as exc:  # truncated zip, pickle error, ...
        raise CorruptArtefactError(
            f"checkpoint {path} is truncated or corrupt ({type(exc).__name__}: {exc}); "
            "delete it and rerun the notebook that wrote it"
        ) from exc


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
