"""The book's figures: every plot the notebooks draw (MAE bars, PICP against MPIW, sweeps,
calibration, blackouts, the regime map, training curves) and what they share: a model's label and
colour, the axis texts of each study, legends. Presentation only: the paper's published numbers
live in ``drfkit.study.paper``; writing a figure to disk is ``drfkit.report.writers.save_figure``."""
from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from drfkit.models.kinds import MODEL_CLASSES, model_spec
from drfkit.study.registry import STUDIES

# How the figures and tables name a series that is no model kind ('physics_reference' is a particle filter on
# no_dynamics' outputs: a reference, not a bound on any model). A model kind's label and colour are its
# spec's (``drfkit.models.spec.ModelSpec``): presentation, not the paper's numbers.
REFERENCE_LABELS = {"physics_reference": "particle filter on no_dynamics (reference)"}


def label(model: str) -> str:
    """A model kind's label, a reference's, or the name itself."""
    return model_spec(model).label if model in MODEL_CLASSES else REFERENCE_LABELS.get(model, model)


def color(model: str) -> str:
    """A model kind's colour; grey for anything else."""
    return model_spec(model).colour if model in MODEL_CLASSES else "gray"


def drawn_in_colour(model: str) -> bool:
    """Whether a line figure draws ``model`` in its colour, solid; a reference (the particle filter, a kind
    whose spec says ``reference``) is drawn dashed in black."""
    return model in MODEL_CLASSES and not model_spec(model).reference


def new_figure(ncols: int = 1, nrows: int = 1, width: float = 4.5, height: float = 3.4, **kw):
    fig, axes = plt.subplots(nrows, ncols, figsize=(width * ncols, height * nrows), squeeze=False, **kw)
    return fig, axes


def paper_value(paper: dict, level: float, model: str) -> float:
    for key, row in paper.items():
        if abs(key - level) < 1e-9:
            return row.get(model, float("nan"))
    return float("nan")


# What a figure says about its axes, from each study's registry entry: the noise parameter it varies
# and the name and unit of its targets (the pendulum's (cos θ, sin θ) are dimensionless, the
# pedestrians' depths in metres).
NOISE_PARAMETER = {name: s.noise_name for name, s in STUDIES.items()}
TARGET_UNIT = {name: s.target_unit for name, s in STUDIES.items()}
TARGET_NAME = {name: s.target_name for name, s in STUDIES.items()}
CI_TEXT = "95 % t-interval over seeds"


def _study_of(frame: pd.DataFrame | None = None, level_name: str | None = None,
              models: list[str] | None = None) -> str | None:
    """Which study a figure shows: the frame's ``study`` column, else the noise's name, else the
    models (Monoloco only in the pedestrian study); None when nothing tells."""
    if frame is not None and "study" in frame and frame["study"].nunique() == 1:
        return str(frame["study"].iloc[0])
    name = (level_name or "").strip().lower()
    if "max noise" in name:
        return "pendulum"
    if name == "p" or "salt" in name:
        return "pedestrians"
    if models and "monoloco" in models:
        return "pedestrians"
    return None


def _noise_name(level_name: str | None, study: str | None) -> str:
    """The noise parameter's full name ("p" alone reads as a dropout rate beside PICP–MPIW)."""
    if study in NOISE_PARAMETER and (level_name or "noise").strip() in ("noise", "p", NOISE_PARAMETER[study]):
        return NOISE_PARAMETER[study]
    return level_name or "test noise"


def _metric_label(metric: str, study: str | None) -> str:
    unit = TARGET_UNIT.get(study, "")
    return {"mae": f"{TARGET_NAME.get(study, '')} MAE {unit}", "mpiw": f"MPIW {unit}",
            "crps": f"CRPS {unit}", "picp": "PICP (%)", "nll": "NLL (nats)",
            "cal_error": "calibration error"}.get(metric, metric.upper()).strip()


def _clipped_err(value, half, lo: float = 0.0, hi: float = np.inf) -> np.ndarray:
    """Asymmetric error bar (2, n) of ``value ± half`` cut to the metric's range [lo, hi]."""
    value = np.asarray(value, dtype=float)
    half = np.nan_to_num(np.asarray(half, dtype=float))
    return np.stack([np.clip(np.minimum(half, value - lo), 0, None), np.clip(np.minimum(half, hi - value), 0, None)])


def _proxy(ax, text: str, **kw) -> None:
    """A legend entry without data (what a whisker, band or number at a point means)."""
    ax.plot([], [], ls=kw.pop("ls", "none"), label=text, **kw)


def _legend(ax, fontsize: float = 7, extra: list | None = None, **kw) -> None:
    handles, labels = ax.get_legend_handles_labels()
    for handle in extra or []:
        handles.append(handle); labels.append(handle.get_label())
    if handles:
        ax.legend(handles, labels, fontsize=fontsize, **kw)


def plot_mae_bars(summary: pd.DataFrame, models: list[str], paper: dict | None = None, ylabel: str = "MAE",
                  level_name: str = "noise", width: float = 6.0, reference: dict | None = None,
                  reference_label: str = "particle filter on no_dynamics (reference)",
                  references: dict[str, dict] | None = None):
    """Grouped bars of seed-mean MAE (95 % interval as error bar) per noise level and model;
    the paper's value as a black tick on each bar; ``reference`` (level -> MAE: e.g. the particle
    filter on no_dynamics' outputs) as a dashed line across each level's group, labelled
    ``reference_label``; ``references`` (label -> {level -> MAE}: estimators that learn nothing, such as the
    limit on pixels) as grey lines of their own style. summary: ``drfkit.study.evaluate.summarise`` by model, noise."""
    fig, axes = new_figure(1, width=width)
    ax = axes[0, 0]
    study = _study_of(summary, level_name, models)
    levels = sorted(summary["noise"].unique())
    w = 0.8 / len(models)
    for i, kind in enumerate(models):
        rows = summary[summary["model"] == kind].set_index("noise").reindex(levels)
        x = np.arange(len(levels)) + i * w
        # an MAE is >= 0: the bar's interval stops there
        ax.bar(x, rows["mae"], w * 0.9, yerr=_clipped_err(rows["mae"], rows["mae_ci"]), color=color(kind),
               label=label(kind))
        if paper:
            ax.scatter(x, [paper_value(paper, lv, kind) for lv in levels], marker="_", s=300, color="black",
                       zorder=3, label="paper's value" if i == 0 else None)
    for j, lv in enumerate(levels):
        value = paper_value({float(k): {"reference": v} for k, v in (reference or {}).items()}, lv, "reference")
        if np.isfinite(value):
            ax.hlines(value, j - w / 2, j + 0.8 - w / 2, colors="black", linestyles="--", lw=1,
                      label=reference_label if j == 0 else None)
    for (text, values), style in zip((references or {}).items(), (":", "-.", (0, (1, 3)), (0, (5, 2, 1, 2)))):
        shown = [(j, values[float(lv)]) for j, lv in enumerate(levels) if np.isfinite(values.get(float(lv), np.nan))]
        for i, (j, value) in enumerate(shown):  # estimators that learn nothing (e.g. the limit on pixels), per level
            ax.hlines(value, j - w / 2, j + 0.8 - w / 2, colors="dimgray", linestyles=style, lw=1.2,
                      label=text if i == 0 else None)
    _proxy(ax, f"whisker: {CI_TEXT}", marker="|", ms=8, color="black")
    ax.set_xticks(np.arange(len(levels)) + 0.4 - w / 2)
    ax.set_xticklabels([f"{level_name} {lv:g}" for lv in levels])
    ax.set_xlabel(f"test {_noise_name(level_name, study)}")
    ax.set_ylabel(_metric_label("mae", study) if ylabel == "MAE" else ylabel)
    _legend(ax)
    return fig


def plot_blackout(curves: pd.DataFrame, frames: tuple[int, int], models: list[str]):
    """MAE per frame (mean over seeds) through a blackout, the blackout frames shaded.
    curves: columns model, seed, frame, mae (``drfkit.study.dynamics.blackout_curves``), and optionally
    protocol: then one panel per protocol (rows without a protocol, such as the reference's, are drawn
    in every panel). A reference (``drawn_in_colour``: the particle filter) is drawn dashed in black."""
    has_protocol = "protocol" in curves
    panels = (list(dict.fromkeys(curves["protocol"].dropna())) if has_protocol else []) or [None]
    fig, axes = new_figure(len(panels), width=6.0 if len(panels) == 1 else 4.2)
    for ax, protocol in zip(axes[0], panels):
        rows = curves if protocol is None else curves[curves["protocol"].isna() | (curves["protocol"] == protocol)]
        ax.axvspan(frames[0] - 0.5, frames[1] - 0.5, color="gray", alpha=0.2,
                   label=f"pure-noise frames {frames[0]}–{frames[1] - 1}")
        for kind in models:
            mean = rows[rows["model"] == kind].groupby("frame")["mae"].mean()
            known = drawn_in_colour(kind)
            ax.plot(mean.index, mean.to_numpy(), color=color(kind) if known else "black", ls="-" if known else "--",
                    label=label(kind))
        ax.set_xlabel("frame"); ax.set_yscale("log")
        ax.set_ylabel("MAE (cos θ, sin θ), log scale")
        if protocol is not None:
            ax.set_title(f"{protocol} protocol")
        _legend(ax)
    if len(panels) > 1:
        lo, hi = zip(*(ax.get_ylim() for ax in axes[0]))
        for ax in axes[0]:
            ax.set_ylim(min(lo), max(hi))
    return fig


def plot_regime(table: pd.DataFrame, models: list[str]):
    """The noise-regime map: one panel per training noise, MAE (seed mean) along the test noise for
    each model and the particle-filter reference (dashed black), the training noise marked; the last
    panel the blackout MAE per training noise. table: ``drfkit.study.regime.regime_map``."""
    trains = sorted(table["train_noise"].unique())
    fig, axes = new_figure(len(trains) + 1, width=3.6)
    sweep = table[table["test_noise"].notna()]
    for ax, tn in zip(axes[0], trains):
        for kind in models + ["physics_reference"]:
            mean = sweep[(sweep["train_noise"] == tn) & (sweep["model"] == kind)].groupby("test_noise")["mae"].mean()
            known = drawn_in_colour(kind)
            ax.plot(mean.index, mean.to_numpy(), marker="o", ms=3, color=color(kind) if known else "black",
                    ls="-" if known else "--", label=label(kind))
        ax.axvline(tn, color="gray", ls=":", lw=1, label=f"training noise ({tn:g})")
        ax.set(title=f"trained at max noise {tn:g}", xlabel="test max noise", yscale="log",
               ylabel="MAE (cos θ, sin θ), log scale")
        _legend(ax, fontsize=6)
    if len(trains) > 1:  # one y-range for the sweep panels: they compare regimes
        lo, hi = zip(*(ax.get_ylim() for ax in axes[0, :len(trains)]))
        for ax in axes[0, :len(trains)]:
            ax.set_ylim(min(lo), max(hi))
    ax, width = axes[0, -1], 0.8 / (len(models) + 1)
    dark = table[table["test"] == "blackout"]
    for i, kind in enumerate(models + ["physics_reference"]):
        mean = dark[dark["model"] == kind].groupby("train_noise")["mae"].mean().reindex(trains)
        known = drawn_in_colour(kind)
        ax.bar(np.arange(len(trains)) + i * width, mean.to_numpy(), width, color=color(kind) if known else "black",
               label=label(kind))
    ax.set_xticks(np.arange(len(trains)) + width * len(models) / 2, [f"{tn:g}" for tn in trains])
    ax.set(title="blackout (15 pure-noise frames)", xlabel="training max noise",
           ylabel="MAE on the blackout (cos θ, sin θ)")
    shown = dark[dark["model"].isin(models + ["physics_reference"])]
    tallest = shown.groupby(["model", "train_noise"])["mae"].mean().max()
    if np.isfinite(tallest) and tallest > 0:
        ax.set_ylim(0, 1.45 * tallest)  # room for the legend above the bars
    _legend(ax, fontsize=6, loc="upper center", ncol=2)
    fig.tight_layout()
    return fig


def plot_picp_mpiw(curves: pd.DataFrame, models: list[str], paper: dict | None = None, per_level_paper: bool = False,
                   level_name: str = "noise", nominal: float = 0.95):
    """PICP (%) against MPIW as the dropout rate varies, one panel per noise level; the dropout
    rate written at each point, error bars (95 % over seeds) cut to PICP's [0, 100] and MPIW >= 0,
    the nominal coverage as a line, one PICP range on every panel.

    curves: ``summarise`` by model, noise, dropout_p. paper: model -> [(mpiw, picp%)] drawn on the
    last panel, or (per_level_paper) level -> model -> points drawn on each panel.
    """
    study = _study_of(curves, level_name, models)
    levels = sorted(curves["noise"].unique())
    fig, axes = new_figure(len(levels))
    lowest = 100 * nominal
    for ax, lv in zip(axes[0], levels):
        drawn = []
        for kind in models:
            rows = curves[(curves["model"] == kind) & np.isclose(curves["noise"], lv)].sort_values("dropout_p")
            picp = 100 * rows["picp"].to_numpy(dtype=float)
            yerr = _clipped_err(picp, 100 * rows["picp_ci"].to_numpy(dtype=float), 0.0, 100.0)
            ax.errorbar(rows["mpiw"], picp, xerr=_clipped_err(rows["mpiw"], rows["mpiw_ci"]), yerr=yerr,
                        marker="o", ms=4, color=color(kind), label=label(kind))
            if kind == models[0]:  # the rates come in the same order along every model's curve
                for x, y, p in zip(rows["mpiw"], picp, rows["dropout_p"]):
                    if np.isfinite(x) and np.isfinite(y) and pd.notna(p):
                        ax.annotate(f"{p:g}", (x, y), xytext=(4, -8), textcoords="offset points", fontsize=6,
                                    color=color(kind))
            drawn += list(picp - yerr[0])
        pts = None
        if paper and per_level_paper:
            pts = next((v for k, v in paper.items() if abs(k - lv) < 1e-9), None)
        elif paper and lv == levels[-1]:
            pts = paper
        shown = [kind for kind in (pts or {}) if kind in models]
        for kind in shown:
            ax.plot(*zip(*pts[kind]), "s--", ms=3, color=color(kind), alpha=0.35,
                    label="the paper's curves (faded)" if kind == shown[0] else None)
            drawn += [y for _, y in pts[kind]]
        ax.axhline(100 * nominal, color="gray", lw=0.8, ls=":", label=f"nominal {100 * nominal:g} %")
        finite = [v for v in drawn if np.isfinite(v)]
        lowest = min([lowest] + finite)
        if finite and min(finite) >= 99.5:
            ax.text(0.03, 0.6, "PICP ≥ 99.5 % at every dropout rate", transform=ax.transAxes, fontsize=7,
                    color="dimgray")
        _proxy(ax, f"numbers at {label(models[0])}: dropout rate")
        _proxy(ax, "whiskers: 95 % over seeds", marker="+", ms=7, color="black")
        ax.set_title(f"{_noise_name(level_name, study)} {lv:g}")
        ax.set_xlabel(_metric_label("mpiw", study)); ax.set_ylabel("PICP (%)")
        _legend(ax, fontsize=5.5, loc="lower right")
    for ax in axes[0]:  # one PICP range on every panel, never beyond what PICP can take
        ax.set_ylim(max(0.0, lowest - 2.0), 101.5)
    return fig


def plot_sweep(summary: pd.DataFrame, models: list[str], train_level: float, metrics=("mae", "picp"),
               xlabel: str = "noise", nominal: float = 0.95):
    """Metrics against test noise level (seed mean and its 95 % t-interval as a band, cut to the
    metric's range), training noise marked; on a PICP panel the nominal coverage as a line."""
    from matplotlib.patches import Patch

    study = _study_of(summary, xlabel, models)
    fig, axes = new_figure(len(metrics))
    for ax, metric in zip(axes[0], metrics):
        scale = 100 if metric == "picp" else 1
        lo_lim, hi_lim = (0.0, 100.0) if metric == "picp" else (-np.inf, np.inf)
        lows = []
        for kind in models:
            rows = summary[summary["model"] == kind].sort_values("noise")
            ax.plot(rows["noise"], scale * rows[metric], "o-", ms=3, color=color(kind), label=label(kind))
            if rows[f"{metric}_ci"].notna().any():
                lo = np.clip(scale * rows[f"{metric}_lo"].to_numpy(dtype=float), lo_lim, hi_lim)
                hi = np.clip(scale * rows[f"{metric}_hi"].to_numpy(dtype=float), lo_lim, hi_lim)
                ax.fill_between(rows["noise"], lo, hi, color=color(kind), alpha=0.15)
                lows += list(lo)
            lows += list(scale * rows[metric].to_numpy(dtype=float))
        ax.axvline(train_level, color="black", lw=0.8, ls="--", label=f"training noise ({train_level:g})")
        if metric == "picp":
            ax.axhline(100 * nominal, color="gray", lw=0.8, ls=":", label=f"nominal coverage {100 * nominal:g} %")
            finite = [v for v in lows if np.isfinite(v)] + [100 * nominal]
            ax.set_ylim(max(0.0, min(finite) - 3.0), 102.0)
        ax.set_xlabel(f"test {_noise_name(xlabel, study)}"); ax.set_ylabel(_metric_label(metric, study))
        _legend(ax, extra=[Patch(color="gray", alpha=0.3, label=f"band: {CI_TEXT}")])
    fig.subplots_adjust(wspace=0.3)  # room for every panel's y-label
    return fig


def plot_calibration(points: pd.DataFrame, models: list[str], level_name: str | None = None):
    """Observed against expected quantile coverage (Kuleshov et al. 2018), one panel per noise level.
    points: columns model, noise, expected, observed (seed-averaged), and study (which names the
    noise parameter in the titles; ``level_name`` overrides it)."""
    noise = _noise_name(level_name, _study_of(points, level_name, models))
    levels = sorted(points["noise"].unique())
    fig, axes = new_figure(len(levels), width=3.6)
    for ax, lv in zip(axes[0], levels):
        ax.plot([0, 1], [0, 1], color="gray", lw=0.8, ls=":", label="perfect calibration")
        for kind in models:
            rows = points[(points["model"] == kind) & np.isclose(points["noise"], lv)].sort_values("expected")
            ax.plot(rows["expected"], rows["observed"], "o-", ms=3, color=color(kind), label=label(kind))
        ax.set_title(f"{noise} {lv:g}")
        ax.set_xlabel("expected quantile level"); ax.set_ylabel("observed fraction below the quantile")
        ax.set_xlim(0, 1); ax.set_ylim(0, 1)
        _legend(ax)
    fig.subplots_adjust(wspace=0.35)  # room for every panel's y-label
    return fig


def _selection_metric(run: pd.DataFrame) -> str:
    """What selected a run's checkpoint (as ``drfkit.methods.train.selection_audit`` reads it)."""
    return "val_l1" if "val_l1" in run and run["val_l1"].notna().all() else "val_loss"


def plot_training_curves(curves: pd.DataFrame, models: list[str] | None = None, focus: bool = True):
    """Training curves of a study, two panels, one line per (model, seed), the epoch of each run's
    kept checkpoint (the first minimum of what selected it, as ``drfkit.methods.train.selection_audit``)
    marked by a star. Runs all selected on validation NLL (the pendulum): training and validation
    NLL; some on validation L1 (Monoloco, the pedestrians): the NLL runs' validation NLL and the
    L1 runs' validation L1 (m). ``focus``: the y-range spans the selection region (the lowest value
    to a margin above the marked ones) instead of the first epochs' losses.
    curves: ``drfkit.methods.train.history_frame`` rows with model and seed columns."""
    models = models or list(dict.fromkeys(curves["model"]))
    runs = [(kind, seed, run.sort_values("epoch"))
            for (kind, seed), run in curves.groupby(["model", "seed"], sort=False) if kind in models]
    on_l1 = {(kind, seed): _selection_metric(run) == "val_l1" for kind, seed, run in runs}
    if any(on_l1.values()):
        l1_kinds = ", ".join(label(k) for k in dict.fromkeys(kind for (kind, _), on in on_l1.items() if on))
        panels = [("val_loss", False, "validation NLL (nats)", "validation Gaussian NLL: selects the checkpoint"),
                  ("val_l1", True, "validation L1 of μ (m)", f"validation L1: selects {l1_kinds}'s checkpoint")]
    else:
        panels = [("train_loss", None, "training loss (NLL, nats)", "training NLL"),
                  ("val_loss", None, "validation NLL (nats)", "validation NLL: selects the checkpoint")]
    first_seed = {kind: min(seed for k, seed, _ in runs if k == kind) for kind in {k for k, _, _ in runs}}
    fig, axes = new_figure(2)
    for ax, (column, l1_runs, ylabel, title) in zip(axes[0], panels):
        values, marked, starred = [], [], False
        for kind, seed, run in runs:
            if l1_runs is not None and on_l1[(kind, seed)] != l1_runs:
                continue
            y = run[column].to_numpy(dtype=float)
            best = int(np.nanargmin(run[_selection_metric(run)].to_numpy(dtype=float)))
            ax.plot(run["epoch"], y, color=color(kind), alpha=0.7, lw=1,
                    label=label(kind) if seed == first_seed[kind] else None)
            ax.plot([run["epoch"].iloc[best]], [y[best]], ls="none", marker="*", ms=9, color=color(kind),
                    mec="black", mew=0.5, zorder=4,
                    label=None if starred else ("best epoch (kept)" if column != "train_loss"
                                                else "kept epoch (best on validation)"))
            starred = True
            values += list(y[np.isfinite(y)]); marked.append(y[best])
        if focus and values:
            low, top = min(values), max(marked)
            pad = max(top - low, 0.05 * max(abs(low), abs(top)), 1e-3)
            ax.set_ylim(low - pad, top + 3 * pad)
            if max(values) > top + 3 * pad:
                _proxy(ax, "y cut to the selection region")
        ax.set_title(title, fontsize=9); ax.set_xlabel("epoch"); ax.set_ylabel(ylabel)
        _legend(ax, fontsize=6.5)
    fig.tight_layout()
    return fig


__all__ = [
    "REFERENCE_LABELS", "label", "color", "drawn_in_colour", "new_figure", "paper_value", "NOISE_PARAMETER", "TARGET_UNIT",
    "CI_TEXT", "plot_mae_bars", "plot_blackout", "plot_regime", "plot_picp_mpiw", "plot_sweep", "plot_calibration",
    "plot_training_curves",
]


GATING_METHODS = {"kalman_gain": ("Kalman-gain gating", "tab:blue", "-"), "random": ("random gating", "tab:gray", "--"),
                  "oracle": ("oracle (frames of largest true error)", "black", ":")}


def _seed_band(frame: pd.DataFrame, value: str) -> pd.DataFrame:
    """Per val_fraction: mean fraction, mean ``value`` and the half-width of its 95 % t-interval over seeds."""
    from drfkit.core.metrics import t975

    stats = frame.groupby("val_fraction").agg(fraction=("fraction", "mean"), mean=(value, "mean"), sd=(value, "std"),
                                              n=(value, "size")).sort_index()
    stats["half"] = [t975(int(n) - 1) * sd / np.sqrt(n) if n > 1 else np.nan for n, sd in zip(stats["n"], stats["sd"])]
    return stats


def plot_gating_fractions(sweep: pd.DataFrame, groups: list[tuple[str, str]] | None = None):
    """Threshold-free gating, one column per (study, protocol): top, PICP against the fraction of test
    frames given MC dropout for the Kalman-gain gate, random gating and an oracle selecting as many
    frames (those of largest true error; when the sweep has it); bottom, each gate's PICP minus random
    gating's at the same fraction, paired by seed (what claim C7 judges). Seed means, 95 % t-interval
    over seeds as a band. sweep: ``drfkit.study.gating_study`` sweep rows (study, protocol, method,
    seed, val_fraction, fraction, picp)."""
    groups = groups or list(dict.fromkeys(zip(sweep["study"], sweep["protocol"])))
    fig, axes = new_figure(len(groups), 2, width=3.8, height=3.0)
    for col, (study, protocol) in enumerate(groups):
        part = sweep[(sweep["study"] == study) & (sweep["protocol"] == protocol)]
        wide = part.pivot_table(index=["seed", "val_fraction"], columns="method", values="picp")
        for method, (name, colour, ls) in GATING_METHODS.items():
            rows = part[part["method"] == method]
            if rows.empty:
                continue
            for row, stats in enumerate((_seed_band(rows, "picp"), _seed_band(rows.merge(
                    (wide[method] - wide["random"]).rename("gain").reset_index(), on=["seed", "val_fraction"]), "gain"))):
                if row == 1 and method == "random":
                    continue
                ax = axes[row, col]
                x, y, h = 100 * stats["fraction"], 100 * stats["mean"], 100 * np.nan_to_num(stats["half"])
                ax.plot(x, y, ls=ls, marker="o", ms=2.5, color=colour, label=name)
                ax.fill_between(x, y - h, y + h, color=colour, alpha=0.15, lw=0)
        axes[0, col].set(title=f"{study}, {protocol} protocol", ylabel="PICP (%)")
        axes[1, col].axhline(0, color="gray", lw=0.8)
        axes[1, col].set(xlabel="frames given MC dropout (%)", ylabel="PICP − random gating's (points)")
        for ax in axes[:, col]:
            _proxy(ax, f"band: {CI_TEXT}", marker="s", ms=6, color="lightgray")
            _legend(ax, fontsize=6)
    fig.tight_layout()
    return fig


LIMIT_ESTIMATORS = {"pixel_pf": ("particle filter on pixels, level marginalised (the limit)", "black", "-"),
                    "pixel_pf_known_level": ("particle filter on pixels, level known", "gray", ":"),
                    "per_frame_bayes": ("per-frame Bayes on pixels", "tab:brown", "--"),
                    "template_matching": ("per-frame template matching", "tab:olive", "-.")}


def plot_pixel_limit(limit: pd.DataFrame, models: dict[str, dict[str, float]] | None = None, width: float = 6.5):
    """MAE (log scale) per test set of the estimators that know the observation model (``limit``: rows
    noise, estimator, mae from ``drfkit.study.dynamics.pixel_limit``) and, as markers, learned models'
    MAE on the same sets (``models``: label or kind -> {set: mae})."""
    fig, axes = new_figure(1, width=width)
    ax = axes[0, 0]
    sets = list(dict.fromkeys(limit["noise"].astype(str)))
    x = np.arange(len(sets))
    for name, (text, col, style) in LIMIT_ESTIMATORS.items():
        rows = limit[limit["estimator"] == name].assign(noise=lambda d: d["noise"].astype(str)).set_index("noise")
        if len(rows):
            ax.plot(x, rows["mae"].reindex(sets), style, color=col, marker="o", ms=3, label=text)
    for i, (kind, values) in enumerate((models or {}).items()):
        ax.scatter(x + 0.06 * (i - len(models) / 2), [values.get(s, np.nan) for s in sets], color=color(kind),
                   marker="s", s=22, zorder=3, label=label(kind))
    ax.set_yscale("log")
    ax.set_xticks(x)
    ax.set_xticklabels([s if s in ("clean", "blackout") else f"max noise {s}" for s in sets])
    ax.set_ylabel("MAE (cos θ, sin θ)")
    ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    return fig
