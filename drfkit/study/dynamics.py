"""The pendulum dynamics study on a profile's trained models: does the filter filter, and how
does every model compare with filters that know the true physics?

* ``mechanism_table``  -- ``drfkit.methods.diagnostics`` per (model, seed) on the test split at one
                          noise level and on the blackout test set
* ``blackout_curves``  -- MAE per frame through the blackout (the dropout-off estimate, as every
                          MAE the book reports)
* ``physics_reference`` -- the particle filter with the true physics fed no_dynamics' per-frame
                          estimates (``drfkit.methods.references``), its likelihood scale and outlier weight
                          chosen on the VALIDATION split at the training noise; and the per-frame
                          template-matching reference ("what the pixels hold")

Both references use knowledge no learned model has (the generator's equations, its renderer);
they are comparisons, not bounds: a model whose encoder is trained through its filter can do better
than the particle filter on no_dynamics' outputs.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd
import torch

from drfkit.methods import references
from drfkit.methods.references import like_for_like_mae, reference_on
from drfkit.study import studies
from drfkit.study.profile import narrowed
from drfkit.core.metrics import bootstrap_interval
from drfkit.data.noise import Noise
from drfkit.data.pendulum import BLACKOUT_SEED_OFFSET, blackout_frames, with_blackout
from drfkit.methods.diagnostics import (abs_error_per_frame, blackout_summary, filter_trace, mechanism_summary,
                                       recovery_summary)
from drfkit.util.paths import predictions_dir
from drfkit.methods.predictions import point_and_sigma
from drfkit.util.tasks import forget, map_tasks, memo
from drfkit.models.frame_codes import distinct_frames_once
from drfkit.models.portable import portable



def blackout_split(P, split: str) -> dict[str, np.ndarray]:
    """A pendulum split at the training noise with its ``blackout_frames`` pure noise."""
    arrays = studies.pendulum_split(P, split)
    seed = studies.split_seed(P, split) + BLACKOUT_SEED_OFFSET
    return with_blackout(arrays, *blackout_frames(arrays["images"].shape[1]), seed=seed)


def _point_and_sigma(P, model, arrays, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``predictions.point_and_sigma`` of ``model`` on arrays['images'] (any model input) with the profile's cache and
    samples."""
    return point_and_sigma(model, arrays["images"], cache=predictions_dir(P.profile), n_samples=P.uncertainty.n_samples,
                           seed=seed)


def mechanism_table(P, models: dict[tuple[str, int], Any], noise: Noise | float, split: str = "test") -> pd.DataFrame:
    """One row per (model, seed): diagnostics on ``split`` at max noise ``noise`` (a pendulum
    ``Noise`` or its level) and the gains on the blackout version of ``split``'s clean and
    pure-noise frames. One task per model (``drfkit.util.tasks.map_tasks``)."""
    noise = studies.study_noise(P, "pendulum", noise).level
    forget()
    _split(P, split, noise), _dark(P, split)  # read (made, the first time) here once: workers only read them
    rows = map_tasks(_mechanism_task, [(P, split, noise, kind, seed) for kind, seed in models], shared=portable(models),
                     desc=f"mechanism checks at max noise {noise:g}")
    return pd.DataFrame(rows)


def _split(P, split: str, noise: float) -> dict[str, np.ndarray]:
    return memo((P, "pendulum split", split, noise), lambda: studies.pendulum_split(P, split, noise))


def _dark(P, split: str) -> dict[str, np.ndarray]:
    return memo((P, "blackout split", split), lambda: blackout_split(P, split))


def _mechanism_task(P, split: str, noise: float, kind: str, seed: int, shared: dict) -> dict[str, Any]:
    model, test = shared[(kind, seed)].model, _split(P, split, noise)
    with distinct_frames_once(model):  # one block: the blackout set's frames outside its gap are the test set's
        row = {"model": kind, "seed": seed, "noise": float(noise),
               **mechanism_summary(filter_trace(model, torch.from_numpy(test["images"])), test["noise"])}
        if hasattr(model, "filter_diagnostics"):  # a filter: its gain on the blackout's clean and pure-noise frames
            dark = _dark(P, split)
            on_dark = mechanism_summary(filter_trace(model, torch.from_numpy(dark["images"])), dark["noise"])
            row |= {f"{k}_blackout": on_dark[k] for k in ("gain_clean", "gain_pure", "gain_ratio")}
    return row


def blackout_curves(P, models: dict[tuple[str, int], Any], split: str = "test") -> pd.DataFrame:
    """MAE per frame of every (model, seed) on the blackout set of ``split``: columns model, seed, frame, mae.
    One task per model (``drfkit.util.tasks.map_tasks``)."""
    forget()
    _dark(P, split)
    per_model = map_tasks(_blackout_task, [(P, split, kind, seed) for kind, seed in models], shared=portable(models),
                          desc="blackout curves")
    return pd.DataFrame([row for rows in per_model for row in rows])


def _blackout_task(P, split: str, kind: str, seed: int, shared: dict) -> list[dict[str, Any]]:
    dark = _dark(P, split)
    mean, _ = _point_and_sigma(P, shared[(kind, seed)].model, dark, seed)
    return [{"model": kind, "seed": seed, "frame": frame, "mae": float(err)}
            for frame, err in enumerate(abs_error_per_frame(mean, dark["targets"]))]


def blackout_table(curves: pd.DataFrame) -> pd.DataFrame:
    """Per model and seed: MAE on the blackout frames and on the 15 after (``blackout_summary``) and the
    recovery (``recovery_summary``: the before-gap MAE, after / before, frames until back within 1.5x), from
    ``blackout_curves``."""
    rows = []
    for (kind, seed), run in curves.groupby(["model", "seed"], sort=False):
        per_frame = run.sort_values("frame")["mae"].to_numpy()
        frames = blackout_frames(per_frame.size)
        rows.append({"model": kind, "seed": seed, **blackout_summary(per_frame, frames),
                     **recovery_summary(per_frame, frames)})
    return pd.DataFrame(rows)


def _reference_sets(P, levels: list[float]) -> tuple[dict[str, np.ndarray], dict[Any, dict[str, np.ndarray]]]:
    """(val at the training noise, {level: test, 'blackout': the blackout test set}) of ``physics_reference``."""
    val = memo((P, "pendulum split", "val", None), lambda: studies.pendulum_split(P, "val"))
    return val, {**{level: _split(P, "test", level) for level in levels}, "blackout": _dark(P, "test")}


def _reference_task(P, levels: list[float], n_particles: int, seed: int, shared: dict
                    ) -> tuple[pd.DataFrame, pd.DataFrame]:
    model = shared[seed].model
    val, sets = _reference_sets(P, levels)
    return reference_on(lambda arrays: _point_and_sigma(P, model, arrays, seed), val, sets, n_particles, seed)


def physics_reference(P, no_dynamics: dict[int, Any], levels, n_particles: int = 1000
                      ) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The true-physics particle filter on each no_dynamics seed's per-frame estimates.

    Returns (table, curves): table rows per (seed, noise) with 'mae_input' (no_dynamics), 'mae'
    (the reference), the calibrated 'sigma_scale' and 'outlier'; noise = 'blackout' for the blackout
    test set. curves: the reference's MAE per frame on the blackout set (model = 'physics_reference').
    """
    levels = [float(level) for level in levels]
    forget()
    _reference_sets(P, levels)  # read (made, the first time) here once: workers only read them
    parts = map_tasks(_reference_task, [(P, levels, n_particles, seed) for seed in no_dynamics],
                      shared=portable(no_dynamics), desc="true-physics reference (per no_dynamics seed)")
    rows = [table.assign(seed=seed) for seed, (table, _) in zip(no_dynamics, parts)]
    curve_rows = [curves.assign(seed=seed) for seed, (_, curves) in zip(no_dynamics, parts)]
    order = ["seed", "noise", "mae_input", "mae", "sigma_scale", "outlier", "calibration_interior", "n_particles"]
    return (pd.concat(rows, ignore_index=True)[order],
            pd.concat(curve_rows, ignore_index=True)[["model", "seed", "frame", "mae"]])


def encoder_accuracy_check(targets: np.ndarray, encoder_mae: dict[str, float], n_particles: int = 500,
                           seed: int = 0) -> pd.DataFrame:
    """What filtering homoscedastic errors of a given size gives: per-frame estimates = truth +
    independent Gaussian errors of a constant, known size, scaled so that their MAE is
    ``encoder_mae[name]`` (E|e| = s sqrt(2/pi) per component), filtered by the true-physics particle
    filter (the exact dynamics, the exact error model). Not a lower bound for a filter on an encoder of
    that accuracy: at a fixed mean error a constant sigma is the *least* favourable case for a filter
    (E[1/sigma^2] >= 1/E[sigma]^2), and heteroscedastic or heavy-tailed errors with a sigma that tracks
    them can be filtered to a much lower MAE.

    targets: (N, T, 2) true (cos, sin). Returns one row per name: name, encoder_mae (wanted),
    encoder_mae_drawn (measured on the draw), sigma, filtered_mae, n_particles."""
    targets = np.asarray(targets, dtype=np.float64)
    rows = []
    for i, (name, mae) in enumerate(encoder_mae.items()):
        sigma = float(mae) * math.sqrt(math.pi / 2.0)
        rng = np.random.default_rng([seed, i])
        est = targets + rng.normal(0.0, sigma, size=targets.shape)
        filtered = references.pendulum_particle_filter(est, np.full_like(est, sigma), n_particles=n_particles,
                                                       seed=seed)
        rows.append({"name": name, "encoder_mae": float(mae), "encoder_mae_drawn": float(np.abs(est - targets).mean()),
                     "sigma": sigma, "filtered_mae": float(np.abs(filtered - targets).mean()),
                     "n_particles": n_particles})
    return pd.DataFrame(rows)


def pixel_reference(P, levels, n_angles: int = 4096) -> pd.DataFrame:
    """Per-frame template matching against the renderer at each test noise level: MAE of
    (cos, sin) of the best-matching angle. No dynamics, no learning, the true renderer."""
    rows = []
    for level in levels:
        arrays = studies.pendulum_split(P, "test", level)
        theta = references.template_angles(arrays["images"], n_angles)
        est = np.stack([np.cos(theta), np.sin(theta)], axis=-1)
        rows.append({"noise": float(level), "mae": float(np.abs(est - arrays["targets"]).mean()), "n_angles": n_angles})
    return pd.DataFrame(rows)


PROTOCOL_COLUMNS = ("r_noise_spearman", "gain_clean", "gain_pure_blackout", "gain_ratio_blackout", "prior_ratio",
                    "spectral_radius_median")


def blackout_chance(P, split: str = "test") -> float:
    """The MAE of always answering (0, 0) on the blackout frames of ``split``'s blackout set: the error of
    a model that knows nothing there (what F2's 'partly' must beat)."""
    dark = blackout_split(P, split)
    start, stop = blackout_frames(dark["targets"].shape[1])
    return float(np.abs(dark["targets"][:, start:stop]).mean())


def protocol_table(protocol: str, evals: pd.DataFrame, mechanism: pd.DataFrame, dark: pd.DataFrame,
                   pure_noise_training: str | None = None, chance: float = math.nan) -> pd.DataFrame:
    """One row per (model, seed) of a protocol: MAE at each test level ('mae_<level>', from
    ``evaluate_study``), on and after the blackout (``blackout_table``) and the mechanism checks
    (``mechanism_table``; NaN where a model has no filter); 'pure_noise_training': why the protocol's
    training frames include pure noise ('' when none: ``claims.mechanism.pure_noise_training``), so the
    table says what its models saw."""
    wide = evals.pivot_table(index=["model", "seed"], columns="noise", values="mae")
    wide.columns = [f"mae_{c:g}" for c in wide.columns]
    mech = mechanism.set_index(["model", "seed"]).reindex(columns=list(PROTOCOL_COLUMNS))
    dark_cols = [c for c in ("mae_blackout", "mae_after_blackout", "recovery_ratio", "frames_to_recover") if c in dark]
    out = wide.join(dark.set_index(["model", "seed"])[dark_cols]).join(mech)
    out = out.reset_index().assign(protocol=protocol, pure_noise_training=pure_noise_training or "",
                                   mae_blackout_chance=chance)
    return out[["protocol", "model", "seed", *[c for c in out.columns if c not in ("protocol", "model", "seed")]]]



#: the parameters ``pixel_limit`` reads: the pendulum splits (``studies.profile_splits``)
LIMIT_PARAMETERS = ("profile", "pend_train_sequences", "pend_val_sequences", "pend_test_sequences", "pend_seq_len",
                    "pend_train_max_noise", "pend_data_seed", "pend_test_seed")


def limit_profile(P):
    """``P`` narrowed to ``LIMIT_PARAMETERS``: notebooks 02 and 04 call the cached ``pixel_limit`` with it, so the
    second call reads the first one's entry (a key of each notebook's whole parameter set would miss it)."""
    return narrowed(P, LIMIT_PARAMETERS, "the limit on pixels (drfkit.study.dynamics.pixel_limit)")


def pixel_limit(P, levels, n_sequences: int = 40, particle_counts=(500, 1000, 2000, 4000),
                seed: int = 0) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The limit on pixels (``drfkit.methods.pixel_bayes``) on the first ``n_sequences`` test sequences,
    clean, at every max noise of ``levels`` and on the blackout set: the particle filter with the true
    physics and the exact likelihood, the noise level marginalised ('pixel_pf') and known
    ('pixel_pf_known_level'), the per-frame posterior mean ('per_frame_bayes') and per-frame template
    matching ('template_matching'). Nothing is learned or tuned.

    Returns (table, convergence): table rows per (noise, estimator): mae (``like_for_like_mae``: the
    blackout set's over its blackout frames), mae_lo, mae_hi (95 % percentile bootstrap over sequences),
    n_sequences, n_particles; convergence rows per (noise,
    n_particles): the marginalised filter's mae at each particle count. One task per test set
    (``drfkit.util.tasks.map_tasks``), gathered in the sets' order."""
    names = ["clean", *(float(level) for level in levels), "blackout"]
    forget()
    for name in names:  # read (made, the first time) here once: workers only read them
        _limit_set(P, name)
    parts = map_tasks(_limit_task, [(P, name, n_sequences, tuple(particle_counts), seed) for name in names],
                      desc="the limit on pixels (one task per test set)")
    return (pd.DataFrame([row for rows, _ in parts for row in rows]),
            pd.DataFrame([row for _, conv in parts for row in conv]))


def _limit_set(P, name: str | float) -> dict[str, np.ndarray]:
    return _dark(P, "test") if name == "blackout" else _split(P, "test", 0.0 if name == "clean" else float(name))


def _limit_task(P, name: str | float, n_sequences: int, particle_counts: tuple[int, ...], seed: int,
                shared=None) -> tuple[list[dict], list[dict]]:
    """``pixel_limit``'s rows and convergence rows of one test set (a task: the sets are independent)."""
    from drfkit.methods import pixel_bayes

    arrays = _limit_set(P, name)
    name = name if isinstance(name, str) else f"{name:g}"
    most = max(particle_counts)
    rows, conv = [], []
    images, targets = arrays["images"][:n_sequences], arrays["targets"][:n_sequences]
    loglik = pixel_bayes.sequence_log_likelihoods(images)
    known = pixel_bayes.sequence_log_likelihoods(images, arrays["noise"][:n_sequences])
    theta = references.template_angles(images)
    by_count = {count: pixel_bayes.pixel_particle_filter(loglik, n_particles=count, seed=seed)
                for count in particle_counts}
    estimates = {
        "pixel_pf": by_count[most],
        "pixel_pf_known_level": pixel_bayes.pixel_particle_filter(known, n_particles=most, seed=seed),
        "per_frame_bayes": pixel_bayes.per_frame_bayes(images, loglik=loglik.reshape(-1, loglik.shape[-1])),
        "template_matching": np.stack([np.cos(theta), np.sin(theta)], axis=-1)}
    for estimator, est in estimates.items():
        per_sequence = [like_for_like_mae(abs_error_per_frame(est[i:i + 1], targets[i:i + 1]), name)
                        for i in range(images.shape[0])]
        lo, hi = bootstrap_interval(per_sequence, seed=seed)
        rows.append({"noise": name, "estimator": estimator,
                     "mae": like_for_like_mae(abs_error_per_frame(est, targets), name), "mae_lo": lo, "mae_hi": hi,
                     "n_sequences": int(images.shape[0]),
                     "n_particles": most if estimator.startswith("pixel_pf") else 0})
    for count, est in by_count.items():
        conv.append({"noise": name, "n_particles": count,
                     "mae": like_for_like_mae(abs_error_per_frame(est, targets), name)})
    return rows, conv


def quantisation_effect(P, models: dict[tuple[str, int], Any], levels, n_sequences: int = 100,
                        n_particles: int = 2000, seed: int = 0) -> pd.DataFrame:
    """What storing the blend by truncation (the benchmark's code) instead of rounding (the book's generator) changes,
    on the first ``n_sequences`` test sequences at each max noise of ``levels``: the same motions, noise levels and
    pixel draws, stored both ways (noise kinds 'rkn_uniform' and 'rkn_uniform_truncated').

    Rows per (noise, estimator, frames, likelihood) with 'mae': the limit's per-frame Bayes estimate and particle
    filter ('per_frame_bayes', 'pixel_pf') with the likelihood of either storage on either frames (the mismatched
    pair shows what the wrong model of the benchmark's pixels costs); every (kind, seed) of ``models`` by its
    dropout-off pass on both ('likelihood' NaN; trained on rounded frames, so 'truncate' is a shift it never saw)."""
    levels = [float(v) for v in levels]
    forget()
    for level in levels:  # read (made, the first time) here once: workers only read them
        _stored_both_ways(P, level)
    parts = map_tasks(_quantisation_task, [(P, level, n_sequences, n_particles, seed) for level in levels],
                      shared=portable(models), desc="rounding or truncation (one task per level)")
    return pd.DataFrame([row for rows in parts for row in rows])


def _stored_both_ways(P, level: float) -> dict[str, dict[str, np.ndarray]]:
    return {q: memo((P, "pendulum split", "test", kind, level),
                    lambda kind=kind: studies.pendulum_split(P, "test", Noise(kind, level)))
            for q, kind in (("round", "rkn_uniform"), ("truncate", "rkn_uniform_truncated"))}


def _quantisation_task(P, level: float, n_sequences: int, n_particles: int, seed: int, shared: dict) -> list[dict]:
    """``quantisation_effect``'s rows at one level (a task: the levels are independent)."""
    from drfkit.methods import pixel_bayes

    rows = []
    frames = _stored_both_ways(P, level)
    targets = frames["round"]["targets"][:n_sequences]
    for stored, arrays in frames.items():
        images = arrays["images"][:n_sequences]
        for likelihood in ("round", "truncate"):
            loglik = pixel_bayes.sequence_log_likelihoods(images, quantise=likelihood)
            estimates = {"per_frame_bayes": pixel_bayes.per_frame_bayes(images, loglik=loglik.reshape(-1, loglik.shape[-1])),
                         "pixel_pf": pixel_bayes.pixel_particle_filter(loglik, n_particles=n_particles, seed=seed)}
            rows += [{"noise": level, "estimator": name, "seed": np.nan, "frames": stored, "likelihood": likelihood,
                      "mae": float(abs_error_per_frame(est, targets).mean())} for name, est in estimates.items()]
        for (kind, model_seed), entry in shared.items():
            point = dropout_off_point(entry.model, images)
            rows.append({"noise": level, "estimator": kind, "seed": model_seed, "frames": stored,
                         "likelihood": np.nan, "mae": float(abs_error_per_frame(point, targets).mean())})
    return rows


def dropout_off_point(model, images: np.ndarray, chunk: int = 256) -> np.ndarray:
    """The dropout-off output (N, T, out) of ``model`` on images uint8 (N, T, 24, 24); its mode restored after."""
    was = model.training
    model.eval()
    try:
        with torch.no_grad():
            x = torch.from_numpy(images)
            return torch.cat([model(x[i:i + chunk])[0] for i in range(0, x.shape[0], chunk)]).numpy()
    finally:
        model.train(was)


# ------------------------------------------------------------------------------ pedestrians
# Frames whose detection the pedestrian blackout removes (keypoints zeroed, confidence 0), in windows
# whose every frame is real. No training window holds such an all-zero frame (a missed detection is
# left out of its track, not zeroed), so every model reads one as a person about 50 m away
# (docs/simulator.md, section 4); the constant-velocity reference is told which frames are missing.
PEDESTRIAN_BLACKOUT = (4, 7)
CV_SIGMA_SCALES = (0.5, 1.0, 2.0)
CV_ACCEL_STDS = (0.25, 0.5, 1.0, 2.0, 4.0)  # m/s^2 of depth change: walking turns plus the ego car's drift


def pedestrian_blackout(P, split: str) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """The full-length windows of a pedestrian split at the training p with the detections of
    frames PEDESTRIAN_BLACKOUT removed; returns (split arrays, (N, S) bool of removed frames)."""
    seqs = studies.pedestrian_split(P, split)
    full = seqs["mask"].all(axis=1)
    start, stop = PEDESTRIAN_BLACKOUT
    if seqs["mask"].shape[1] < stop + 1 or not full.any():
        raise ValueError(f"the pedestrian blackout needs full windows of more than {stop} frames; ped_seq_len is "
                         f"{seqs['mask'].shape[1]}")
    out = {k: (v[full] if isinstance(v, np.ndarray) and v.shape[:1] == full.shape else v) for k, v in seqs.items()}
    out["inputs"] = out["inputs"].copy()
    out["inputs"][:, start:stop] = 0.0
    removed = np.zeros(out["mask"].shape, bool)
    removed[:, start:stop] = True
    return out, removed


def _depth_predictions(P, model, inputs: np.ndarray, seed: int) -> tuple[np.ndarray, np.ndarray]:
    mean, total = _point_and_sigma(P, model, {"images": inputs}, seed)
    return mean[..., 0], total[..., 0]


def _seconds(seqs: dict[str, np.ndarray]) -> np.ndarray:
    return np.diff(seqs["timestamp"], axis=1) / 1e6


def _masked_mae(est: np.ndarray, target: np.ndarray, where: np.ndarray) -> float:
    return float(np.abs(est - target)[where].mean())


def pedestrian_reference(P, no_dynamics: dict[int, Any], models: dict[tuple[str, int], Any] | None = None
                         ) -> pd.DataFrame:
    """A constant-velocity Kalman filter on each no_dynamics seed's per-frame depths, its sigma scale
    and acceleration noise chosen on the VALIDATION split at the training p; evaluated at every
    ``ped_eval_p`` and on the pedestrian blackout (where it predicts through the removed frames).
    With ``models``, their blackout MAE is added (noise 'blackout', model = kind). Rows: model,
    seed, noise, mae (valid frames; on the blackout, the removed frames only)."""
    val = studies.pedestrian_split(P, "val")
    rows = []
    for seed, model in no_dynamics.items():
        mean, sigma = _depth_predictions(P, model, val["inputs"], seed)
        target = val["targets"][..., 0]
        best = (np.inf, None, None)
        for scale in CV_SIGMA_SCALES:
            for accel in CV_ACCEL_STDS:
                est = references.constant_velocity_filter(mean, scale * sigma, val["mask"], dt=_seconds(val),
                                                          accel_std=accel)
                err = _masked_mae(est, target, val["mask"])
                if err < best[0]:
                    best = (err, scale, accel)
        _, scale, accel = best
        for p in P.pedestrians.eval_p:
            seqs = studies.pedestrian_split(P, "test", p)
            mean, sigma = _depth_predictions(P, model, seqs["inputs"], seed)
            est = references.constant_velocity_filter(mean, scale * sigma, seqs["mask"], dt=_seconds(seqs),
                                                      accel_std=accel)
            rows.append({"model": "cv_reference", "seed": seed, "noise": str(float(p)),
                         "mae": _masked_mae(est, seqs["targets"][..., 0], seqs["mask"]),
                         "sigma_scale": scale, "accel_std": accel})
        dark, removed = pedestrian_blackout(P, "test")
        mean, sigma = _depth_predictions(P, model, dark["inputs"], seed)
        est = references.constant_velocity_filter(mean, scale * sigma, ~removed, dt=_seconds(dark), accel_std=accel)
        rows.append({"model": "cv_reference", "seed": seed, "noise": "blackout",
                     "mae": _masked_mae(est, dark["targets"][..., 0], removed), "sigma_scale": scale, "accel_std": accel})
    if models:
        dark, removed = pedestrian_blackout(P, "test")
        for (kind, seed), model in models.items():
            mean, _ = _depth_predictions(P, model, dark["inputs"], seed)
            rows.append({"model": kind, "seed": seed, "noise": "blackout",
                         "mae": _masked_mae(mean, dark["targets"][..., 0], removed)})
    return pd.DataFrame(rows)


# ------------------------------------------------------------------------ command line
def probe(P, models: dict[tuple[str, int], Any], noise: Noise | float, split: str = "val") -> pd.DataFrame:
    """The mechanism checks and the blackout MAE of ``models`` on ``split`` (validation by
    default: a run can be judged while it trains without touching the test set)."""
    mech = mechanism_table(P, models, noise, split)
    dark = blackout_table(blackout_curves(P, models, split))
    return dark.merge(mech, on=["model", "seed"])
