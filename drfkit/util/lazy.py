"""A layer package's re-export of its modules by name, each loaded on first use (PEP 562), so
``from drfkit.core import filter`` works without importing every module of the layer."""
from __future__ import annotations

import importlib
from typing import Any, Callable


def lazy_modules(package: str, names: list[str]) -> Callable[[str], Any]:
    """The ``__getattr__`` of ``package`` that imports ``package.<name>`` for each of ``names``."""
    def __getattr__(name: str) -> Any:
        if name in names:
            return importlib.import_module(f"{package}.{name}")
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    return __getattr__
