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

Every variant stays listed, whether it helped or not: the ablation table shows them all.
"""
from __future__ import annotations

from collections.abc import Iterator, Mapping
from typing import TYPE_CHECKING, Any

from drfkit.models.kinds import MODEL_CLASSES, model_spec

if TYPE_CHECKING:
    import pandas as pd

BLACKOUT_TRAINING = {"fraction": 0.5, "lengths": (5, 20)}
BOOK_DRF = {"transition_kind": "basis", "memory_dims": 15, "noise_head": "log"}

VARIANTS: dict[str, dict[str, Any]] = {
    "paper": {"kind": "drf"},
    "log_r": {"kind": "drf", "model": {"noise_head": "log"}},
    "basis": {"kind": "drf", "model": {"transition_kind": "basis"}},
    "memory": {"kind": "drf", "model": {"memory_dims": 15}},
    "blackout": {"kind": "drf", "blackouts": BLACKOUT_TRAINING},
    "basis_memory_log": {"kind": "drf", "model": BOOK_DRF},
    "lstm_memory_log_blackout": {"kind": "drf", "model": {"memory_dims": 15, "noise_head": "log"},
                                 "blackouts": BLACKOUT_TRAINING},
    "book": {"kind": "drf", "model": BOOK_DRF, "blackouts": BLACKOUT_TRAINING},
    "book_noise1": {"kind": "drf", "model": BOOK_DRF, "train_max_noise": 1.0},
    "no_dynamics_paper": {"kind": "no_dynamics"},
    "lstm_paper": {"kind": "lstm"},
    "no_dynamics_book": {"kind": "no_dynamics", "model": {"noise_head": "log"}, "blackouts": BLACKOUT_TRAINING},
    "lstm_book": {"kind": "lstm", "model": {"noise_head": "log"}, "blackouts": BLACKOUT_TRAINING},
}

# The ablation's second round: how the models are FIT (``drfkit.methods.objectives``, ``drfkit.methods.train``),
# not what they are. Under the paper's Gaussian NLL on one fixed noise draw the validation MAE of
# every model doubles while the training NLL falls (the mean is starved where sigma is small);
# ``FIT_THE_MEAN`` is the recipe that fits it: beta-NLL (beta = 1), noise redrawn on the clean frames
# every epoch, cosine decay of the learning rate, random 25-frame windows, the checkpoint selected on
# the validation MAE of the mean. The ``fit_*`` variants vary one lever of it at a time.
FIT_THE_MEAN = {"objective": "beta_nll", "beta": 1.0, "lr_schedule": "cosine", "fresh_noise": True,
                "window": 25, "batch_size": 16, "select_on": "l1"}
_FIT_NLL = FIT_THE_MEAN | {"objective": "nll"}
_FIT_STAGED = FIT_THE_MEAN | {"objective": "nll", "mse_warmup": "half"}  # MSE for half the epochs, then NLL
_FIT_PRIOR = FIT_THE_MEAN | {"prior_weight": 1.0}  # the one-step prior fitted with the same weight as the posterior
ROUND2_VARIANTS = {
    "fit_paper": {"kind": "drf", "train": FIT_THE_MEAN},
    "fit_paper_blackout": {"kind": "drf", "train": FIT_THE_MEAN, "blackouts": BLACKOUT_TRAINING},
    "fit_book": {"kind": "drf", "model": BOOK_DRF, "train": FIT_THE_MEAN, "blackouts": BLACKOUT_TRAINING},
    "fit_nll_paper_blackout": {"kind": "drf", "train": _FIT_NLL, "blackouts": BLACKOUT_TRAINING},
    "fit_staged_paper_blackout": {"kind": "drf", "train": _FIT_STAGED, "blackouts": BLACKOUT_TRAINING},
    "fit_paper_noise1": {"kind": "drf", "train": FIT_THE_MEAN, "train_max_noise": 1.0},
    "fit_lstm_blackout": {"kind": "lstm", "train": FIT_THE_MEAN, "blackouts": BLACKOUT_TRAINING},
    "fit_lstm_noise1": {"kind": "lstm", "train": FIT_THE_MEAN, "train_max_noise": 1.0},
    "fit_no_dynamics": {"kind": "no_dynamics", "train": FIT_THE_MEAN},
    "fit_no_dynamics_blackout": {"kind": "no_dynamics", "train": FIT_THE_MEAN, "blackouts": BLACKOUT_TRAINING},
    # a filter lever: the mean decoded from z alone, sigma from P alone (as the RKN's decoder)
    "fit_split_paper_blackout": {"kind": "drf", "model": {"decoder_split": True}, "train": FIT_THE_MEAN,
                                 "blackouts": BLACKOUT_TRAINING},
    "fit_split_book": {"kind": "drf", "model": BOOK_DRF | {"decoder_split": True}, "train": FIT_THE_MEAN,
                       "blackouts": BLACKOUT_TRAINING},
    # a filter lever: the one-step prior z_{t|t-1} decoded and fitted too (the transition must predict)
    "fit_prior_paper_blackout": {"kind": "drf", "train": _FIT_PRIOR, "blackouts": BLACKOUT_TRAINING},
    "fit_prior_split_book": {"kind": "drf", "model": BOOK_DRF | {"decoder_split": True}, "train": _FIT_PRIOR,
                             "blackouts": BLACKOUT_TRAINING},
    # a filter lever: Q learned but constant in time (the paper's LSTM transition emits q_t per step)
    "fit_constq_paper_blackout": {"kind": "drf", "model": {"constant_q": True}, "train": FIT_THE_MEAN,
                                  "blackouts": BLACKOUT_TRAINING},
}
VARIANTS.update(ROUND2_VARIANTS)

# The third round: competence. Trained without pure-noise frames (max noise 0.5 only), so 0.75, 1.0 and the
# blackout stay out of distribution. Levers that make r follow frame quality and let the gain follow r:
# an observation loss (w_t decoded alone, r_t its variance: ``TrainConfig.obs_weight``), a monotone link
# from one learned quality score to every r_i (``noise_head='quality'``), and a state whose units are
# physical (the known-dynamics filter, ``drfkit.models.known_dynamics``: r and q on the same scale).
_FIT_OBS = FIT_THE_MEAN | {"obs_weight": 1.0}
_FIT_PRIOR_OBS = _FIT_PRIOR | {"obs_weight": 1.0}
_SPLIT_BOOK = BOOK_DRF | {"decoder_split": True}
WIDE_ENCODER = {"encoder_channels": 32, "feature_dim": 128}  # the encoder probe's wider encoder
_WIDE = WIDE_ENCODER
_PHYSICAL_DRF = {"transition_kind": "basis", "latent": 17, "memory_dims": 15, "noise_head": "log", "readout": "identity"}
ROUND3_VARIANTS = {
    "fit_prior_split_book_clean": {"kind": "drf", "model": _SPLIT_BOOK, "train": _FIT_PRIOR},
    "fit_obs_prior_split_book": {"kind": "drf", "model": _SPLIT_BOOK, "train": _FIT_PRIOR_OBS},
    "fit_obs_quality_book": {"kind": "drf", "model": _SPLIT_BOOK | {"noise_head": "quality"}, "train": _FIT_PRIOR_OBS},
    # the DRF in the output's units: 2 observed latent dims ARE (cos, sin) (read as they are, no decoder), 15
    # memory dims, so r and q are variances of (cos, sin) and the observation loss pins r's scale
    "fit_physical_book": {"kind": "drf", "model": _PHYSICAL_DRF, "train": _FIT_PRIOR_OBS},
    "fit_known_dynamics": {"kind": "known_dynamics", "train": _FIT_OBS},
    "fit_known_dynamics_e2e": {"kind": "known_dynamics", "train": FIT_THE_MEAN},
    "fit_lstm": {"kind": "lstm", "train": FIT_THE_MEAN},
    # the encoder probe: is no_dynamics' distance to the per-frame Bayes estimate capacity or data? New
    # trajectories every epoch (unlimited frames), a wider encoder (32 channels, 128 features), both
    "fit_no_dynamics_fresh_motion": {"kind": "no_dynamics", "train": FIT_THE_MEAN | {"fresh_motion": True}},
    "fit_no_dynamics_wide": {"kind": "no_dynamics", "model": _WIDE, "train": FIT_THE_MEAN},
    "fit_no_dynamics_wide_fresh_motion": {"kind": "no_dynamics", "model": _WIDE, "train": FIT_THE_MEAN | {"fresh_motion": True}},
    # what the probe found (capacity, not data), carried into every model of the book's protocol
    "fit_known_dynamics_wide": {"kind": "known_dynamics", "model": _WIDE, "train": _FIT_OBS},
    "fit_lstm_wide": {"kind": "lstm", "model": _WIDE, "train": FIT_THE_MEAN},
    "fit_physical_book_wide": {"kind": "drf", "model": _PHYSICAL_DRF | _WIDE, "train": _FIT_PRIOR_OBS},
    "fit_obs_quality_book_wide": {"kind": "drf", "model": _SPLIT_BOOK | {"noise_head": "quality"} | _WIDE,
                                  "train": _FIT_PRIOR_OBS},
    # the paper's other lever, "driving the learned state transition network towards a known dynamics model":
    # the known-dynamics filter's state and encoder with a learned transition (x' = x + g(x), started as a
    # random walk; q learned, as a learned transition's error must go somewhere), free or pulled toward the
    # true pendulum (``KnownDynamicsFilter.regulariser``)
    "fit_known_dynamics_learned": {"kind": "known_dynamics", "model": {"transition": "learned", "learn_q": True},
                                   "train": _FIT_OBS},
    "fit_known_dynamics_pulled": {"kind": "known_dynamics",
                                  "model": {"transition": "learned", "learn_q": True, "pull": 100.0}, "train": _FIT_OBS},
}
VARIANTS.update(ROUND3_VARIANTS)

# The fourth round: the paper's model fit well, and a gain calibrated out of distribution (docs/dynamics.md, "Why
# the DRF does not filter, measured"). Trained, like the third, without pure-noise frames.
ROUND4_VARIANTS = {
    # the paper's DRF as written (30-dim LayerNorm latent, ELU + 1 r, LSTM transition, decoder on [z, P] with
    # MC dropout), fit with the recipe that fits the mean and the wider encoder, as its baselines are
    "fit_paper_wide": {"kind": "drf", "model": _WIDE, "train": FIT_THE_MEAN},
    # the DRF whose gain is calibrated out of distribution (``drfkit.models.drf.CalibratedGainDRF``): r from the frame's
    # noise statistic through a monotone log-linear link; alone, and with the one-step prior decoded and fitted
    # (a prior variance far above the prior's error costs likelihood there: q is held to what F achieves)
    "fit_calibrated_wide": {"kind": "drf_calibrated", "model": _WIDE, "train": FIT_THE_MEAN},
    "fit_calibrated_prior_wide": {"kind": "drf_calibrated", "model": _WIDE, "train": _FIT_PRIOR},
}
VARIANTS.update(ROUND4_VARIANTS)

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


# The noise-regime map (``drfkit.study.regime``): the book's protocol of each model kind, trained at
# other max noise levels than the paper's 0.5 (the book's own kinds: taken when this module is imported).
# ``regime_variant`` names them.
REGIME_BASES = dict(PROTOCOLS["book"])
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
