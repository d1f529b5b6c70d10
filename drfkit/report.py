"""Writing what a run produces: tables (CSV) and figures (PNG) under results/<profile>/,
always atomically, plus the small plotting helpers the notebooks share."""
from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from drfkit.io import atomic_savefig, atomic_write_csv
from drfkit.paper import MODEL_COLORS, MODEL_LABELS
from drfkit.paths import figures_dir, tables_dir


def save_table(profile: str, name: str, frame: pd.DataFrame) -> Path:
    """Write ``results/<profile>/tables/<name>.csv`` atomically and return its path."""
    return atomic_write_csv(tables_dir(profile) / f"{name}.csv", frame)


def save_figure(profile: str, name: str, fig) -> Path:
    """Write ``results/<profile>/figures/<name>.png`` atomically and return its path."""
    return atomic_savefig(figures_dir(profile) / f"{name}.png", fig)


def label(model: str) -> str:
    return MODEL_LABELS.get(model, model)


def color(model: str) -> str:
    return MODEL_COLORS.get(model, "gray")


def new_figure(ncols: int = 1, nrows: int = 1, width: float = 4.5, height: float = 3.4, **kw):
    fig, axes = plt.subplots(nrows, ncols, figsize=(width * ncols, height * nrows), squeeze=False, **kw)
    return fig, axes


def _paper_value(paper: dict, level: float, model: str) -> float:
    for key, row in paper.items():
        if abs(key - level) < 1e-9:
            return row.get(model, float("nan"))
    return float("nan")


# What a figure says about its axes: the noise parameter each study varies and the unit of its
# targets (the pendulum's (cos θ, sin θ) are dimensionless, the pedestrians' depths in metres).
NOISE_PARAMETER = {"pendulum": "max noise", "pedestrians": "salt-and-pepper p"}
TARGET_UNIT = {"pendulum": "(cos θ, sin θ)", "pedestrians": "(m)"}
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
    return {"mae": f"{'depth ' if study == 'pedestrians' else ''}MAE {unit}", "mpiw": f"MPIW {unit}",
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
                  level_name: str = "noise", width: float = 6.0, bound: dict | None = None,
                  bound_label: str = "true-physics bound"):
    """Grouped bars of seed-mean MAE (95 % interval as error bar) per noise level and model;
    the paper's value as a black tick on each bar; ``bound`` (level -> MAE) as a dashed line
    across each level's group. summary: ``drfkit.evaluate.summarise`` by model, noise."""
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
            ax.scatter(x, [_paper_value(paper, lv, kind) for lv in levels], marker="_", s=300, color="black",
                       zorder=3, label="paper's value" if i == 0 else None)
    for j, lv in enumerate(levels):
        value = _paper_value({float(k): {"bound": v} for k, v in (bound or {}).items()}, lv, "bound")
        if np.isfinite(value):
            ax.hlines(value, j - w / 2, j + 0.8 - w / 2, colors="black", linestyles="--", lw=1,
                      label=bound_label if j == 0 else None)
    _proxy(ax, f"whisker: {CI_TEXT}", marker="|", ms=8, color="black")
    ax.set_xticks(np.arange(len(levels)) + 0.4 - w / 2)
    ax.set_xticklabels([f"{level_name} {lv:g}" for lv in levels])
    ax.set_xlabel(f"test {_noise_name(level_name, study)}")
    ax.set_ylabel(_metric_label("mae", study) if ylabel == "MAE" else ylabel)
    _legend(ax)
    return fig


def plot_blackout(curves: pd.DataFrame, frames: tuple[int, int], models: list[str]):
    """MAE per frame (mean over seeds) through a blackout, the blackout frames shaded.
    curves: columns model, seed, frame, mae (``drfkit.dynamics.blackout_curves``), and optionally
    protocol: then one panel per protocol (rows without a protocol, such as the bound's, are drawn
    in every panel). A model absent from MODEL_COLORS (the bound) is drawn dashed in black."""
    has_protocol = "protocol" in curves
    panels = (list(dict.fromkeys(curves["protocol"].dropna())) if has_protocol else []) or [None]
    fig, axes = new_figure(len(panels), width=6.0 if len(panels) == 1 else 4.2)
    for ax, protocol in zip(axes[0], panels):
        rows = curves if protocol is None else curves[curves["protocol"].isna() | (curves["protocol"] == protocol)]
        ax.axvspan(frames[0] - 0.5, frames[1] - 0.5, color="gray", alpha=0.2,
                   label=f"pure-noise frames {frames[0]}–{frames[1] - 1}")
        for kind in models:
            mean = rows[rows["model"] == kind].groupby("frame")["mae"].mean()
            known = kind in MODEL_COLORS
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
    each model and the true-physics bound (dashed black), the training noise marked; the last
    panel the blackout MAE per training noise. table: ``drfkit.regime.regime_map``."""
    trains = sorted(table["train_noise"].unique())
    fig, axes = new_figure(len(trains) + 1, width=3.6)
    sweep = table[table["test_noise"].notna()]
    for ax, tn in zip(axes[0], trains):
        for kind in models + ["physics_bound"]:
            mean = sweep[(sweep["train_noise"] == tn) & (sweep["model"] == kind)].groupby("test_noise")["mae"].mean()
            known = kind in MODEL_COLORS
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
    for i, kind in enumerate(models + ["physics_bound"]):
        mean = dark[dark["model"] == kind].groupby("train_noise")["mae"].mean().reindex(trains)
        known = kind in MODEL_COLORS
        ax.bar(np.arange(len(trains)) + i * width, mean.to_numpy(), width, color=color(kind) if known else "black",
               label=label(kind))
    ax.set_xticks(np.arange(len(trains)) + width * len(models) / 2, [f"{tn:g}" for tn in trains])
    ax.set(title="blackout (15 pure-noise frames)", xlabel="training max noise",
           ylabel="MAE on the blackout (cos θ, sin θ)")
    shown = dark[dark["model"].isin(models + ["physics_bound"])]
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
    """What selected a run's checkpoint (as ``drfkit.train.selection_audit`` reads it)."""
    return "val_l1" if "val_l1" in run and run["val_l1"].notna().all() else "val_loss"


def plot_training_curves(curves: pd.DataFrame, models: list[str] | None = None, focus: bool = True):
    """Training curves of a study, two panels, one line per (model, seed), the epoch of each run's
    kept checkpoint (the first minimum of what selected it, as ``drfkit.train.selection_audit``)
    marked by a star. Runs all selected on validation NLL (the pendulum): training and validation
    NLL; some on validation L1 (Monoloco, the pedestrians): the NLL runs' validation NLL and the
    L1 runs' validation L1 (m). ``focus``: the y-range spans the selection region (the lowest value
    to a margin above the marked ones) instead of the first epochs' losses.
    curves: ``drfkit.train.history_frame`` rows with model and seed columns."""
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


README_START, README_END = "<!-- results:start -->", "<!-- results:end -->"
HEADLINE_FIGURES = [
    ("pendulum_mae", "Pendulum MAE at max noise 0.5 and 0.75 (paper values as black ticks)"),
    ("pendulum_picp_mpiw", "Pendulum PICP against MPIW as the dropout rate varies"),
    ("pedestrians_mae", "Pedestrian depth MAE with Monoloco at p = 0.01, 0.025, 0.05"),
    ("pedestrians_picp_mpiw", "Pedestrian PICP against MPIW at the three noise levels"),
    ("pendulum_sweep", "Pendulum: MAE, PICP and NLL along the noise sweep"),
    ("pedestrians_sweep", "Pedestrians: MAE, PICP and NLL along the noise sweep"),
    ("pendulum_book_mae", "Pendulum MAE of the book's training protocol (the DRF's filter checked to filter)"),
    ("pendulum_blackout", "Pendulum: MAE per frame through 15 pure-noise frames, with the true-physics bound"),
    ("pendulum_blackout_protocols", "Pendulum blackout under the paper's and the book's protocol, with the "
                                    "true-physics bound"),
    ("pendulum_mae_with_bound", "Pendulum MAE (paper's protocol) beside the true-physics bound and the paper's "
                                "values (black ticks)"),
    ("pendulum_regime_map", "Noise-regime map: MAE along the test noise for each training noise, and on the blackout"),
]


def epoch_times_line(epochs: pd.DataFrame) -> str:
    """One sentence of a ``drfkit.timing.epoch_times`` table (notebook 01); the first row is the base."""
    base = epochs["model"].iloc[0]
    rows = epochs.set_index("model")
    others = [f"{model} **{row[f'ratio_to_{base}']:.2f}×** (IQR {row[f'ratio_to_{base}_iqr']:.2f}; "
              f"{row['epoch_median_s']:.3g} s)" for model, row in rows.iloc[1:].iterrows()]
    return (f"Whole training epochs in notebook 01 (the training loop itself, validation and checkpoints "
            f"included, {int(rows['rounds'].iloc[0])} interleaved rounds, {int(rows['threads'].iloc[0])} torch "
            f"thread(s), {int(rows['sequences'].iloc[0])} sequences): against a {base} epoch of "
            f"{rows.loc[base, 'epoch_median_s']:.3g} s, " + ", ".join(others) + "; target ≤ 1.5× for the DRF "
            "(`tables/pendulum_epoch_times.csv`).")


def recursion_scaling_line(scaling: pd.DataFrame) -> str:
    """One sentence per thread count of a ``drfkit.timing.recursion_scaling`` table (notebook 01)."""
    parts = []
    for threads, rows in scaling.groupby("threads"):
        step = rows[(rows["model"] == "drf") & (rows["part"] == "step")].iloc[0]
        rec = rows[(rows["part"] == "recursion") & (rows["batch"] == step["batch"])].iloc[0]
        parts.append(f"at {int(threads)} thread(s) the recursion takes {1e3 * rec['median_s']:.0f} ms at batch "
                     f"{int(step['batch'])}, {1e3 * step['fixed_s']:.0f} ms of it per-call cost (the intercept of its "
                     f"time against the batch), and without that cost the DRF step would cost "
                     f"**{step['floor_ratio']:.2f}×** a no_dynamics step instead of {step['ratio']:.2f}× (the step ratio timed in "
                     f"this same run; the training-speed line times steps in a separate run)")
    return ("Per-call cost or arithmetic, in notebook 01 (the recursion alone at half, one and two times the batch, "
            "in one run with both training steps): " + "; ".join(parts)
            + " (`tables/pendulum_recursion_scaling.csv`, `figures/pendulum_recursion_scaling.png`).")


def dynamics_lines(tables: Path) -> list[str]:
    """README lines of the dynamics study (notebook 01): both protocols beside the true-physics
    bound, and the protocol ablation on validation data; [] when notebook 01 has not written them."""
    lines: list[str] = []
    protocols, bound = tables / "pendulum_protocols.csv", tables / "pendulum_physics_bound.csv"
    if protocols.exists() and bound.exists():
        pt = pd.read_csv(protocols)
        mae_cols = [c for c in pt if c.startswith("mae_") and c != "mae_after_blackout"]
        mean = pt.groupby(["protocol", "model"], sort=False).mean(numeric_only=True)
        b = pd.read_csv(bound).groupby("noise")["mae"].mean()
        lines += ["Does the filter filter? Test MAE (MC dropout mean, seed means) of each protocol's models beside "
                  "the true-physics bound (a particle filter with the generator's equations on no_dynamics' "
                  "per-frame estimates: knowledge no learned model has), and the DRF's mechanism checks "
                  "(`tables/pendulum_protocols.csv`, `tables/pendulum_physics_bound.csv`, notebook 01):", "",
                  "| protocol | model | " + " | ".join(c.replace("mae_", "MAE ") for c in mae_cols)
                  + " | rank corr(r, noise) | gain pure / clean | ‖Fz − w‖ / ‖z − w‖ |",
                  "|---|---|" + "---|" * (len(mae_cols) + 3)]
        fmt = lambda v, d=4: "" if pd.isna(v) else f"{v:.{d}f}"  # noqa: E731
        for (protocol, model), r in mean.iterrows():
            lines.append(f"| {protocol} | {label(model)} | " + " | ".join(fmt(r[c]) for c in mae_cols) + " | "
                         + " | ".join(fmt(r.get(c), 2) for c in ("r_noise_spearman", "gain_ratio_blackout", "prior_ratio"))
                         + " |")
        # the bound's noise column holds levels and 'blackout': name them as the protocol table's columns
        bound_of = {("mae_blackout" if k == "blackout" else f"mae_{float(k):g}"): v for k, v in b.items()}
        lines += ["| — | true-physics bound | " + " | ".join(fmt(bound_of.get(c)) for c in mae_cols) + " | | | |", ""]
    ablation = tables / "pendulum_ablation.csv"
    if ablation.exists():
        from drfkit.ablation import summarise_ablation

        raw = pd.read_csv(ablation)
        ab = summarise_ablation(raw)
        budgets = ", ".join(sorted(raw["budget"].astype(str).unique()))
        lines += [f"Protocol ablation on **validation** data (`tables/pendulum_ablation.csv`; budget {budgets} of "
                  "`drfkit.protocols.ABLATION_BUDGETS`, `python -m drfkit.ablation`), sorted by blackout MAE:", "",
                  "| variant | model | seeds | MAE 0.5 | MAE 0.75 | MAE 1.0 | MAE blackout | rank corr(r, noise) "
                  "| gain pure / clean | ‖Fz − w‖ / ‖z − w‖ |", "|---|---|---|---|---|---|---|---|---|---|"]
        for _, r in ab.iterrows():
            cells = [r.get(k) for k in ("mae_0.5", "mae_0.75", "mae_1", "mae_blackout", "r_noise_spearman",
                                        "gain_ratio_blackout", "prior_ratio")]
            lines.append(f"| {r['variant']} | {label(r['kind'])} | {r['n_seeds']} | "
                         + " | ".join("" if v is None or pd.isna(v) else f"{v:.3g}" for v in cells) + " |")
        lines.append("")
    regime = tables / "pendulum_regime_summary.csv"
    if regime.exists():
        rg = pd.read_csv(regime)
        lines += ["Noise-regime map (the book's protocol trained at each max noise on the ablation's budget; MAE on "
                  "the map's own **test** split, seed means; `tables/pendulum_regime_summary.csv`, "
                  "`python -m drfkit.regime`): DRF against no_dynamics (< 1: the filter helps) and against the "
                  "true-physics bound:", "",
                  "| trained at | test | DRF | LSTM | no_dynamics | bound | DRF / no_dynamics | DRF / bound |",
                  "|---|---|---|---|---|---|---|---|"]
        for r in rg.itertuples():
            lines.append(f"| {r.train_noise:g} | {r.test} | {r.drf:.4f} | {r.lstm:.4f} | {r.no_dynamics:.4f} | "
                         f"{r.physics_bound:.4f} | {r.drf_over_no_dynamics:.2f} | {r.drf_over_bound:.2f} |")
        lines.append("")
    return lines


# the README shows these, in this order; report.md all of HEADLINE_FIGURES
README_FIGURES = ("pendulum_mae_with_bound", "pendulum_blackout_protocols", "pedestrians_mae")


def claims_summary_table(claims_csv: Path) -> list[str]:
    """The README's short claims table from ``claims.csv``: one row per claim (id, claim, the paper's
    number) and a verdict per protocol when there is more than one ("—" where a claim is judged
    under one protocol only); report.md and claims.md hold ours and the rules."""
    from drfkit.claims import CLAIM_EVIDENCE, PEDESTRIAN_CLAIMS, evidence_links, read_claims
    from drfkit.paths import REPO_ROOT

    c = read_claims(claims_csv)
    try:
        prefix = Path(claims_csv).resolve().parent.relative_to(REPO_ROOT).as_posix() + "/"
    except ValueError:  # a profile outside the repository: links relative to its results folder
        prefix = ""
    protocols = list(dict.fromkeys(c["protocol"]))
    verdict_cols = [f"verdict, {p} protocol" for p in protocols] if len(protocols) > 1 else ["verdict"]
    head = ["id", "claim", "paper"] + verdict_cols + ["judged in"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for cid, rows in c.groupby("id", sort=False):
        by_protocol = dict(zip(rows["protocol"], rows["verdict"]))
        first = rows.iloc[0]
        sim = " (simulated source)" if cid in PEDESTRIAN_CLAIMS else ""
        verdicts = [f"**{by_protocol[p]}**{sim}" if p in by_protocol else "—" for p in protocols]
        cells = [cid, first["claim"], first["paper"]] + verdicts
        lines.append("| " + " | ".join(str(x).replace("|", "/") for x in cells) + " | "
                     + (evidence_links(cid, prefix) if cid in CLAIM_EVIDENCE else "") + " |")
    if len(protocols) > 1:
        lines += ["", "— : the claim is judged under the paper's protocol only (the book's protocol changes "
                      "only the pendulum models)."]
    return lines


def readme_section(profile: str, command: str) -> str:
    """The README's short results section: where the run came from, the verdicts, the two
    headline figures and a link to ``results/<profile>/report.md`` (``results_section``)."""
    from drfkit.paths import REPO_ROOT, results_dir

    root = results_dir(profile)
    if not (root / "claims.csv").exists():
        return f"No results for profile `{profile}` yet: run `{command}`.\n"
    full = results_section(profile, command, link_figures=True)
    lines = [full.split("\n", 2)[0], "",  # the provenance line
             f"Every number, the rules behind each verdict, the training cost, the speed measurements and the "
             f"dynamics tables: [results/{profile}/report.md](results/{profile}/report.md) (written with this "
             f"section by `python -m drfkit.report --profiles {profile}`).", ""]
    lines += claims_summary_table(root / "claims.csv") + [""]
    captions = dict(HEADLINE_FIGURES)
    for name in README_FIGURES:
        png, caption = root / "figures" / f"{name}.png", captions[name]
        if png.exists():
            lines += [f"![{caption}]({png.relative_to(REPO_ROOT)})", f"*{caption}* (`{command}`)", ""]
    return "\n".join(lines)


def write_report(profile: str, command: str) -> Path:
    """``results/<profile>/report.md``: the whole generated results section, figures included."""
    from drfkit.io import atomic_write_text
    from drfkit.paths import results_dir

    path = results_dir(profile) / "report.md"
    body = results_section(profile, command, link_figures=True).replace("](results/", "](../../results/")
    atomic_write_text(path, f"# Results of profile `{profile}`\n\nGenerated by `python -m drfkit.report "
                            f"--profiles {profile}`; never edit by hand.\n\n{body}\n")
    return path


def results_section(profile: str, command: str, link_figures: bool) -> str:
    """The whole results section for ``profile``, built from its claims.md and manifest."""
    import json

    from drfkit.paths import REPO_ROOT, results_dir

    root = results_dir(profile)
    claims = root / "claims.md"
    if not claims.exists():
        return f"No results for profile `{profile}` yet: run `{command}`.\n"
    manifest = json.loads((root / "manifest.json").read_text()) if (root / "manifest.json").exists() else {}
    pipe = manifest.get("pipeline", {})
    env = manifest.get("environment", {})
    overrides = manifest.get("overrides") or {}
    last_run = (f"last pipeline run: {', '.join(pipe.get('notebooks', [])) or 'n/a'}"
                + (f" with --set {' '.join(f'{k}={v}' for k, v in overrides.items())}" if overrides else "")
                + f", status {pipe.get('status', 'n/a')}"
                + (f", {pipe['total_s']} s" if pipe.get("total_s") is not None else "")
                + (f": {pipe['note']}" if pipe.get("note") else ""))
    lines = [f"Profile `{profile}`, produced by `{command}` "
             f"({last_run}, on {env.get('cpu', '?')} with {env.get('torch_threads', '?')} torch threads, git "
             f"{(env.get('git') or {}).get('commit', '?')}).",
             "Notebooks run for this profile so far: " + ", ".join(
                 f"{name} ({entry.get('status', '?')})" for name, entry in sorted(manifest.get("notebooks", {}).items()))
             + ".", ""]
    table = claims.read_text().split("\n", 4)[-1]  # drop the title lines
    lines += [table.strip(), ""]
    budget = root / "training_budget.csv"
    if budget.exists():
        b = pd.read_csv(budget)
        if "hours_left" not in b:  # written before the column existed
            b["epochs_done"], b["hours_left"] = 0, b["hours"]
        if "step_ratio" not in b:  # written before models were timed together
            b["step_ratio"], b["ratio_to"] = np.nan, ""
        if "flop_ratio" not in b:  # written before steps were counted
            b["flop_ratio"] = np.nan
        lines += [f"Training cost of this profile on this machine, measured by `python -m drfkit.budget --profile "
                  f"{profile}` (one training step per model, scaled by batches, epochs and seeds, "
                  f"{int(b['threads'].iloc[0])} torch thread(s); models sharing batches timed in interleaved rounds, "
                  f"the step ratio is the median of per-round ratios, the FLOP ratio that of the step's counted "
                  f"matrix products and convolutions): **{b['hours'].sum():.1f} hours** in all, "
                  f"**{b['hours_left'].sum():.1f} hours left** after the epochs already in `results/{profile}/models/`.",
                  "", "| study | model | s / epoch | step ratio | FLOP ratio | epochs × seeds | epochs done | hours "
                  "| hours left |", "|---|---|---|---|---|---|---|---|---|"]
        lines += [f"| {r.study} | {r.model} | {r.epoch_s:.3g} | "
                  + (f"{r.step_ratio:.2f}× {r.ratio_to}" if pd.notna(r.step_ratio) else "") + " | "
                  + (f"{r.flop_ratio:.2f}×" if pd.notna(r.flop_ratio) else "") + " | "
                  f"{r.epochs} × {r.seeds} | {r.epochs_done} | {r.hours:.2f} | {r.hours_left:.2f} |"
                  for r in b.itertuples()]
        lines.append("")
    speed = root / "tables" / "pendulum_training_speed.csv"
    if speed.exists():
        sp = pd.read_csv(speed).set_index("model")
        if {"drf", "no_dynamics"} <= set(sp.index) and "ratio_to_no_dynamics" in sp:
            drf, nd = sp.loc["drf"], sp.loc["no_dynamics"]
            notes = [f"per-round IQR {drf['ratio_to_no_dynamics_iqr']:.2f}"] if "ratio_to_no_dynamics_iqr" in sp else []
            notes += [f"{drf['step_median_s']:.3g} s against {nd['step_median_s']:.3g} s", "target ≤ 1.5×"]
            if "drf_per_step" in sp.index:
                notes.append(f"{sp.loc['drf_per_step', 'ratio_to_no_dynamics']:.2f}× when autograd differentiates "
                             f"the filter step by step instead of the one-node recursion")
            if "flop_ratio_to_no_dynamics" in sp:
                notes.append(f"its counted arithmetic is {drf['flop_ratio_to_no_dynamics']:.2f}× a no_dynamics step's "
                             f"({drf['gflop']:.3g} against {nd['gflop']:.3g} GFLOP of matrix products and "
                             f"convolutions), run at {drf['gflop_per_s'] / nd['gflop_per_s']:.2f}× its rate")
            lines += [f"Pendulum training speed in notebook 01 (one run, {int(sp['threads'].iloc[0])} torch "
                      f"thread(s), batch {int(sp['batch'].iloc[0])} × {int(sp['frames'].iloc[0])} frames): a DRF step "
                      f"costs **{drf['ratio_to_no_dynamics']:.2f}×** a no_dynamics step ("
                      + "; ".join(notes) + "; `tables/pendulum_training_speed.csv`).", ""]
    lines += dynamics_lines(root / "tables")
    epochs = root / "tables" / "pendulum_epoch_times.csv"
    if epochs.exists():
        lines += [epoch_times_line(pd.read_csv(epochs)), ""]
    scaling = root / "tables" / "pendulum_recursion_scaling.csv"
    if scaling.exists():
        lines += [recursion_scaling_line(pd.read_csv(scaling)), ""]
    if link_figures:
        for name, caption in HEADLINE_FIGURES:
            png = root / "figures" / f"{name}.png"
            if png.exists():
                lines += [f"![{caption}]({png.relative_to(REPO_ROOT)})", f"*{caption}* (`{command}`)", ""]
    return "\n".join(lines)


def update_readme(sections: list[tuple[str, str, bool]]) -> None:
    """Replace the README text between the results markers by the sections of
    (profile, command, link_figures)."""
    from drfkit.io import atomic_write_text
    from drfkit.paths import REPO_ROOT

    path = REPO_ROOT / "README.md"
    text = path.read_text()
    if README_START not in text or README_END not in text:
        raise ValueError(f"README.md lacks the markers {README_START} ... {README_END}")
    body = "\n".join(readme_section(profile, command) for profile, command, _ in sections)
    for profile, command, _ in sections:
        if (REPO_ROOT / "results" / profile / "claims.md").exists():
            write_report(profile, command)
    head, rest = text.split(README_START, 1)
    tail = rest.split(README_END, 1)[1]
    atomic_write_text(path, f"{head}{README_START}\n{body}\n{README_END}{tail}")


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser(description="Regenerate the README's results section from results/.")
    ap.add_argument("--profiles", nargs="+", default=["paper"])
    args = ap.parse_args()
    update_readme([(p, "make reproduce" if p == "paper" else f"make reproduce PROFILE={p}", p == "paper")
                   for p in args.profiles])


def paper_comparison(summary: pd.DataFrame, paper: dict, metric: str = "mae") -> pd.DataFrame:
    """Ours next to the paper's value for every (model, noise) the paper reports.

    summary: ``drfkit.evaluate.summarise`` by model, noise; paper: noise -> model -> value.
    Columns: model, noise, ours, ours_ci (95 % half-width over seeds), paper, ours_over_paper.
    """
    rows = []
    for r in summary.itertuples():
        ref = _paper_value(paper, r.noise, r.model)
        if np.isnan(ref):
            continue
        ours = getattr(r, metric)
        rows.append({"model": r.model, "noise": r.noise, "ours": ours, "ours_ci": getattr(r, f"{metric}_ci"),
                     "paper": ref, "ours_over_paper": ours / ref})
    return pd.DataFrame(rows)
