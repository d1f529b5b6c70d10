"""Progress of long computations inside a notebook, shown where the user is looking.

A notebook run by the pipeline (``make reproduce``) executes in a Jupyter kernel whose output goes
into the notebook, not to the terminal. So the pipeline names a file in the environment variable
``DRFKIT_PROGRESS_FILE``; ``steps`` appends a line to it now and then (what is done, of how many,
elapsed and a rough time left), and the pipeline echoes new lines to its terminal
(``Echo``). Without the variable (a notebook opened by hand, a test) nothing is written: stored
notebook outputs stay the same either way.
"""
from __future__ import annotations

import os
import sys
import threading
import time
from pathlib import Path
from typing import Iterable, Iterator, TypeVar

ENV = "DRFKIT_PROGRESS_FILE"
EVERY_S = 10.0  # at most one line per this many seconds, plus the last

T = TypeVar("T")


def _clock(seconds: float) -> str:
    minutes, secs = divmod(int(round(seconds)), 60)
    return f"{minutes}:{secs:02d}"


def steps(items: Iterable[T], desc: str, total: int | None = None, every_s: float = EVERY_S) -> Iterator[T]:
    """Yield ``items``; with ``DRFKIT_PROGRESS_FILE`` set, report ``desc: k/total`` lines to it."""
    path = os.environ.get(ENV)
    if not path:
        yield from items
        return
    items = list(items) if total is None else items
    total = len(items) if total is None else total
    t0 = last = time.perf_counter()
    done = 0

    def report() -> None:
        elapsed = time.perf_counter() - t0
        left = f", ~{_clock(elapsed / done * (total - done))} left" if 0 < done < total else ""
        with open(path, "a", encoding="utf-8") as f:
            f.write(f"   {desc}: {done}/{total} ({_clock(elapsed)} elapsed{left})\n")

    for item in items:
        yield item
        done += 1
        now = time.perf_counter()
        if now - last >= every_s or done == total:
            report()
            last = now


class Echo:
    """Copy the lines appended to ``path`` onto ``stream`` (a background thread) while in use;
    sets ``DRFKIT_PROGRESS_FILE`` for the processes started meanwhile (the notebook's kernel)."""

    def __init__(self, path: Path, stream=None, poll_s: float = 0.5):
        self.path, self.stream, self.poll_s = Path(path), stream or sys.stderr, poll_s
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        offset = 0
        while True:
            stopping = self._stop.is_set()
            try:
                with open(self.path, "rb") as f:
                    f.seek(offset)
                    chunk = f.read()
            except FileNotFoundError:
                chunk = b""
            if b"\n" in chunk:
                whole = chunk[:chunk.rindex(b"\n") + 1]
                offset += len(whole)
                self.stream.write("\n" + whole.decode("utf-8", "replace"))  # below papermill's cell bar
                self.stream.flush()
            if stopping:
                return
            self._stop.wait(self.poll_s)

    def __enter__(self) -> "Echo":
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.path.write_text("")
        self._previous = os.environ.get(ENV)
        os.environ[ENV] = str(self.path)
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()
        if self._previous is None:
            os.environ.pop(ENV, None)
        else:
            os.environ[ENV] = self._previous
        self.path.unlink(missing_ok=True)
