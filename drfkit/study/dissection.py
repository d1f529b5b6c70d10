"""The dissection of the pendulum study's filters (``drfkit.methods.dissection``) on a profile's trained
models: per noise level, how r, the prior variance and the gain compare with the errors they stand for; the
transition open loop (the gain forced to 0) by horizon beside hold; the gain clamped on the first k gap frames
only; and the oracle gain at the highest noise and on the blackout.

Every MAE here is the dropout-off output's. Nothing reads another split: the oracle gain is an oracle on purpose
(it reads the scored frames' errors), a yardstick of what the model's own transition and observations allow.
"""
from __future__ import annotations

import hashlib
import math
from typing import Any

import numpy as np
import pandas as pd
import torch

from drfkit.data.pendulum import blackout_frames
from drfkit.methods import dissection as dis
from drfkit.study import studies
from drfkit.study.dynamics import blackout_split, dropout_off_point
from drfkit.util.tasks import forget, map_tasks, memo
from drfkit.models.frame_codes import distinct_frames_once
from drfkit.models.portable import portable

# (a3) the gain clamped on the first k gap frames: the first sequences of the scored split (enough for a curve)
PARTIAL_CLAMP_SEQUENCES = 200


def _prepared(model, arrays: dict[str, np.ndarray], clean_codes: dict[str, torch.Tensor]
              ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """w, r (N, T, n) on the set's frames and the observed block's truth (N, T, k). ``clean_codes`` (content digest
    -> w of those noiseless frames) is filled and read: the sets show the same motions, so their noiseless frames
    are encoded once per model, not once per set (the same call on the same frames: the same numbers)."""
    w, r = dis.observations(model, torch.from_numpy(arrays["images"]))
    clean = np.ascontiguousarray(arrays["clean"])
    digest = hashlib.sha256(f"{clean.dtype}|{clean.shape}|".encode() + clean.tobytes()).hexdigest()
    if digest not in clean_codes:
        clean_codes[digest] = dis.observations(model, torch.from_numpy(clean))[0]
    return w, r, model.observed_truth(clean_codes[digest], torch.from_numpy(arrays["targets"]))


def _dropout_off_mae(model, arrays: dict[str, np.ndarray], frames: slice = slice(None)) -> float:
    """MAE of the dropout-off output on ``frames`` of every sequence (a model without a filter too)."""
    mean = dropout_off_point(model, arrays["images"])
    return float(np.abs(mean.astype(np.float64) - arrays["targets"])[:, frames].mean())


def _oracle_pass(model, arrays, prepared, trace) -> tuple[dict[str, np.ndarray], list[dict]]:
    """(b) on one set: K* per level bin from the as-run ``trace``'s output-space errors, forced on every frame,
    decoded with the as-run variances. Returns (the intervened trace, the K* rows)."""
    targets = arrays["targets"].astype(np.float64)
    obs = dis.observation_outputs(model, torch.from_numpy(arrays["images"]))
    prior_err2 = np.square(trace["prior_mean"] - targets[:, 1:]).sum(-1)
    obs_err2 = np.square(obs - targets).sum(-1)[:, 1:]
    table = dis.oracle_gain_table(prior_err2, obs_err2, arrays["noise"])
    w, r, truth = prepared
    out = dis.filter_pass(model, w, r, truth, targets, log_var=trace["log_var"],
                          gain=dis.oracle_gain(arrays["noise"], table))
    return out, table


def open_loop(model, prepared, targets: np.ndarray, as_run: dict[str, np.ndarray], start: int, stop: int
              ) -> tuple[dict[str, np.ndarray], float]:
    """(a1, a2) on one set: the gain forced to exactly 0 on frames [start, stop), in float64 (P of an expanding F
    outgrows float32), decoded with the belief's variance held at start - 1, beside zero-order hold of the as-run
    estimate there. Frames after the gap are not run: an expanding F leaves a P that no update can factor.
    prepared: w, r, truth (N, T, ...); targets (N, T, 2); as_run: the model's own ``filter_pass`` on the set.
    Returns ({'mae_clamped', 'angle_clamped', 'mae_hold', 'angle_hold'}: (stop - start,) by horizon, the largest
    gain read back on the clamped frames (``check_clamped`` raises above its tolerance))."""
    w, r, truth = prepared
    gap = slice(0, stop)
    clamp = dis.forced_gain((w.shape[0], stop), start, stop)
    clamped = dis.filter_pass(model, w[:, gap], r[:, gap], truth[:, gap], targets[:, gap], float64=True, gain=clamp,
                              log_var=dis.held_variance(as_run["log_var"][:, gap], start, stop))
    worst = dis.check_clamped(clamped, clamp)
    held = dis.hold(as_run["mean"], start, stop)
    curve = {"mae_clamped": clamped["abs_err"], "angle_clamped": dis.angle_error(clamped["mean"], targets[:, gap]),
             "mae_hold": np.abs(held - targets).mean(-1), "angle_hold": dis.angle_error(held, targets)}
    return {name: dis.per_horizon(err, start, stop - start) for name, err in curve.items()}, worst


def dissect_filters(P, models: dict[tuple[str, int], Any], split: str = "test"
                    ) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame, pd.DataFrame]:
    """The dissection of every filter in ``models`` ((kind, seed) -> model; models without ``filter_internals``
    serve as the no_dynamics yardstick) on ``split`` at the training noise, at the highest evaluation noise and
    on its blackout set (frames [start, stop) pure noise).

    Returns (calibration, interventions, horizons, gains):
    * calibration: one row per (model, seed, set, level bin) of ``dissection.calibration_table``, set in
      {'train', 'ood', 'blackout'};
    * horizons: one row per (model, seed, h = 1..15): the open-loop error with the gain forced to 0 from the gap's
      first frame ('mae_clamped', 'angle_clamped'), zero-order hold of the last decoded estimate ('mae_hold',
      'angle_hold'), the model as it runs on the blackout ('mae_as_run', 'angle_as_run') and on the same frames
      without the blackout ('mae_as_run_ordinary'), the oracle gain on the blackout ('mae_oracle_gain'), the
      verdict ('dissection.horizon_verdicts'), and (a3) 'mae_gap_partial': the gap's MAE with only its first h
      frames clamped, the own gain after (first ``PARTIAL_CLAMP_SEQUENCES`` sequences; NaN where a transition that
      expanded over the clamp left a covariance the own update cannot factor), 'mae_after_partial' the 15 frames
      after the gap;
    * interventions: one row per filter: mae_train, mae_ood, mae_blackout as the model runs; mae_blackout_clamped
      (the gap's mean of mae_clamped) and mae_blackout_hold; clamped_gain_max (read back; an error above
      ``dissection.GAIN_TOLERANCE``); open_loop_horizon H; mae_ood_oracle_gain, mae_blackout_oracle_gain;
      verdict_blackout (the per-horizon verdicts as runs), verdict_ood ('gain' where the oracle gain beats the
      model at the highest noise, else 'filtering'); no_dynamics' mae_ood (mean over its seeds, NaN without one);
    * gains: one row per (model, seed, set in {'ood', 'blackout'}, level bin) of ``dissection.oracle_gain_table``
      beside the model's own mean gain there ('model_gain', on its observed block)."""
    forget()
    sets = _sets(P, split)  # read (made, the first time) here once: workers only read them
    nd = [_dropout_off_mae(m, sets["ood"]) for (kind, _), m in models.items() if kind == "no_dynamics"]
    nd_ood = float(np.mean(nd)) if nd else float("nan")
    filters = [key for key, m in models.items() if hasattr(m, "filter_internals")]
    parts = map_tasks(_dissect_one, [(P, split, kind, seed, nd_ood) for kind, seed in filters],
                      shared=portable({key: models[key] for key in filters}), desc="dissecting the filters")
    return tuple(pd.DataFrame([row for part in parts for row in part[i]]) for i in range(4))


def _sets(P, split: str) -> dict[str, dict[str, np.ndarray]]:
    """The dissection's three sets of ``split``: at the training noise, at the highest evaluation noise and the
    blackout set (read once per process, ``tasks.memo``)."""
    return memo((P, "dissection sets", split), lambda: {
        "train": studies.pendulum_split(P, split, P.pendulum.train_max_noise),
        "ood": studies.pendulum_split(P, split, max(P.pendulum.eval_max_noise)),
        "blackout": blackout_split(P, split)})


def _dissect_one(P, split: str, kind: str, seed: int, nd_ood: float, shared: dict) -> tuple[list, list, list, list]:
    """``dissect_filters``' rows of one filter (a task of ``map_tasks``): (calibration, [intervention], horizons,
    gains). Its passes share one ``distinct_frames_once`` block: the three sets show the same sequences, so the
    encoder sees each distinct frame once per filter (the blackout set's frames outside the gap are the training
    noise set's), the same numbers."""
    model = shared[(kind, seed)].model
    with distinct_frames_once(model):
        return _dissect(P, split, kind, seed, nd_ood, model)


def _dissect(P, split: str, kind: str, seed: int, nd_ood: float, model) -> tuple[list, list, list, list]:
    sets = _sets(P, split)
    train_level, ood_level = P.pendulum.train_max_noise, max(P.pendulum.eval_max_noise)
    dark = sets["blackout"]
    start, stop = blackout_frames(dark["images"].shape[1])
    targets = dark["targets"].astype(np.float64)
    calibration, horizons, gains = [], [], []
    row: dict[str, Any] = {"model": kind, "seed": seed, "train_level": train_level, "ood_level": ood_level}
    prepared, traces, clean_codes = {}, {}, {}
    for name, arrays in sets.items():
        prepared[name] = _prepared(model, arrays, clean_codes)
        traces[name] = dis.filter_pass(model, *prepared[name], arrays["targets"])
        for cal in dis.calibration_table(traces[name], arrays["noise"]):
            calibration.append({"model": kind, "seed": seed, "set": name, **cal})
    row["mae_train"] = float(traces["train"]["abs_err"].mean())
    row["mae_ood"] = float(traces["ood"]["abs_err"].mean())
    row["mae_blackout"] = float(traces["blackout"]["abs_err"][:, start:stop].mean())
    as_run = traces["blackout"]
    w, r, truth = prepared["blackout"]
    curve, row["clamped_gain_max"] = open_loop(model, prepared["blackout"], targets, as_run, start, stop)
    curve |= {name: dis.per_horizon(err, start, stop - start) for name, err in (
        ("mae_as_run", as_run["abs_err"]), ("angle_as_run", dis.angle_error(as_run["mean"], targets)),
        ("mae_as_run_ordinary", traces["train"]["abs_err"]))}
    # (b) the oracle gain at the highest noise and on the blackout
    for name in ("ood", "blackout"):
        out, table = _oracle_pass(model, sets[name], prepared[name], traces[name])
        own_gain = traces[name]["gain"][:, 1:]
        bins = dis.level_bins(sets[name]["noise"])[:, 1:]
        for g in table:
            b = np.iinfo(np.int32).max if g["level_lo"] >= 1.0 else int(round(g["level_lo"] / dis.LEVEL_BIN))
            gains.append({"model": kind, "seed": seed, "set": name, **g,
                          "model_gain": float(own_gain[bins == b].mean())})
        if name == "ood":
            row["mae_ood_oracle_gain"] = float(out["abs_err"].mean())
        else:
            row["mae_blackout_oracle_gain"] = float(out["abs_err"][:, start:stop].mean())
            curve["mae_oracle_gain"] = dis.per_horizon(out["abs_err"], start, stop - start)
    # (a3) only the first k gap frames clamped, the own gain after
    few = slice(0, min(PARTIAL_CLAMP_SEQUENCES, w.shape[0]))
    partial, after = [], []
    for k in range(1, stop - start + 1):
        gain = dis.forced_gain((few.stop, w.shape[1]), start, start + k)
        try:
            out = dis.filter_pass(model, w[few], r[few], truth[few], targets[few], float64=True, gain=gain,
                                  log_var=dis.held_variance(as_run["log_var"][few], start, start + k,
                                                            elsewhere=np.nan))
        except ValueError:  # k expanding steps left a P that the own update cannot factor: NaN, not a number
            partial.append(np.nan), after.append(np.nan)
            continue
        dis.check_clamped(out, gain)
        partial.append(float(out["abs_err"][:, start:stop].mean()))
        after.append(float(out["abs_err"][:, stop:stop + (stop - start)].mean()))
    verdicts = dis.horizon_verdicts(curve["mae_clamped"], curve["mae_as_run"], curve["mae_hold"])
    for h in range(stop - start):
        horizons.append({"model": kind, "seed": seed, "h": h + 1, **{k: float(v[h]) for k, v in curve.items()},
                         "mae_gap_partial": partial[h], "mae_after_partial": after[h], "verdict": verdicts[h]})
    row |= {"mae_blackout_clamped": float(curve["mae_clamped"].mean()),
            "mae_blackout_hold": float(curve["mae_hold"].mean()),
            "open_loop_horizon": dis.open_loop_horizon(curve["mae_clamped"], curve["mae_hold"]),
            "verdict_blackout": dis.verdict_runs(verdicts),
            "verdict_ood": "gain" if row["mae_ood_oracle_gain"] < row["mae_ood"] else "filtering",
            "no_dynamics_mae_ood": nd_ood}
    return calibration, [row], horizons, gains


# the calibrated-gain screen's rule, written before its runs (docs/dynamics.md)
SCREEN_MIN_SPEARMAN = 0.8
SCREEN_MAE_TIE = 0.05


# a seed whose r does not follow the noise in distribution (the known-dynamics filter's failure, docs/dynamics.md)
FAILED_SEED_SPEARMAN = 0.5


def screen_variants(P, variants, seeds, budget_name: str = "fit", out=None, train_level: float = 0.5,
                    per_seed: bool = False, rule: str = "calibrated", reference_mae: float | None = None
                    ) -> pd.DataFrame:
    """The calibrated-gain screen on VALIDATION data at the training noise only (levels <= ``train_level``;
    never 0.75 or a blackout): per trained (variant, seed) of the protocol ablation (``drfkit.study.ablation``,
    trained if missing) ``dissection.in_distribution_screen``; 'eligible' and 'chosen' by the rule:
    seed means with rho(log r, level) >= SCREEN_MIN_SPEARMAN and gain slope < 0 are eligible, the lowest
    MAE is chosen, MAEs within SCREEN_MAE_TIE of the lowest are a tie broken by the steeper gain slope.
    ``per_seed``: the rows per (variant, seed) instead, with 'failed' (rho < FAILED_SEED_SPEARMAN: a seed whose
    r does not follow the noise, the known-dynamics filter's failure mode). Every row also carries the open loop on
    validation (updates skipped on the blackout's frames of ordinary frames: 'open_loop_horizon' H, 'mae_open_loop'
    and hold's 'mae_open_loop_hold' over the 15 frames). ``rule='both_halves'`` judges by ``screen_both_halves``
    against ``reference_mae`` (the yardstick's validation MAE, read from its own screen's table)."""
    from drfkit.methods.train import load_checkpoint
    from drfkit.study import ablation
    from drfkit.study.pendulum_runs import load_split

    rows = []
    for variant in variants:
        for seed in seeds:
            res, run = ablation.train_variant(P, variant, seed, budget_name, out, progress=False)
            val = load_split(run.splits, "val", run.noise(train_level))
            model = load_checkpoint(res.best_path)
            prepared = _prepared(model, val, {})
            trace = dis.filter_pass(model, *prepared, val["targets"])
            # the open loop on ordinary validation frames: updates skipped on the blackout's frames, nothing noisier
            start, stop = blackout_frames(val["targets"].shape[1])
            curve, _ = open_loop(model, prepared, val["targets"].astype(np.float64), trace, start, stop)
            rows.append({"variant": variant, "seed": seed,
                         **dis.in_distribution_screen(trace, val["noise"], max_level=train_level),
                         "open_loop_horizon": dis.open_loop_horizon(curve["mae_clamped"], curve["mae_hold"]),
                         "mae_open_loop": float(curve["mae_clamped"].mean()),
                         "mae_open_loop_hold": float(curve["mae_hold"].mean())})
    table = pd.DataFrame(rows)
    if per_seed:  # each seed's row, and whether its r fails to follow the noise in distribution
        return table.assign(failed=table["r_level_spearman"] < FAILED_SEED_SPEARMAN)
    means = table.groupby("variant", sort=False).mean(numeric_only=True).drop(columns="seed")
    means = means.join(table.groupby("variant", sort=False).size().rename("n_seeds"))
    if rule == "both_halves":
        if reference_mae is None or not reference_mae > 0:
            raise ValueError(f"the both-halves rule needs the yardstick's validation MAE (> 0), got {reference_mae!r}")
        return screen_both_halves(means, reference_mae).reset_index()
    if rule != "calibrated":
        raise ValueError(f"rule must be 'calibrated' or 'both_halves', got {rule!r}")
    return screen_choice(means).reset_index()


def restart_check(P, kind: str, protocol: str = "book") -> pd.DataFrame:
    """The validation-only restart rule on a profile's runs of ``kind``: per seed slot of ``P.seeds``, the run trained
    from the slot's own seed and, where the protocol's ``restarts`` replace it, the run trained from the replacement,
    each with ``dissection.in_distribution_screen`` on the VALIDATION split at the training noise (levels <= it;
    never the OOD level or a blackout). Columns: slot, training_seed, checkpoint, r_level_spearman, r_log_slope,
    gain_slope, mae, failed (rho < FAILED_SEED_SPEARMAN), used (the run the book's tables read). A run whose
    checkpoint is absent has NaN statistics (a replaced seed's run need not be kept)."""
    from drfkit.methods.train import load_checkpoint
    from drfkit.study.pendulum_runs import pendulum_split, training_seed

    level = P.pendulum.train_max_noise
    val = pendulum_split(P, "val", level)
    rows = []
    for slot in P.seeds:
        used = training_seed(P, kind, slot, protocol)
        for seed in dict.fromkeys([slot, used]):
            stem = studies.checkpoint_stem(P, "pendulum", kind, slot, protocol, training_seed=seed)
            row = {"slot": slot, "training_seed": seed, "checkpoint": stem.name, "used": seed == used}
            best = stem.parent / f"{stem.name}-best.pt"
            if best.exists():
                model = load_checkpoint(best)
                w, r, truth = _prepared(model, val, {})
                trace = dis.filter_pass(model, w, r, truth, val["targets"])
                row |= dis.in_distribution_screen(trace, val["noise"], max_level=level)
            rows.append(row)
    table = pd.DataFrame(rows)
    if "r_level_spearman" not in table:
        table["r_level_spearman"] = np.nan
    return table.assign(failed=table["r_level_spearman"] < FAILED_SEED_SPEARMAN)


def screen_choice(means: pd.DataFrame) -> pd.DataFrame:
    """The screen's rule on seed means indexed by variant (r_level_spearman, gain_slope, mae): adds
    'eligible' and 'chosen' (at most one row; none when no variant is eligible)."""
    means = means.copy()
    means["eligible"] = (means["r_level_spearman"] >= SCREEN_MIN_SPEARMAN) & (means["gain_slope"] < 0)
    means["chosen"] = False
    pool = means[means["eligible"]]
    if len(pool):
        tied = pool[pool["mae"] <= pool["mae"].min() * (1 + SCREEN_MAE_TIE)]
        means.loc[tied["gain_slope"].idxmin(), "chosen"] = True
    return means


# the fifth round's rule, written before its runs (docs/dynamics.md): the candidate keeps the calibrated gain, fits the
# mean within this factor of the reference (the book's calibrated-gain DRF on the same budget), and then predicts
# open loop the longest; horizons within BOTH_HALVES_H_TIE frames are a tie, broken by the lower MAE
BOTH_HALVES_MAE_RATIO = 1.5
BOTH_HALVES_H_TIE = 1.0


def screen_both_halves(means: pd.DataFrame, reference_mae: float) -> pd.DataFrame:
    """The fifth round's rule on seed means indexed by variant (r_level_spearman, gain_slope, mae,
    open_loop_horizon): eligible, a variant with rho(log r, level) >= SCREEN_MIN_SPEARMAN, a gain slope < 0 and an
    MAE <= BOTH_HALVES_MAE_RATIO x ``reference_mae`` (the yardstick's, on the same validation split and budget);
    chosen, the eligible one with the largest open-loop horizon, horizons within BOTH_HALVES_H_TIE a tie broken by
    the lower MAE; when none is eligible, none is chosen (the failure is recorded, docs/dynamics.md)."""
    means = means.copy()
    means["mae_bound"] = BOTH_HALVES_MAE_RATIO * float(reference_mae)
    means["eligible"] = ((means["r_level_spearman"] >= SCREEN_MIN_SPEARMAN) & (means["gain_slope"] < 0)
                         & (means["mae"] <= means["mae_bound"]))
    means["chosen"] = False
    pool = means[means["eligible"]]
    if len(pool):
        tied = pool[pool["open_loop_horizon"] >= pool["open_loop_horizon"].max() - BOTH_HALVES_H_TIE]
        means.loc[tied["mae"].idxmin(), "chosen"] = True
    return means


# The fifth round's targets for its chosen DRF (docs/dynamics.md, written before the runs): (name, the model's
# column, the table it lies in, the bound: a number or (a comparator's column, a factor), '<=' or '<')
BOTH_HALVES_TARGETS = (
    ("open-loop horizon H >= 15 at 0.5", "open_loop_horizon", "dissection", 15.0, ">="),
    ("blackout MAE <= 0.10", "mae_blackout", "protocols", 0.10, "<="),
    ("MAE at 0.75 <= 0.5 x no_dynamics'", "mae_0.75", "protocols", ("no_dynamics", 0.5), "<="),
    ("MAE at 0.75 below the LSTM's", "mae_0.75", "protocols", ("lstm", 1.0), "<"),
    ("gain on pure noise <= 0.25 of clean", "gain_ratio_blackout", "protocols", 0.25, "<="),
    ("MAE at 0.5 <= no_dynamics'", "mae_0.5", "protocols", ("no_dynamics", 1.0), "<="),
    ("MAE after the gap <= 1.5 x no_dynamics' MAE at 0.5", "mae_after_blackout", "protocols",
     ("no_dynamics", 1.5, "mae_0.5"), "<="),
    ("beyond: MAE at 0.5 <= 0.0048", "mae_0.5", "protocols", 0.0048, "<="),
    ("beyond: MAE at 0.75 <= 0.015", "mae_0.75", "protocols", 0.015, "<="),
)


def both_halves_targets(protocols: pd.DataFrame, dissection: pd.DataFrame, model: str) -> pd.DataFrame:
    """The fifth round's targets for ``model`` (``BOTH_HALVES_TARGETS``), on seed means of one protocol's rows:
    ``protocols`` (notebook 02's protocol table: model, seed, mae_0.5, ...) and ``dissection`` (its dissection
    table: model, seed, open_loop_horizon). One row per target: value, bound, met, and the per-seed values."""
    tables = {"protocols": protocols, "dissection": dissection}
    rows = []
    for name, column, where, bound, op in BOTH_HALVES_TARGETS:
        own = tables[where].loc[tables[where]["model"] == model].sort_values("seed")[column].astype(float)
        if own.empty:
            raise ValueError(f"no rows of {model!r} in the {where} table: it is not a model of this protocol")
        if isinstance(bound, tuple):
            other, factor, *col = bound
            ref = protocols.loc[protocols["model"] == other, col[0] if col else column].astype(float)
            limit = factor * float(ref.mean()) if len(ref) else math.nan
        else:
            limit = float(bound)
        value = float(own.mean())
        # compared at 10 significant digits: a mean of equal seeds must not miss its bound by a rounding error
        v, b = float(f"{value:.10g}"), float(f"{limit:.10g}")
        met = {"<=": v <= b, "<": v < b, ">=": v >= b}[op]
        rows.append({"model": model, "target": name, "value": value, "bound": limit, "met": bool(met),
                     "per_seed": ", ".join(f"{v:.4g}" for v in own)})
    return pd.DataFrame(rows)


def calibration_summary(calibration: pd.DataFrame) -> pd.DataFrame:
    """Per (model, set): the calibration ratios and the gain over the set's frames, mean over seeds and
    level bins weighted by frames -- the dissection's table in one screen."""
    cols = ["r", "p_prior", "q", "gain", "obs_err2", "prior_err2"]
    weighted = calibration.assign(**{c: calibration[c] * calibration["frames"] for c in cols})
    g = weighted.groupby(["model", "seed", "set"], sort=False)[[*cols, "frames"]].sum()
    per = g[cols].div(g["frames"], axis=0)
    per["err2_over_r"], per["e2_over_p"] = per["obs_err2"] / per["r"], per["prior_err2"] / per["p_prior"]
    return per.groupby(["model", "set"], sort=False)[["gain", "err2_over_r", "e2_over_p", "r", "p_prior", "q"]].mean()


__all__ = ["BOTH_HALVES_TARGETS", "both_halves_targets", "BOTH_HALVES_H_TIE", "BOTH_HALVES_MAE_RATIO", "FAILED_SEED_SPEARMAN", "open_loop", "screen_both_halves", "SCREEN_MAE_TIE", "SCREEN_MIN_SPEARMAN", "calibration_summary", "dissect_filters",
           "restart_check", "screen_choice", "screen_variants"]
