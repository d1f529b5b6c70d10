"""The dissection of the pendulum study's filters (``drfkit.methods.dissection``) on a profile's trained
models: per noise level, how r, the prior variance and the gain compare with the errors they stand for,
and what the filter gives with its gain clamped on a blackout or with a competent r out of distribution.

Every MAE here is the dropout-off output's. The r fit of intervention (b) reads the fit split (validation)
at the training noise only; the scored split is another.
"""
from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd
import torch

from drfkit.data.pendulum import blackout_frames
from drfkit.methods import dissection as dis
from drfkit.study import studies
from drfkit.study.dynamics import blackout_split, dropout_off_point
from drfkit.util.progress import steps


def _prepared(model, arrays: dict[str, np.ndarray]) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """w, r (N, T, n) on the set's frames and the observed block's truth (N, T, k)."""
    w, r = dis.observations(model, torch.from_numpy(arrays["images"]))
    w_clean, _ = dis.observations(model, torch.from_numpy(arrays["clean"]))
    return w, r, model.observed_truth(w_clean, torch.from_numpy(arrays["targets"]))


def _dropout_off_mae(model, arrays: dict[str, np.ndarray], frames: slice = slice(None)) -> float:
    """MAE of the dropout-off output on ``frames`` of every sequence (a model without a filter too)."""
    mean = dropout_off_point(model, arrays["images"])
    return float(np.abs(mean.astype(np.float64) - arrays["targets"])[:, frames].mean())


def dissect_filters(P, models: dict[tuple[str, int], Any], split: str = "test", fit_split: str = "val"
                    ) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The dissection of every filter in ``models`` ((kind, seed) -> model; models without
    ``filter_internals`` serve as the no_dynamics yardstick) on ``split`` at the training noise, at the
    highest evaluation noise and on its blackout set; r of intervention (b) fit on ``fit_split`` at the
    training noise.

    Returns (calibration, interventions). calibration: one row per (model, seed, set, level bin) of
    ``dissection.calibration_table``, set in {'train', 'ood', 'blackout'}. interventions: one row per
    filter (model, seed): mae_train, mae_ood, mae_blackout as the model is; mae_blackout_clamped (a), in
    float64 (a diverging transition outgrows float32's covariance);
    mae_ood_fitted_r and mae_ood_oracle_r (b), the fit's slope b (mean over dims); mae_ood_oracle_r_q (c)
    with q_scale chosen on the fit split (e2_over_p_fit its prior calibration there); no_dynamics' mae_ood
    (mean over its seeds, NaN without one) and the verdict of ``dissection.failure_verdict``."""
    train_level = P.pendulum.train_max_noise
    ood_level = max(P.pendulum.eval_max_noise)
    sets = {"train": studies.pendulum_split(P, split, train_level),
            "ood": studies.pendulum_split(P, split, ood_level),
            "blackout": blackout_split(P, split)}
    fit_set = studies.pendulum_split(P, fit_split, train_level)
    start, stop = blackout_frames(sets["blackout"]["images"].shape[1])
    nd = [_dropout_off_mae(m, sets["ood"]) for (kind, _), m in models.items() if kind == "no_dynamics"]
    nd_ood = float(np.mean(nd)) if nd else float("nan")
    calibration, interventions = [], []
    filters = {key: m for key, m in models.items() if hasattr(m, "filter_internals")}
    for (kind, seed), model in steps(filters.items(), "dissecting the filters", len(filters)):
        k = model.observed_dims
        row: dict[str, Any] = {"model": kind, "seed": seed, "train_level": train_level, "ood_level": ood_level}
        traces = {}
        for name, arrays in sets.items():
            w, r, truth = _prepared(model, arrays)
            traces[name] = (w, r, truth, dis.filter_pass(model, w, r, truth, arrays["targets"]))
            for cal in dis.calibration_table(traces[name][3], arrays["noise"]):
                calibration.append({"model": kind, "seed": seed, "set": name, **cal})
        row["mae_train"] = float(traces["train"][3]["abs_err"].mean())
        row["mae_ood"] = float(traces["ood"][3]["abs_err"].mean())
        row["mae_blackout"] = float(traces["blackout"][3]["abs_err"][:, start:stop].mean())
        w, r, truth, _ = traces["blackout"]
        clamped = dis.override_r(r, dis.clamp_frames((*r.shape[:2], k), start, stop), k)
        held = dis.held_variance(traces["blackout"][3]["log_var"], start, stop)
        row["mae_blackout_clamped"] = float(dis.filter_pass(model, w, clamped, truth, sets["blackout"]["targets"],
                                                            log_var=held, float64=True)["abs_err"][:, start:stop].mean())
        fw, fr, ftruth = _prepared(model, fit_set)
        fit_trace = dis.filter_pass(model, fw, fr, ftruth, fit_set["targets"])
        log_a, b = dis.fit_log_linear_r(fit_trace["obs_err2_dims"], fit_set["noise"], max_level=train_level)
        own_scale = dis.r_scale(fit_trace, fr)                              # (k,) E[err^2] / E[r] on validation
        w, r, truth, trace = traces["ood"]
        noise = sets["ood"]["noise"]
        oracle_r = dis.r_from_levels(trace["obs_err2_dims"], noise) / own_scale
        for name, r_new in (("fitted_r", dis.r_from_fit(noise, log_a, b) / own_scale), ("oracle_r", oracle_r)):
            out = dis.filter_pass(model, w, dis.override_r(r, r_new, k), truth, sets["ood"]["targets"],
                                  log_var=trace["log_var"])
            row[f"mae_ood_{name}"] = float(out["abs_err"].mean())
        scale, ratio = dis.calibrate_q_scale(model, fw, fr, ftruth, fit_set["targets"])
        out = dis.filter_pass(model, w, dis.override_r(r, oracle_r, k), truth, sets["ood"]["targets"], q_scale=scale,
                              log_var=trace["log_var"])
        row["mae_ood_oracle_r_q"] = float(out["abs_err"].mean())
        row |= {"fitted_r_slope": float(np.mean(b)), "r_scale_fit": float(np.mean(own_scale)), "q_scale": scale,
                "e2_over_p_fit": ratio,
                "no_dynamics_mae_ood": nd_ood}
        row["failure"] = dis.failure_verdict(row["mae_blackout_clamped"], row["mae_ood_oracle_r"], nd_ood,
                                             row["mae_ood_oracle_r_q"])
        interventions.append(row)
    return pd.DataFrame(calibration), pd.DataFrame(interventions)


# the calibrated-gain screen's rule, written before its runs (docs/dynamics.md)
SCREEN_MIN_SPEARMAN = 0.8
SCREEN_MAE_TIE = 0.05


# a seed whose r does not follow the noise in distribution (the known-dynamics filter's failure, docs/dynamics.md)
FAILED_SEED_SPEARMAN = 0.5


def screen_variants(P, variants, seeds, budget_name: str = "fit", out=None, train_level: float = 0.5,
                    per_seed: bool = False) -> pd.DataFrame:
    """The calibrated-gain screen on VALIDATION data at the training noise only (levels <= ``train_level``;
    never 0.75 or a blackout): per trained (variant, seed) of the protocol ablation (``drfkit.study.ablation``,
    trained if missing) ``dissection.in_distribution_screen``; 'eligible' and 'chosen' by the rule:
    seed means with rho(log r, level) >= SCREEN_MIN_SPEARMAN and gain slope < 0 are eligible, the lowest
    MAE is chosen, MAEs within SCREEN_MAE_TIE of the lowest are a tie broken by the steeper gain slope.
    ``per_seed``: the rows per (variant, seed) instead, with 'failed' (rho < FAILED_SEED_SPEARMAN: a seed whose
    r does not follow the noise, the known-dynamics filter's failure mode)."""
    from drfkit.methods.train import load_checkpoint
    from drfkit.study import ablation
    from drfkit.study.pendulum_runs import load_split

    rows = []
    for variant in variants:
        for seed in seeds:
            res, run = ablation.train_variant(P, variant, seed, budget_name, out, progress=False)
            val = load_split(run.splits, "val", run.noise(train_level))
            model = load_checkpoint(res.best_path)
            w, r, truth = _prepared(model, val)
            trace = dis.filter_pass(model, w, r, truth, val["targets"])
            rows.append({"variant": variant, "seed": seed,
                         **dis.in_distribution_screen(trace, val["noise"], max_level=train_level)})
    table = pd.DataFrame(rows)
    if per_seed:  # each seed's row, and whether its r fails to follow the noise in distribution
        return table.assign(failed=table["r_level_spearman"] < FAILED_SEED_SPEARMAN)
    means = table.groupby("variant", sort=False).mean(numeric_only=True).drop(columns="seed")
    return screen_choice(means.join(table.groupby("variant", sort=False).size().rename("n_seeds"))).reset_index()


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
                w, r, truth = _prepared(model, val)
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


def calibration_summary(calibration: pd.DataFrame) -> pd.DataFrame:
    """Per (model, set): the calibration ratios and the gain over the set's frames, mean over seeds and
    level bins weighted by frames -- the dissection's table in one screen."""
    cols = ["r", "p_prior", "q", "gain", "obs_err2", "prior_err2"]
    weighted = calibration.assign(**{c: calibration[c] * calibration["frames"] for c in cols})
    g = weighted.groupby(["model", "seed", "set"], sort=False)[[*cols, "frames"]].sum()
    per = g[cols].div(g["frames"], axis=0)
    per["err2_over_r"], per["e2_over_p"] = per["obs_err2"] / per["r"], per["prior_err2"] / per["p_prior"]
    return per.groupby(["model", "set"], sort=False)[["gain", "err2_over_r", "e2_over_p", "r", "p_prior", "q"]].mean()


__all__ = ["FAILED_SEED_SPEARMAN", "SCREEN_MAE_TIE", "SCREEN_MIN_SPEARMAN", "calibration_summary", "dissect_filters",
           "restart_check", "screen_choice", "screen_variants"]
