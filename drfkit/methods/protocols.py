"""Training protocols of the pendulum study, and every variant the protocol ablation tried.

A *variant* is a model kind, its options (``drfkit.models``) and a training-time corruption;
``drfkit.study.ablation`` trains each on a small budget and judges it on validation data. A
*protocol* names one variant per model kind, so the three models of a comparison are trained
the same way; each kind's class names its variants (``drfkit.models.spec.ModelSpec.protocols``),
``PROTOCOLS`` gathers them:

* ``paper`` -- the paper as written: LSTM transition network, ELU + 1 observation variance,
  every latent dim observed, training frames as the benchmark makes them.
* ``book``  -- the book's protocol, chosen on validation data by the ablation's third round (notebook 02):
  trained WITHOUT pure-noise frames (max noise 0.5 only, so 0.75, 1.0 and the blackout stay out of
  distribution), with the recipe that fits the mean (``FIT_THE_MEAN``) and the encoder probe's wider
  encoder (``WIDE_ENCODER``: capacity, not data, kept every encoder from the per-frame limit). Its DRF is
  the third round's choice by the mechanism rule; beside it the same recipe and data train the LSTM,
  no_dynamics and the known-dynamics filter (``drfkit.models.known_dynamics``), the model-based
  reference that splits the distance to the limit into what the encoder and what a learned transition
  lose. (The second round's choice, with training blackouts, was the book's protocol before.)

Every variant stays listed, whether it helped or not: the ablation table shows them all. The variants and
the parts they are made of (recipes, model options, corruptions) are data, in ``params/protocols.yaml``: the one
place a researcher edits or adds a recipe; ``load_variants`` reads and checks it.
"""
from __future__ import annotations

from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from drfkit.models.kinds import MODEL_CLASSES, model_spec
from drfkit.util.paths import PARAMS_DIR

if TYPE_CHECKING:
    import pandas as pd

# the variants and their parts: params/protocols.yaml (the one place a recipe is edited), read and checked here
VARIANT_FIELDS = ("kind", "model", "train", "blackouts", "train_max_noise")
# what a recipe may set: TrainConfig's fields the profile does not own, and the data's business
RECIPE_FIELDS = ("objective", "beta", "lr_schedule", "window", "batch_size", "select_on", "prior_weight", "obs_weight",
                 "skip_spans", "skip_fraction", "mse_warmup", "weight_decay", "grad_clip", "lr_step", "lr_gamma", "fresh_noise", "fresh_motion")


def _resolve(value: Any, parts: dict[str, Any], where: str) -> dict[str, Any]:
    """A part's name, a mapping, or a list of them merged left to right -> one mapping."""
    if isinstance(value, str):
        if value not in parts:
            raise ValueError(f"{where}: unknown part {value!r}; params/protocols.yaml defines {sorted(parts)}")
        return dict(parts[value])
    if isinstance(value, dict):
        return dict(value)
    if isinstance(value, list):
        out: dict[str, Any] = {}
        for item in value:
            out |= _resolve(item, parts, where)
        return out
    raise ValueError(f"{where}: expected a part's name, a mapping or a list of them, got {value!r}")


def load_variants(path: str | Path | None = None) -> tuple[dict[str, dict[str, Any]], dict[int, dict[str, dict[str, Any]]],
                                                           dict[str, Any]]:
    """(variants, rounds, parts) from params/protocols.yaml: each variant resolved (its parts merged), checked."""
    import yaml

    path = Path(path) if path is not None else PARAMS_DIR / "protocols.yaml"
    try:
        data = yaml.safe_load(path.read_text())
    except OSError as exc:
        raise FileNotFoundError(f"the training recipes live in {path}; it is missing ({exc}): restore it from git") from exc
    parts, rounds_in = data.get("parts") or {}, data.get("rounds") or {}
    variants: dict[str, dict[str, Any]] = {}
    rounds: dict[int, dict[str, dict[str, Any]]] = {}
    for number, entries in rounds_in.items():
        rounds[int(number)] = {}
        for name, entry in (entries or {}).items():
            where = f"{path.name}: variant {name!r}"
            if name in variants:
                raise ValueError(f"{where} is defined twice")
            unknown = set(entry) - set(VARIANT_FIELDS)
            if unknown or "kind" not in entry:
                raise ValueError(f"{where}: fields {sorted(unknown)} unknown or 'kind' missing; allowed {VARIANT_FIELDS}")
            spec: dict[str, Any] = {"kind": entry["kind"]}
            for field in ("model", "train", "blackouts"):
                if field in entry:
                    spec[field] = _resolve(entry[field], parts, where)
            bad = set(spec.get("train", {})) - set(RECIPE_FIELDS)
            if bad:
                raise ValueError(f"{where}: recipe fields {sorted(bad)} unknown; a recipe sets {RECIPE_FIELDS}")
            if "blackouts" in spec:
                if set(spec["blackouts"]) != {"fraction", "lengths"}:
                    raise ValueError(f"{where}: blackouts need 'fraction' and 'lengths', got {spec['blackouts']}")
                spec["blackouts"]["lengths"] = tuple(spec["blackouts"]["lengths"])
            if "train_max_noise" in entry:
                level = float(entry["train_max_noise"])
                if not 0.0 <= level <= 1.0:
                    raise ValueError(f"{where}: train_max_noise must lie in [0, 1], got {level}")
                spec["train_max_noise"] = level
            variants[name] = rounds[int(number)][name] = spec
    return variants, rounds, parts


VARIANTS, _ROUNDS, _PARTS = load_variants()
BLACKOUT_TRAINING = _resolve("training_blackouts", _PARTS, "params/protocols.yaml") | {
    "lengths": tuple(_PARTS["training_blackouts"]["lengths"])}
BOOK_DRF = _resolve("book_drf", _PARTS, "params/protocols.yaml")
FIT_THE_MEAN = _resolve("fit_the_mean", _PARTS, "params/protocols.yaml")
WIDE_ENCODER = _resolve("wide", _PARTS, "params/protocols.yaml")
ROUND2_VARIANTS, ROUND3_VARIANTS, ROUND4_VARIANTS, ROUND5_VARIANTS = (_ROUNDS.get(n, {}) for n in (2, 3, 4, 5))

# The ablation's budgets (``drfkit.study.ablation``); data from the profiles' pend_data_seed.
ABLATION_BUDGETS: dict[str, dict[str, Any]] = {
    # 480 Adam steps: 5-12 minutes per run on one CPU thread (two runs side by side on 2 cores)
    "small": dict(train_sequences=300, val_sequences=100, seq_len=75, epochs=40, lr=1e-3, batch_size=25),
    # ten times the steps, the full training set: the confirmation of a winner
    "medium": dict(train_sequences=2000, val_sequences=200, seq_len=75, epochs=60, lr=3e-4, batch_size=50),
    "tiny": dict(train_sequences=6, val_sequences=4, seq_len=48, epochs=1, lr=1e-3, batch_size=3),  # tests
    # the second round (the fit_* variants): the small budget's data, more epochs of shorter windows
    "fit": dict(train_sequences=300, val_sequences=100, seq_len=75, epochs=80, lr=1e-3, batch_size=25),
    "fit_tiny": dict(train_sequences=6, val_sequences=4, seq_len=48, epochs=2, lr=1e-3, batch_size=3),  # tests
}

class _Protocols(Mapping):
    """protocol -> {kind: variant}: what each protocol trains for each registered model kind, read from
    the kinds' specs (``ModelSpec.protocols``) when asked, in registration order, so a model registered
    in one file is trained under the protocols its spec names.

    ``paper`` is the paper as written (``paper``, ``no_dynamics_paper``, ``lstm_paper``). ``book`` is the
    third round's choice: of the DRF variants trained without pure-noise frames, the one that meets the
    most of the mechanism and blackout targets on validation (r follows the noise, gain on pure noise
    <= 0.25 of clean, F z predicts the next observation better than z, blackout MAE <= 0.10), with the
    wider encoder; every model on the same data and encoder (docs/dynamics.md). The second round chose
    "fit_prior_split_book" (trained with blackouts), the first "book"."""

    def _table(self) -> dict[str, dict[str, str]]:
        table: dict[str, dict[str, str]] = {}
        for kind in MODEL_CLASSES:
            for protocol, variant in model_spec(kind).protocols.items():
                table.setdefault(protocol, {})[kind] = variant
        return table

    def __getitem__(self, protocol: str) -> dict[str, str]:
        return self._table()[protocol]

    def __iter__(self) -> Iterator[str]:
        return iter(self._table())

    def __len__(self) -> int:
        return len(self._table())


PROTOCOLS: Mapping[str, dict[str, str]] = _Protocols()


# The pedestrian study's protocols: what each adds to the DRF family's schedule (the profile's
# ``ped_epochs``, ``ped_lr``, ``ped_batch_size``). ``book`` takes the objective and schedule of the recipe
# that fits the mean (beta-NLL, cosine decay, the checkpoint selected on the validation MAE); the
# pendulum's frame-level parts of it (fresh pixel noise, 25-frame windows) have no counterpart in
# 10-frame keypoint sequences. Monoloco keeps its published loss and schedule under every protocol, so
# its runs are shared.
PEDESTRIAN_PROTOCOLS: dict[str, dict[str, Any]] = {
    "paper": {},
    "book": {k: FIT_THE_MEAN[k] for k in ("objective", "beta", "lr_schedule", "select_on")},
}


# The noise-regime map (``drfkit.study.regime``): the book protocol's model of each kind (the same variants,
# ``PROTOCOLS["book"]``), trained at other max noise levels than the paper's 0.5. ``regime_variant`` names them.
REGIME_BASES = {"drf": "fit_paper_wide", "drf_calibrated": "fit_calibrated_prior_wide",
                "no_dynamics": "fit_no_dynamics_wide", "lstm": "fit_lstm_wide",
                "known_dynamics": "fit_known_dynamics_wide"}
REGIME_TRAIN_NOISE = (0.75, 1.0)
# the first round's book protocol, whose regime rows (book_train0.75, ...) stay readable
_ROUND1_BOOK = {"drf": "book", "no_dynamics": "no_dynamics_book", "lstm": "lstm_book"}


def regime_variant(kind: str, train_noise: float) -> str:
    """The variant of the book's protocol for ``kind`` trained at max noise ``train_noise``
    (the protocol's own variant at 0.5, ``<variant>_train0.75`` at 0.75)."""
    if kind not in REGIME_BASES:
        raise ValueError(f"the regime map trains {sorted(REGIME_BASES)}, not {kind!r}")
    base = REGIME_BASES[kind]
    return base if train_noise == 0.5 else f"{base}_train{train_noise:g}"


for _base in (*REGIME_BASES.values(), *_ROUND1_BOOK.values()):
    for _level in REGIME_TRAIN_NOISE:
        VARIANTS[f"{_base}_train{_level:g}"] = VARIANTS[_base] | {"train_max_noise": _level}


def variant_spec(name: str) -> dict[str, Any]:
    """A variant with every field filled: kind, model (options), blackouts (None or a dict),
    train_max_noise, train (overrides of the budget's ``TrainConfig`` fields, plus
    ``fresh_noise``: redraw the training noise every epoch)."""
    if name not in VARIANTS:
        raise ValueError(f"unknown variant {name!r}; choose from {sorted(VARIANTS)}")
    return {"model": {}, "blackouts": None, "train_max_noise": 0.5, "train": {}} | VARIANTS[name]


def protocol_spec(protocol: str, kind: str) -> dict[str, Any]:
    """The variant that ``protocol`` trains for model ``kind``."""
    if protocol not in PROTOCOLS:
        raise ValueError(f"unknown protocol {protocol!r}; choose from {sorted(PROTOCOLS)}")
    if kind not in PROTOCOLS[protocol]:
        raise ValueError(f"protocol {protocol!r} has no {kind!r} model; it trains {sorted(PROTOCOLS[protocol])}")
    return variant_spec(PROTOCOLS[protocol][kind])


# the ablation's rows (``drfkit.study.ablation.ablation_table``) summarised: here, below the ablation, so that
# the report reads the summary without importing the ablation's training machinery
SUMMARY_COLUMNS = ("mae_0.5", "mae_0.75", "mae_1", "mae_blackout", "mae_after_blackout", "r_noise_spearman",
                   "gain_ratio_blackout", "prior_ratio", "spectral_radius_median", "best_epoch")


def summarise_ablation(table: pd.DataFrame) -> pd.DataFrame:
    """Mean over seeds per variant (and the number of seeds), sorted by the blackout MAE."""
    cols = [c for c in SUMMARY_COLUMNS if c in table]
    grouped = table.groupby(["variant", "kind"])
    summary = grouped[cols].mean().join(grouped.size().rename("n_seeds"))
    if "current" in table:  # a variant counts as current only if every seed's row is
        summary = summary.join(grouped["current"].all())
    return summary.sort_values("mae_blackout").round(4).reset_index()
