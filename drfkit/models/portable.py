"""A model that crosses a process boundary as a checkpoint does: its configuration and weights.

``drfkit.util.tasks`` sends the models of an evaluation to worker processes. A module pickled as an object carries
whatever a run left on it (an LSTM's weak references to its flat weights, which Dask's pickling of a module keeps
and cannot send); ``Portable`` sends only ``model.config`` and the state dict and rebuilds the model on the other
side with ``build_model``, in the same mode, so the worker's model computes what the caller's does (and hashes
to the same prediction-cache key: the same weights). In the calling process ``.model`` is the caller's own object.
"""
from __future__ import annotations

from typing import Any, Mapping


class Portable:
    """Wraps ``model`` (a drfkit model: ``.config``, ``.state_dict()``); pickles as (config, weights, mode, meta)."""

    def __init__(self, model):
        self.model = model

    def __reduce__(self):
        if not hasattr(self.model, "config"):
            raise TypeError(f"{type(self.model).__name__} has no .config: only a drfkit model crosses to a worker "
                            "(build it with drfkit.models.build_model or load it with load_checkpoint), or run the "
                            "tasks in this process (DRF_WORKERS=1)")
        state = {k: v.detach().cpu() for k, v in self.model.state_dict().items()}
        return _rebuild, (dict(self.model.config), state, bool(self.model.training),
                          getattr(self.model, "checkpoint_meta", None))


def _rebuild(config: dict[str, Any], state: dict, training: bool, meta) -> Portable:
    from drfkit.models import build_model

    model = build_model(config)
    model.load_state_dict(state)
    if meta is not None:
        model.checkpoint_meta = meta
    return Portable(model.train(training))


def portable(models: Mapping[Any, Any]) -> dict[Any, Portable]:
    """{key: Portable(model)} of a (kind, seed) -> model mapping."""
    return {key: Portable(model) for key, model in models.items()}


__all__ = ["Portable", "portable"]
