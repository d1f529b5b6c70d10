"""Each MC-dropout prediction computed once: a cache on disk shared by every notebook.

Notebooks 01, 02, 04 and 06 evaluate the same checkpoints on the same test sets (01's table at
the paper's levels is part of 04's sweep; 04's dropout-rate curves repeat 01's). A prediction
is fixed by what went into it, so the cache file is named by the hash of exactly that:

    key = the model's content (sha256 of its configuration and every weight), the inputs'
          content (sha256 of their bytes), the dropout rate, the number of samples, the seed,
          the chunk size (it orders the dropout masks), the device type and the code that computes
          it (``PREDICTION_CODE``: the models, core and the sampling, not the rest of drfkit).

One entry per rate: ``predict_rates`` draws the masks' uniforms once per head chunk for every rate
(``SharedUniforms``), so a rate's prediction does not depend on which other rates were asked with it
(tested), and a call finds each rate it asks for wherever it was computed (01's table at the default
rate is the same member of its five-rate curve; 02's evaluation of a model is 04's curve at that rate).
A call computes only the rates it does not find.

The deterministic part of a prediction (``model.features``: the encoder, then the filter or LSTM) is stored
too, in ``features/`` beside the predictions, keyed by the same model, inputs, chunk size, device and code but by
no rate, sample count or seed: a later call at other rates (04's curves after 02's and 04's evaluations at the
models' own rates) runs only the heads, about a twentieth of a filter's evaluation. The features draw no random
numbers, so the predictions are the same bit for bit (tested).

Change any of these and the file name changes, so a stale entry is never read. Files live
in ``results/<profile>/predictions/`` (not committed; delete the folder to empty the cache),
written atomically; a damaged one is recomputed. Hashing the weights themselves (a few ms)
rather than trusting a file name means a model changed after loading can never be served a
stale prediction.

    preds = cached_predict_rates(model, data.inputs, cache=predictions_dir(P.profile),
                                 n_samples=25, dropout_rates=[None], seed=0, label="pendulum test 0.75")
"""
from __future__ import annotations

import functools
import hashlib
import json
from pathlib import Path
from typing import Any

import torch

from drfkit.util.io import CorruptArtefactError, atomic_torch_save, param_hash, torch_load_checked
from drfkit.methods.uncertainty import Prediction, as_model_input, model_features, predict_rates

# 2: the masks are drawn as uniforms shared by the rates, per head chunk (uncertainty.predict_rates); a
# prediction stored by format 1 holds other (equally valid) draws and is computed again
# 3: the dropout-off point estimate is stored beside the MC moments
# 4: one entry per rate (a call computes the rates it does not find)
FORMAT = 4
FEATURES_FORMAT = 1
FIELDS = ("mean", "aleatoric", "epistemic", "total", "point")
# sequences per prediction chunk of every test-set evaluation: one batch size (it orders the masks' draws), so a
# later call on the same inputs (calibration, the curves, the mechanism tables) finds the evaluation's entry
EVAL_BATCH_SIZE = 256


def weights_sha256(model) -> str:
    """sha256 of ``model.config`` and every tensor of its state dict (name, dtype, shape, bytes)."""
    digest = hashlib.sha256(json.dumps(model.config, sort_keys=True, default=str).encode())
    for name, tensor in sorted(model.state_dict().items()):
        t = tensor.detach().cpu().contiguous()
        digest.update(f"{name}|{t.dtype}|{tuple(t.shape)}|".encode())
        digest.update(t.reshape(-1).view(torch.uint8).numpy().tobytes())
    return digest.hexdigest()


def tensor_sha256(x: torch.Tensor) -> str:
    t = x.detach().cpu().contiguous()
    return hashlib.sha256(f"{t.dtype}|{tuple(t.shape)}|".encode() + t.reshape(-1).view(torch.uint8).numpy().tobytes()
                          ).hexdigest()


# the code a prediction is computed by: the models, the filter and metrics beneath them, and the sampling
PREDICTION_CODE = ("drfkit/models/*.py", "drfkit/core/*.py", "drfkit/methods/uncertainty.py")


def prediction_code_sha256(patterns=PREDICTION_CODE) -> str:
    """sha256 of the source files a prediction is computed by (path and bytes): an edit to a model's numerics
    drops the cached predictions, an edit anywhere else (a figure, a claim) keeps them."""
    from drfkit.util import paths

    return _code_sha256(paths.REPO_ROOT, tuple(patterns))


@functools.lru_cache(maxsize=4)
def _code_sha256(root, patterns: tuple[str, ...]) -> str:
    """Read once per process and root (sources do not change under a running kernel)."""
    digest = hashlib.sha256()
    for f in sorted({f for pattern in patterns for f in root.glob(pattern) if f.is_file()}):
        digest.update(f.relative_to(root).as_posix().encode() + b"\0" + f.read_bytes() + b"\0")
    return digest.hexdigest()


def prediction_key(model, inputs: torch.Tensor, n_samples: int, rates: list[float], seed: int,
                   batch_size: int | None, device: torch.device | str | None) -> str:
    """The cache file stem of a prediction (see the module docstring)."""
    device_type = torch.device(device).type if device is not None else next(model.parameters()).device.type
    return param_hash({"format": FORMAT, "model": weights_sha256(model), "inputs": tensor_sha256(inputs),
                       "n_samples": int(n_samples), "rates": [float(r) for r in rates], "seed": int(seed),
                       "batch_size": batch_size, "device": device_type, "code": prediction_code_sha256()})


def cached_predict_rates(model, inputs, *, cache: Path | None, n_samples: int, dropout_rates, seed: int,
                         batch_size: int | None = None, device=None, label: str = "") -> list[Prediction]:
    """``drfkit.methods.uncertainty.predict_rates`` seeded with ``seed``, each rate read from ``cache`` when the
    same prediction was made before (the same numbers, bit for bit), the others computed together and stored.

    ``cache=None`` switches the cache off; ``label`` is kept in the file for a reader.
    """
    x = as_model_input(model, inputs)
    rates = [model.default_dropout_p if p is None else float(p) for p in dropout_rates]
    paths = {}
    if cache is not None:
        paths = {p: Path(cache) / f"{prediction_key(model, x, n_samples, [p], seed, batch_size, device)}.pt"
                 for p in dict.fromkeys(rates)}
    found = {p: pred for p, path in paths.items() if (pred := _read(path)) is not None}
    missing = [p for p in dict.fromkeys(rates) if p not in found]
    if missing:
        h = None if cache is None else cached_features(model, x, cache=cache, batch_size=batch_size, device=device)
        torch.manual_seed(seed)  # the dropout masks are part of the prediction
        computed = predict_rates(model, x, n_samples=n_samples, dropout_rates=missing, batch_size=batch_size,
                                 device=device, features=h)
        for p, pred in zip(missing, computed):
            found[p] = pred
            if p in paths:
                paths[p].parent.mkdir(parents=True, exist_ok=True)
                atomic_torch_save(paths[p], {"format": FORMAT, "label": label, "prediction": {
                    **{f: getattr(pred, f) for f in FIELDS}, "n_samples": pred.n_samples, "dropout_p": pred.dropout_p}})
    return [found[p] for p in rates]


def features_key(model, inputs: torch.Tensor, batch_size: int | None, device: torch.device | str | None) -> str:
    """The store's file stem of ``model_features(model, inputs, batch_size, device)`` (see the module docstring)."""
    device_type = torch.device(device).type if device is not None else next(model.parameters()).device.type
    return param_hash({"format": FEATURES_FORMAT, "features": True, "model": weights_sha256(model),
                       "inputs": tensor_sha256(inputs), "batch_size": batch_size, "device": device_type,
                       "code": prediction_code_sha256()})


def cached_features(model, inputs, *, cache: Path, batch_size: int | None = None, device=None) -> torch.Tensor:
    """``drfkit.methods.uncertainty.model_features`` (B, T, D), read from ``cache``/features/ when the same model
    ran on the same inputs before, else computed and stored (atomically; a damaged entry is computed again)."""
    x = as_model_input(model, inputs)
    path = Path(cache) / "features" / f"{features_key(model, x, batch_size, device)}.pt"
    if path.exists():
        try:
            stored = torch_load_checked(path)
            if stored.get("format") == FEATURES_FORMAT and tuple(stored["features"].shape[:2]) == tuple(x.shape[:2]):
                return stored["features"]
        except (CorruptArtefactError, KeyError, TypeError, AttributeError):
            pass
    h = model_features(model, x, batch_size=batch_size, device=device)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_torch_save(path, {"format": FEATURES_FORMAT, "features": h})
    return h


def point_and_sigma(model, images, *, cache: Path | None, n_samples: int, seed: int):
    """The dropout-off point estimate and the MC-dropout total sigma, numpy (N, T, out), of ``model`` on ``images``,
    seeded, at the evaluation's batch size (the same cache entry as the studies' evaluation of those inputs)."""
    pred = cached_predict_rates(model, images, cache=cache, n_samples=n_samples, dropout_rates=[None], seed=seed,
                                batch_size=EVAL_BATCH_SIZE)[0]
    return pred.point.numpy(), pred.total.numpy()


def _read(path: Path) -> Prediction | None:
    """A stored prediction, or None when absent, of another format or damaged (then computed again)."""
    if not path.exists():
        return None
    try:
        stored = torch_load_checked(path)
        if stored.get("format") == FORMAT:
            p = stored["prediction"]
            return Prediction(**{f: p[f] for f in FIELDS}, n_samples=p["n_samples"], dropout_p=p["dropout_p"])
    except (CorruptArtefactError, KeyError, TypeError, AttributeError):
        pass
    return None


__all__ = ["EVAL_BATCH_SIZE", "PREDICTION_CODE", "cached_features", "cached_predict_rates", "features_key", "point_and_sigma", "prediction_code_sha256", "prediction_key", "tensor_sha256", "weights_sha256"]
