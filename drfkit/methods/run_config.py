"""What names and fingerprints a training run: ``TrainConfig`` and the rules that turn it into a checkpoint's
name (``naming_fields``) and a resume's fingerprint (``fingerprint``). Apart from the loop
(``drfkit.methods.train``) so that a study's registry entry can build configurations without importing it."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from drfkit.util.io import param_hash

# what an epoch may optimise (``drfkit.methods.objectives.objective_loss``): the model's own loss, the
# Gaussian NLL, beta-NLL or the MSE of the mean
OBJECTIVES = ("model", "nll", "beta_nll", "mse")


@dataclass
class TrainConfig:
    epochs: int
    lr: float
    batch_size: int
    seed: int
    grad_clip: float | None = 10.0  # max gradient norm; None = no clipping (Monoloco as published)
    lr_step: int | None = None  # StepLR step (epochs); None = constant lr
    lr_gamma: float = 1.0
    framewise: bool = False  # train on single frames (Monoloco)
    patience: int = 0  # stop after this many epochs without a better validation loss; 0 = never
    select_on: str = "loss"  # the epoch kept as -best.pt: lowest validation loss, or "l1" of the mean
    objective: str = "model"  # drfkit.methods.objectives: model (the model's own loss), nll, beta_nll, mse
    beta: float = 1.0  # of beta_nll: 0 = the NLL, 1 = the mean fitted like MSE
    mse_warmup: int = 0  # epochs of MSE on the mean before the objective (a staged fit)
    lr_schedule: str = "step"  # step (StepLR by lr_step / lr_gamma; constant without lr_step) or cosine (to 0 at epochs)
    weight_decay: float = 0.0  # decoupled (AdamW) when > 0
    window: int | None = None  # train on one random window of this many frames per sequence and epoch
    prior_weight: float = 0.0  # weight of the loss on a filter's one-step prior (drfkit.methods.objectives.batch_loss)
    obs_weight: float = 0.0  # weight of the loss on the observation alone, (w_t, r_t) (drfkit.methods.objectives.batch_loss)
    # a filter's updates skipped (gain 0) on one random span of [lo, hi] frames in a skip_fraction of the training
    # windows, the loss on every frame: the open-loop prediction is fitted (drfkit.methods.objectives.skip_spans)
    skip_spans: list | None = None
    skip_fraction: float = 0.5

    def __post_init__(self) -> None:
        for name in ("epochs", "batch_size"):
            if not isinstance(getattr(self, name), int) or getattr(self, name) < 1:
                raise ValueError(f"TrainConfig.{name} must be an integer >= 1, got {getattr(self, name)!r}")
        if not isinstance(self.patience, int) or isinstance(self.patience, bool) or self.patience < 0:
            raise ValueError(f"TrainConfig.patience must be an integer >= 0 (0 = no early stop), got {self.patience!r}")
        if not (0 < self.lr < 1):
            raise ValueError(f"TrainConfig.lr must be in (0, 1), got {self.lr!r}")
        if self.select_on not in SELECTION_METRICS:
            raise ValueError(f"TrainConfig.select_on must be one of {SELECTION_METRICS}, got {self.select_on!r}")
        if self.grad_clip is not None and not self.grad_clip > 0:
            raise ValueError(f"TrainConfig.grad_clip must be > 0 or None (no clipping), got {self.grad_clip!r}")
        if self.objective not in OBJECTIVES:
            raise ValueError(f"TrainConfig.objective must be one of {OBJECTIVES}, got {self.objective!r}")
        if not 0.0 <= float(self.beta) <= 1.0:
            raise ValueError(f"TrainConfig.beta must lie in [0, 1] (0 = NLL, 1 = mean fitted like MSE), got {self.beta!r}")
        if not isinstance(self.mse_warmup, int) or isinstance(self.mse_warmup, bool) or self.mse_warmup < 0:
            raise ValueError(f"TrainConfig.mse_warmup must be an integer >= 0 (epochs), got {self.mse_warmup!r}")
        if self.lr_schedule not in LR_SCHEDULES:
            raise ValueError(f"TrainConfig.lr_schedule must be one of {LR_SCHEDULES}, got {self.lr_schedule!r}")
        if not self.weight_decay >= 0:
            raise ValueError(f"TrainConfig.weight_decay must be >= 0, got {self.weight_decay!r}")
        if self.window is not None and (isinstance(self.window, bool) or not isinstance(self.window, int)
                                        or self.window < 2):
            raise ValueError(f"TrainConfig.window must be None (whole sequences) or an integer >= 2, got {self.window!r}")
        if not (isinstance(self.prior_weight, (int, float)) and self.prior_weight >= 0):
            raise ValueError(f"TrainConfig.prior_weight must be a number >= 0 (0 = no prior loss), got {self.prior_weight!r}")
        if not (isinstance(self.obs_weight, (int, float)) and self.obs_weight >= 0):
            raise ValueError(f"TrainConfig.obs_weight must be a number >= 0 (0 = no observation loss), got {self.obs_weight!r}")
        if self.skip_spans is not None:
            spans = self.skip_spans
            if not (isinstance(spans, (list, tuple)) and len(spans) == 2 and all(
                    isinstance(v, int) and not isinstance(v, bool) for v in spans) and 1 <= spans[0] <= spans[1]):
                raise ValueError(f"TrainConfig.skip_spans must be None or [lo, hi], whole numbers 1 <= lo <= hi (the "
                                 f"lengths of a skipped span), got {spans!r}")
            self.skip_spans = [int(spans[0]), int(spans[1])]
        if not (isinstance(self.skip_fraction, (int, float)) and 0 < self.skip_fraction <= 1):
            raise ValueError(f"TrainConfig.skip_fraction must lie in (0, 1], got {self.skip_fraction!r}")


SELECTION_METRICS = ("loss", "l1")
LR_SCHEDULES = ("step", "cosine")
# Fields added after checkpoints were committed: at these values they stay out of names and
# fingerprints, so every run made before them keeps its files (and resumes).
LATER_FIELDS = {"select_on": "loss", "objective": "model", "beta": 1.0, "mse_warmup": 0, "lr_schedule": "step",
                "weight_decay": 0.0, "window": None, "prior_weight": 0.0,
                "obs_weight": 0.0, "skip_spans": None, "skip_fraction": 0.5}


def train_fields(cfg: "TrainConfig") -> dict[str, Any]:
    return {k: v for k, v in vars(cfg).items() if not (k in LATER_FIELDS and v == LATER_FIELDS[k])}


# When to stop, not what an epoch computes: epoch e is the same whatever these say, so they
# are left out of the fingerprint (and a finished or early-stopped run can be extended).
STOPPING_FIELDS = ("epochs", "patience")


def fingerprint(config: dict[str, Any], train_cfg: TrainConfig, data_key: str) -> str:
    """What a resume must agree on: everything but ``STOPPING_FIELDS`` (a cosine schedule's
    ``epochs`` stays: it sets every epoch's learning rate)."""
    keep = ("epochs",) if train_cfg.lr_schedule == "cosine" else ()
    train = {k: v for k, v in train_fields(train_cfg).items() if k not in STOPPING_FIELDS or k in keep}
    return param_hash({"model": config, "train": train, "data": data_key})


def naming_fields(train_cfg: TrainConfig) -> dict[str, Any]:
    """The training fields that name a run's checkpoint files: all but ``patience``, which
    only decides when the run stops (``epochs`` stays, as in names made before patience)."""
    return {k: v for k, v in train_fields(train_cfg).items() if k != "patience"}


def run_key(model_config: dict[str, Any], train_cfg: TrainConfig, data: dict[str, Any]) -> str:
    """The one name of a training run (8 hex digits): its model's full configuration, the training fields that
    name it (``naming_fields``) and what names its data (a study's ``data_key``). A profile's checkpoints
    (``drfkit.study.studies.checkpoint_stem``), the ablation's and the regime map's rows all carry it, so two
    recipes that train the same run share one name."""
    return param_hash({"model": model_config, "train": naming_fields(train_cfg), "data": data}, 8)


__all__ = ["LATER_FIELDS", "LR_SCHEDULES", "OBJECTIVES", "SELECTION_METRICS", "STOPPING_FIELDS", "TrainConfig",
           "fingerprint", "naming_fields", "run_key", "train_fields"]
