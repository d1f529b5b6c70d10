"""One training loop for every model of the book.

Seeded, checkpointed every epoch (resumes after a kill with the same final result),
best checkpoint kept on a validation score (``select_on``), non-finite losses stop the run
with the step named.

What an epoch optimises is ``TrainConfig.objective`` (``drfkit.methods.objectives``): the model's own
loss by default (Gaussian NLL for the DRF family, relative Laplace for Monoloco), or beta-NLL,
with an optional MSE warm-up; the learning rate is constant, stepped or cosine-annealed; the
training data may be drawn afresh every epoch (``fresh_train``: new noise on the same clean
frames) and cut into random windows. The validation loss recorded is always ``model.loss``.

Determinism: the model is initialised under ``torch.manual_seed(seed)``; the batch order
and the windows of epoch ``e`` come from generators seeded with ``(seed, e)``, the fresh
training data of epoch ``e`` from ``fresh_train(e)`` (the caller seeds it by epoch); the global RNG that
drives dropout is saved in the checkpoint and restored on resume. So an interrupted
and resumed run equals an uninterrupted one on CPU.
"""
from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import torch

from drfkit.util.io import CorruptArtefactError, atomic_torch_save, exclusive_lock, param_hash, torch_load_checked
from drfkit.data.sequence_data import SequenceData
from drfkit.methods.objectives import batch_loss, make_optimiser, random_windows, skip_spans
from drfkit.methods.run_config import TrainConfig, fingerprint, naming_fields

CHECKPOINT_FORMAT = 1


class NonFiniteLossError(RuntimeError):
    """The loss or a gradient became NaN/inf; the last good checkpoint is kept."""


class ResumeMismatchError(RuntimeError):
    """An unfinished run would continue under a setting that changes its numbers (thread count)."""


# A second process on a finished checkpoint waits this long for the lock (a cache hit holds it for
# milliseconds); a run that is training holds it for hours, so waiting longer would only hide that.
LOCK_WAIT_S = 10.0


@dataclass
class TrainResult:
    best_path: Path
    last_path: Path
    history: list[dict[str, float]] = field(default_factory=list)
    best_epoch: int = 0
    best_val_loss: float = math.inf
    resumed_from: int = 0
    stopped_early: bool = False  # ended by ``patience`` before ``epochs``


def device_label(device: torch.device) -> str:
    """What trained an epoch, for the history: 'cpu' or 'cuda (<GPU name>)'."""
    if device.type == "cuda":
        return f"cuda ({torch.cuda.get_device_name(device)})"
    return device.type


def _epoch_order(n: int, seed: int, epoch: int) -> torch.Tensor:
    gen = torch.Generator().manual_seed(seed * 100_003 + epoch)
    return torch.randperm(n, generator=gen)


@torch.no_grad()
def evaluate_loss(model, data: SequenceData, batch_size: int, device: torch.device) -> float:
    """Mean loss over ``data`` in eval mode (dropout off), weighted by batch frames."""
    def loss(inputs, targets, mask):
        mean, sigma = model(inputs)
        w = int(mask.sum()) if mask is not None else targets.shape[0] * targets.shape[1]
        return float(model.loss(mean, sigma, targets, mask)) * w, w

    return _batch_mean(model, data, batch_size, device, loss)


@torch.no_grad()
def evaluate_l1(model, data: SequenceData, batch_size: int, device: torch.device) -> float:
    """Mean |mean - target| over the valid values of ``data`` in eval mode (dropout off):
    Monoloco's epoch selection (validation L1 of mu)."""
    def l1(inputs, targets, mask):
        err = (model(inputs)[0] - targets).abs()  # (B, T, out)
        if mask is not None:
            err = err[mask]
        return float(err.sum()), err.numel()

    return _batch_mean(model, data, batch_size, device, l1)


def _batch_mean(model, data: SequenceData, batch_size: int, device: torch.device, score) -> float:
    """sum(score) / sum(weight) over the batches of ``data`` in eval mode; score(inputs, targets,
    mask) -> (sum, weight) of one batch."""
    model.eval()
    total, weight = 0.0, 0
    for start in range(0, len(data), batch_size):
        idx = torch.arange(start, min(start + batch_size, len(data)))
        part, w = score(*data.batch(idx, device))
        total += part
        weight += w
    return total / max(weight, 1)


def patience_exhausted(epoch: int, best_epoch: int, patience: int) -> bool:
    """True when ``patience`` (> 0) epochs have passed since the best validation loss."""
    return patience > 0 and epoch - best_epoch >= patience


def run_finished(epoch: int, best_epoch: int, cfg: TrainConfig) -> bool:
    """Whether a run at ``epoch`` (best at ``best_epoch``) has nothing left to train."""
    return epoch >= cfg.epochs or patience_exhausted(epoch, best_epoch, cfg.patience)


def train_model(
    model_config: dict[str, Any],
    train: SequenceData,
    val: SequenceData,
    cfg: TrainConfig,
    checkpoint_stem: str | Path,
    *,
    data_key: str = "",
    device: torch.device | str = "cpu",
    progress: bool = True,
    stop_after_epochs: int | None = None,
    fresh_train: Callable[[int], SequenceData] | None = None,
    recipe: dict[str, Any] | None = None,
) -> TrainResult:
    """Train ``build_model(model_config)``; checkpoints at ``<stem>-last.pt`` / ``<stem>-best.pt``.

    If ``<stem>-last.pt`` exists and was made by the same configuration (its fingerprint
    matches), training resumes from it; a finished run returns at once. ``stop_after_epochs``
    ends the call early (as an interruption would), used by tests and by time-boxed runs.
    ``fresh_train(epoch)``, if given, returns the training data of that epoch (the same clean
    sequences under new noise, drawn from a seed that depends on ``epoch`` alone, so a resumed run
    sees what an uninterrupted one saw); ``train`` is then used only for its size. Whatever makes
    it differ between runs belongs in ``data_key``. ``recipe`` (plain values: the training noise, the
    corruptions such as pure-noise blackouts, fresh noise, the protocol or variant) is stored in both
    checkpoints' ``meta`` / state as ``recipe``, so a reader can tell from the file what the model saw.

    One writer per checkpoint: the call holds an OS lock on ``<stem>``; a second process gets a
    ``LockedError`` naming the holder (after LOCK_WAIT_S) and writes nothing. ``-last.pt`` also
    keeps the best epoch's weights, so a lost or corrupt ``-best.pt`` is restored from it.
    An unfinished CPU run resumes only with the torch thread count it was trained with
    (``ResumeMismatchError`` otherwise): float sums split over threads round differently.
    """
    stem = Path(checkpoint_stem)
    with exclusive_lock(stem.parent / f".{stem.name}.lock", f"checkpoint {stem}", wait_s=LOCK_WAIT_S):
        return _train_locked(model_config, train, val, cfg, stem, data_key=data_key, device=device,
                             progress=progress, stop_after_epochs=stop_after_epochs, fresh_train=fresh_train,
                             recipe=recipe)


def finished_run(model_config: dict[str, Any], cfg: TrainConfig, checkpoint_stem: str | Path, *,
                 data_key: str = "") -> TrainResult | None:
    """The result of a run whose ``-last.pt`` says it is finished under this configuration, read from
    its files alone (no data, no lock: both files are written atomically); None if it must (re)train
    -- missing, unfinished, another fingerprint, or a best checkpoint that needs restoring -- which
    ``train_model`` then does or explains."""
    stem = Path(checkpoint_stem)
    last_path, best_path = Path(f"{stem}-last.pt"), Path(f"{stem}-best.pt")
    if not (last_path.exists() and best_path.exists()):
        return None
    try:
        state = torch_load_checked(last_path)
    except CorruptArtefactError:
        return None
    if state.get("fingerprint") != fingerprint(model_config, cfg, data_key) \
            or not run_finished(state["epoch"], state["best_epoch"], cfg):
        return None
    result = TrainResult(best_path=best_path, last_path=last_path, history=state["history"],
                         best_epoch=state["best_epoch"], best_val_loss=state["best_val_loss"],
                         resumed_from=state["epoch"])
    result.stopped_early = state["epoch"] < cfg.epochs
    return result


def train_or_load(model_config: dict[str, Any], cfg: TrainConfig, checkpoint_stem: str | Path,
                  data: Callable[[], tuple[SequenceData, SequenceData, Callable[[int], SequenceData] | None]], *,
                  data_key: str = "", device: torch.device | str = "cpu", progress: bool = True,
                  recipe: dict[str, Any] | None = None) -> TrainResult:
    """The run of every experiment (a study's, the ablation's, the regime map's): a finished run read from its
    files alone (``finished_run``), else ``train_model`` (which resumes) on ``data()`` = (train, val, fresh_train),
    called only then, so that a finished run generates no data."""
    result = finished_run(model_config, cfg, checkpoint_stem, data_key=data_key)
    if result is not None:
        return result
    train, val, fresh = data()
    return train_model(model_config, train, val, cfg, checkpoint_stem, data_key=data_key, device=device,
                       progress=progress, fresh_train=fresh, recipe=recipe)


def _restore_best(best_path: Path, last_path: Path, best: dict[str, Any] | None) -> None:
    """Make sure ``best_path`` holds a readable checkpoint, rewriting it from ``-last.pt``'s copy."""
    if best_path.exists():
        try:
            torch_load_checked(best_path)
            return
        except CorruptArtefactError:
            pass
    if best is None:
        raise CorruptArtefactError(
            f"{best_path} is missing or corrupt and {last_path} was written before the best weights were kept "
            f"in it, so they cannot be restored: delete {last_path} too to retrain the run")
    atomic_torch_save(best_path, best)


def _train_locked(model_config, train, val, cfg: TrainConfig, stem: Path, *, data_key, device, progress,
                  stop_after_epochs, fresh_train=None, recipe=None) -> TrainResult:
    from drfkit.models import build_model

    device = torch.device(device)
    last_path, best_path = Path(f"{stem}-last.pt"), Path(f"{stem}-best.pt")
    fp = fingerprint(model_config, cfg, data_key)
    for stale in stem.parent.glob(f".{stem.name}-*.tmp"):  # left by a killed run; the lock says none is live
        stale.unlink(missing_ok=True)
    if cfg.framewise:
        train, val = train.frames(), val.frames()

    torch.manual_seed(cfg.seed)
    model = build_model(model_config).to(device)
    optimiser, scheduler = make_optimiser(model, cfg)
    result = TrainResult(best_path=best_path, last_path=last_path)
    start_epoch, best = 0, None

    if last_path.exists():
        state = torch_load_checked(last_path)
        if state.get("fingerprint") != fp:
            raise CorruptArtefactError(
                f"checkpoint {last_path} was written by a different configuration "
                f"(fingerprint {state.get('fingerprint')} != {fp}); delete it to retrain")
        model.load_state_dict(state["model"])
        optimiser.load_state_dict(state["optimiser"])
        scheduler.load_state_dict(state["scheduler"])
        torch.set_rng_state(state["rng_torch"])
        if device.type == "cuda" and state.get("rng_cuda") is not None:
            torch.cuda.set_rng_state(state["rng_cuda"], device)  # dropout masks on the GPU
        start_epoch = state["epoch"]
        result.history = state["history"]
        result.best_epoch, result.best_val_loss = state["best_epoch"], state["best_val_loss"]
        result.resumed_from = start_epoch
        best = state.get("best")
        _restore_best(best_path, last_path, best)
        if run_finished(start_epoch, result.best_epoch, cfg):
            result.stopped_early = start_epoch < cfg.epochs
            return result  # finished: a cache hit
        threads = state.get("threads")
        if device.type == "cpu" and state.get("device_type", "cpu") == "cpu" and threads is not None \
                and threads != torch.get_num_threads():
            raise ResumeMismatchError(
                f"{last_path} was trained with {threads} torch thread(s) and would resume with "
                f"{torch.get_num_threads()}; the thread count changes the numbers, so resume with {threads} "
                f"(python -m drfkit train ... --threads {threads}, or threads: {threads} in the profile), "
                f"or delete {last_path} to retrain from scratch")

    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=cfg.epochs, initial=start_epoch, desc=stem.name, mininterval=2.0,
                   file=sys.stderr, leave=False)
    end_epoch = cfg.epochs if stop_after_epochs is None else min(cfg.epochs, start_epoch + stop_after_epochs)
    trained_on = device_label(device)
    for epoch in range(start_epoch, end_epoch):
        t0 = time.perf_counter()
        model.train()
        data = train
        if fresh_train is not None:
            data = fresh_train(epoch)
            data = data.frames() if cfg.framewise else data
            if len(data) != len(train):
                raise ValueError(f"fresh_train({epoch}) gave {len(data)} training items, the run has {len(train)}")
        order = _epoch_order(len(data), cfg.seed, epoch)
        windows = torch.Generator().manual_seed(cfg.seed * 100_003 + epoch + 50_000_017)
        objective = "mse" if epoch < cfg.mse_warmup else cfg.objective
        total, count = 0.0, 0
        for step, start in enumerate(range(0, len(data), cfg.batch_size)):
            idx = order[start:start + cfg.batch_size]
            inputs, targets, mask = data.batch(idx, device)
            if cfg.window is not None:
                inputs, targets, mask = random_windows(inputs, targets, mask, cfg.window, windows)
            gain = None if cfg.skip_spans is None else skip_spans(
                targets.shape[0], targets.shape[1], cfg.skip_spans, cfg.skip_fraction, windows).to(device)
            loss = batch_loss(model, objective, cfg.beta, inputs, targets, mask, cfg.prior_weight, cfg.obs_weight, gain)
            if not torch.isfinite(loss):
                raise NonFiniteLossError(
                    f"non-finite loss {loss.item()} at epoch {epoch + 1}, step {step} (sequences "
                    f"{idx[:8].tolist()}...); the last good checkpoint {last_path} is kept")
            optimiser.zero_grad(set_to_none=True)
            loss.backward()
            grad_norm = torch.nn.utils.clip_grad_norm_(  # an infinite bound only measures the norm
                model.parameters(), math.inf if cfg.grad_clip is None else cfg.grad_clip)
            if not torch.isfinite(grad_norm):
                raise NonFiniteLossError(
                    f"non-finite gradient at epoch {epoch + 1}, step {step} (sequences "
                    f"{idx[:8].tolist()}...); the last good checkpoint {last_path} is kept")
            optimiser.step()
            total += loss.item() * len(idx)
            count += len(idx)
        scheduler.step()
        train_loss = total / count
        val_loss = evaluate_loss(model, val, max(cfg.batch_size, 256), device)
        row = {"epoch": epoch + 1, "train_loss": train_loss, "val_loss": val_loss}
        if cfg.select_on == "l1":
            row["val_l1"] = evaluate_l1(model, val, max(cfg.batch_size, 256), device)
        row |= {"lr": optimiser.param_groups[0]["lr"], "seconds": time.perf_counter() - t0, "device": trained_on}
        result.history.append(row)
        score = row["val_l1"] if cfg.select_on == "l1" else val_loss  # best_val_loss holds this score
        if score < result.best_val_loss:
            result.best_val_loss, result.best_epoch = score, epoch + 1
            best = {"format": CHECKPOINT_FORMAT, "config": model_config,
                    "state_dict": {k: v.detach().clone() for k, v in model.state_dict().items()},
                    "meta": {"epoch": epoch + 1, "val_loss": val_loss, "seed": cfg.seed, "fingerprint": fp,
                             "train": vars(cfg), "data": data_key, "recipe": dict(recipe or {})}}
            atomic_torch_save(best_path, best)
        atomic_torch_save(last_path, {
            "format": CHECKPOINT_FORMAT, "fingerprint": fp, "epoch": epoch + 1,
            "model": model.state_dict(), "optimiser": optimiser.state_dict(),
            "scheduler": scheduler.state_dict(), "rng_torch": torch.get_rng_state(),
            "rng_cuda": torch.cuda.get_rng_state(device) if device.type == "cuda" else None,
            "history": result.history, "best_epoch": result.best_epoch,
            "best_val_loss": result.best_val_loss, "best": best,
            "threads": torch.get_num_threads(), "device_type": device.type, "recipe": dict(recipe or {})})
        if bar is not None:
            bar.update(1)
            bar.set_postfix(train=f"{train_loss:.3f}", val=f"{val_loss:.3f}", refresh=False)
        if patience_exhausted(epoch + 1, result.best_epoch, cfg.patience):
            result.stopped_early = epoch + 1 < cfg.epochs
            break
    if bar is not None:
        bar.close()
    return result


def load_checkpoint(path: str | Path, device: torch.device | str = "cpu"):
    """Rebuild the model of a ``*-best.pt`` checkpoint, in eval mode.

    A truncated or corrupt file raises ``CorruptArtefactError`` naming the file.
    """
    from drfkit.models import build_model

    state = torch_load_checked(path)
    if not isinstance(state, dict) or "config" not in state or "state_dict" not in state:
        raise CorruptArtefactError(
            f"{path} is not a drfkit model checkpoint (expected keys 'config' and 'state_dict'; "
            "a '-last.pt' file is a resume state: load the '-best.pt' one)")
    model = build_model(state["config"])
    model.load_state_dict(state["state_dict"])
    model.checkpoint_meta = state.get("meta", {})
    return model.to(device).eval()


def load_latest(checkpoint_stem: str | Path, device: torch.device | str = "cpu"):
    """The model of a run's LAST epoch (``<stem>-last.pt`` weights, the configuration of
    ``<stem>-best.pt``), in eval mode, with ``checkpoint_meta['epoch']`` set; to compare
    the selected checkpoint with where training ended."""
    best = load_checkpoint(f"{checkpoint_stem}-best.pt", device)
    state = torch_load_checked(f"{checkpoint_stem}-last.pt")
    best.load_state_dict(state["model"])
    best.checkpoint_meta = {"epoch": state["epoch"], "val_loss": state["history"][-1]["val_loss"]}
    return best.eval()


def selection_audit(curves, patience: int):
    """Per (model, seed) of a training-curves frame (``history_frame`` rows with ``model`` and
    ``seed`` columns): epochs trained, the best epoch and validation score (the loss, or the L1
    of runs selected on it), the final one, and the longest wait between two successive improvements. If that wait is shorter than
    ``patience`` in every run, the early stop never ended a run that would still improve within
    what was observed.
    """
    import pandas as pd

    rows = []
    for (kind, seed), run in curves.groupby(["model", "seed"], sort=False):
        metric = "val_l1" if "val_l1" in run and run["val_l1"].notna().all() else "val_loss"  # what selected
        val = run.sort_values("epoch")[metric].to_numpy()
        best, last_improvement, longest_wait = math.inf, 0, 0
        for epoch, v in enumerate(val, 1):
            if v < best:
                longest_wait, best, last_improvement = max(longest_wait, epoch - last_improvement), v, epoch
        devices = run["device"] if "device" in run else pd.Series("cpu", index=run.index)
        per_device = [(d, len(g), g.median()) for d, g in run["seconds"].groupby(devices, sort=True)]
        rows.append({"model": kind, "seed": seed, "epochs": len(val), "best_epoch": last_improvement,
                     "best_val_loss": best, "final_val_loss": float(val[-1]), "longest_wait": longest_wait,
                     "selected_on": metric, "patience": patience, "epoch_s_by_device": "; ".join(
                         f"{device}: {n} epochs, median {sec:.3g} s" for device, n, sec in per_device)})
    return pd.DataFrame(rows)


def history_frame(history: list[dict[str, float]]):
    import pandas as pd

    l1 = ["val_l1"] if any("val_l1" in h for h in history) else []  # runs selected on validation L1
    frame = pd.DataFrame(history, columns=["epoch", "train_loss", "val_loss", *l1, "lr", "seconds", "device"])
    # epochs recorded before the 'device' field existed were all trained on CPU in this book
    return frame.fillna({"device": "cpu"})


def count_parameters(model) -> int:
    return int(sum(p.numel() for p in model.parameters()))


__all__ = ["SequenceData", "TrainConfig", "TrainResult", "NonFiniteLossError", "ResumeMismatchError", "train_model", "train_or_load", "run_finished", "naming_fields",
           "load_checkpoint", "load_latest", "selection_audit", "evaluate_loss", "evaluate_l1", "history_frame", "count_parameters"]
