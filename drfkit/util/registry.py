"""The book's extension points as registries, and extension files that add to them.

A ``Registry`` maps a name to what is registered under it (a model class, a noise kind's
corruption, a claim). The book's own entries are registered when their module is imported; an
**extension** is one Python file that registers more at import, through the same ``register``:

    # my_model.py
    from drfkit.models import MODEL_CLASSES, NoDynamics

    @MODEL_CLASSES.register("toy")
    class Toy(NoDynamics): ...

``extensions(paths)`` imports such files for a block and removes everything they registered when
the block ends (what the tests use: nothing outlives them, no registry is patched by hand);
``load_extensions()`` imports the files named by ``DRFKIT_EXTENSIONS`` (paths separated by
``os.pathsep``) for a whole run, which is how a notebook run by the pipeline sees them.
"""
from __future__ import annotations

import contextlib
import importlib.util
import os
import sys
from pathlib import Path
from typing import Any, Iterator, TypeVar

T = TypeVar("T")
ENV = "DRFKIT_EXTENSIONS"

# (registry, name) of every registration made while an ``extensions`` block imports its files
_journal: list[list[tuple["Registry", str]]] = []
_loaded: dict[Path, Any] = {}


class Registry(dict):
    """A dict of ``what`` (for messages) whose entries are added by ``register``, never replaced:
    registering a taken name is an error naming the entry already there."""

    def __init__(self, what: str, entries: dict[str, Any] | None = None):
        super().__init__()
        self.what = what
        for name, value in (entries or {}).items():
            self.register(name, value)

    def register(self, name: str, value: Any = None) -> Any:
        """Add ``value`` under ``name`` and return it; without ``value``, a decorator that does so."""
        if value is None:
            def decorate(obj: T) -> T:
                self.register(name, obj)
                return obj
            return decorate
        if not isinstance(name, str) or not name:
            raise ValueError(f"a {self.what} is registered under a non-empty name, got {name!r}")
        if name in self and self[name] is not value:
            raise ValueError(f"{self.what} {name!r} is registered already ({self[name]!r}); choose another name")
        if name not in self:
            super().__setitem__(name, value)
            if _journal:
                _journal[-1].append((self, name))
        return value

    def unregister(self, name: str) -> None:
        if name not in self:
            raise KeyError(f"no {self.what} {name!r} is registered; registered: {sorted(self)}")
        super().__delitem__(name)

    def __setitem__(self, name, value):  # one way in, so an extension's entries can be taken out again
        raise TypeError(f"add a {self.what} with .register({name!r}, ...), not by item assignment")


def _import_file(path: Path) -> Any:
    path = Path(path).resolve()
    if not path.is_file():
        raise FileNotFoundError(f"extension file {path} does not exist (check {ENV} or the path given)")
    name = f"drfkit_extension_{abs(hash(path)):x}_{path.stem}"
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        sys.modules.pop(name, None)
        raise
    return module


@contextlib.contextmanager
def extensions(*paths: str | Path) -> Iterator[list[Any]]:
    """Import the extension files ``paths`` for the block (their modules are yielded); every
    registration they made is removed when it ends, in reverse order, whatever happened."""
    _journal.append([])
    modules = []
    try:
        for path in paths:
            modules.append(_import_file(Path(path)))
        yield modules
    finally:
        for registry, name in reversed(_journal.pop()):
            registry.unregister(name)
        for module in modules:
            sys.modules.pop(module.__name__, None)


def load_extensions(env: dict[str, str] | None = None) -> list[Any]:
    """Import, once per process, the files ``DRFKIT_EXTENSIONS`` names; what they register stays."""
    value = (os.environ if env is None else env).get(ENV, "")
    out = []
    for part in filter(None, value.split(os.pathsep)):
        path = Path(part).resolve()
        if path not in _loaded:
            _loaded[path] = _import_file(path)
        out.append(_loaded[path])
    return out


__all__ = ["Registry", "extensions", "load_extensions", "ENV"]
