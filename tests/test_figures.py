"""Figures that read on their own: every panel labelled (units included) with a legend where it
draws more than one series, reference lines explained, PICP panels with a 95 % line and intervals
cut to PICP's range, training curves that show the selection region with the kept epochs marked,
calibration titles that name the noise parameter. Each figure is drawn from a small synthetic
frame and read back from the Figure object (no file is written)."""
import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
import pytest  # noqa: E402

from drfkit.report import figures  # noqa: E402

PEND = ["drf", "no_dynamics", "lstm"]
PED = ["drf", "no_dynamics", "lstm", "monoloco"]


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


def _row(**values):
    """One ``summarise`` row: for each metric (mean, half-width) also _lo / _hi, clipped like summarise."""
    ranges = {"mae": (0, np.inf), "picp": (0, 1), "mpiw": (0, np.inf)}
    row = {}
    for key, value in values.items():
        if isinstance(value, tuple):
            mean, half = value
            lo, hi = ranges.get(key, (-np.inf, np.inf))
            row.update({key: mean, f"{key}_ci": half, f"{key}_lo": max(mean - half, lo),
                        f"{key}_hi": min(mean + half, hi)})
        else:
            row[key] = value
    return row


def _picp_curves(models, levels):
    rows = []
    for i, kind in enumerate(models):
        for j, lv in enumerate(levels):
            for k, p in enumerate([0.05, 0.1, 0.3]):
                picp = 0.999 if j == 0 else 0.90 + 0.03 * k  # the first level sits at 100 %
                rows.append(_row(model=kind, noise=lv, dropout_p=p, n_seeds=3, picp=(picp, 0.04),
                                 mpiw=(0.2 + 0.3 * k + 0.05 * i, 0.5), mae=(0.02, 0.01)))
    return pd.DataFrame(rows)


def _sweep_summary(models, levels, study):
    rows = [_row(study=study, model=kind, noise=lv, n_seeds=3, mae=(0.02 + lv, 0.05), picp=(0.99 - 0.2 * lv, 0.05),
                 nll=(-1.5 + lv, 0.3)) for kind in models for lv in levels]
    return pd.DataFrame(rows)


def _calibration_points(study, levels, models):
    q = np.linspace(0.05, 0.95, 7)
    return pd.DataFrame([{"study": study, "model": kind, "noise": lv, "expected": e, "observed": e ** 1.2}
                         for kind in models for lv in levels for e in q])


def _regime_table():
    rows = []
    for tn in (0.5, 1.0):
        for kind in PEND + ["physics_reference"]:
            for seed in (0, 1):
                rows += [{"train_noise": tn, "model": kind, "seed": seed, "test": f"{lv:g}", "test_noise": lv,
                          "mae": 0.01 + lv / 10} for lv in (0.0, 0.5, 1.0)]
                rows.append({"train_noise": tn, "model": kind, "seed": seed, "test": "blackout", "test_noise": np.nan,
                             "mae": 0.3})
    return pd.DataFrame(rows)


def _blackout_curves():
    frames = np.arange(12)
    curve = lambda model, protocol, level: pd.DataFrame(  # noqa: E731
        {"model": model, "seed": 0, "frame": frames, "mae": level * (1 + (frames >= 4) * (frames < 8)),
         "protocol": protocol})
    return pd.concat([curve("drf", "paper", 0.05), curve("no_dynamics", "paper", 0.06), curve("drf", "book", 0.04),
                      curve("no_dynamics", "book", 0.06), curve("physics_reference", None, 0.01)], ignore_index=True)


def _history(models, selected_on_l1=(), epochs=30):
    """Training curves with a U-shaped validation loss that starts high (+60) and whose minimum
    (model- and seed-dependent) lies inside the run; Monoloco-like runs selected on val_l1."""
    rows = []
    for i, kind in enumerate(models):
        for seed in (0, 1):
            best = 8 + 3 * i + seed
            for epoch in range(1, epochs + 1):
                val = -2.0 + 0.01 * i + 0.02 * seed + 0.05 * (epoch - best) ** 2
                val = 60.0 if epoch == 1 else val
                l1 = 1.4 + 0.01 * abs(epoch - best - 2) if kind in selected_on_l1 else np.nan
                rows.append({"model": kind, "seed": seed, "epoch": epoch, "train_loss": 1.0 - 0.1 * epoch,
                             "val_loss": val, "val_l1": l1, "lr": 1e-3, "seconds": 1.0, "device": "cpu"})
    frame = pd.DataFrame(rows)
    return frame if selected_on_l1 else frame.drop(columns="val_l1")


FIGURES = {
    "mae_bars": lambda: figures.plot_mae_bars(_sweep_summary(PEND, [0.5, 0.75], "pendulum"), PEND,
                                              {0.5: {"drf": 0.02}}, ylabel="MAE (cos θ, sin θ)",
                                              level_name="max noise", reference={0.5: 0.01}),
    "picp_mpiw": lambda: figures.plot_picp_mpiw(_picp_curves(PEND, [0.5, 0.75]), PEND,
                                                {"drf": [(1.0, 97.0), (2.0, 99.0)]}, level_name="max noise"),
    "sweep": lambda: figures.plot_sweep(_sweep_summary(PED, [0.0, 0.01, 0.05], "pedestrians"), PED, 0.01,
                                        metrics=("mae", "picp", "nll"), xlabel="salt-and-pepper p"),
    "calibration": lambda: figures.plot_calibration(_calibration_points("pendulum", [0.5, 0.75], PEND), PEND),
    "blackout": lambda: figures.plot_blackout(_blackout_curves(), (4, 8), ["drf", "no_dynamics", "physics_reference"]),
    "regime": lambda: figures.plot_regime(_regime_table(), PEND),
    "training_curves": lambda: figures.plot_training_curves(_history(PEND)),
    "training_curves_l1": lambda: figures.plot_training_curves(_history(PED, selected_on_l1=("monoloco",))),
}
# what the notebooks' stored outputs show: a figure keeps its size and number of axes
SHAPES = {"mae_bars": (6.0, 3.4, 1), "picp_mpiw": (9.0, 3.4, 2), "sweep": (13.5, 3.4, 3), "calibration": (7.2, 3.4, 2),
          "blackout": (8.4, 3.4, 2), "regime": (10.8, 3.4, 3), "training_curves": (9.0, 3.4, 2),
          "training_curves_l1": (9.0, 3.4, 2)}


def _series(ax) -> int:
    """Data series drawn on a panel: lines with data, bar groups and bands (not reference lines'
    proxies without data)."""
    lines = [line for line in ax.get_lines() if len(line.get_xdata()) > 0 and not line.get_label().startswith("_child")]
    return len(lines) + len(ax.containers) + len(ax.collections)


def _hline_at(ax, y: float) -> bool:
    return any(len(line.get_ydata()) == 2 and np.allclose(np.asarray(line.get_ydata(), dtype=float), y)
               and not np.isclose(*np.asarray(line.get_xdata(), dtype=float)) for line in ax.get_lines())


def _legend_texts(ax) -> list[str]:
    legend = ax.get_legend()
    return [t.get_text() for t in legend.get_texts()] if legend else []


@pytest.mark.parametrize("name", sorted(FIGURES))
def test_every_panel_has_axis_labels_and_a_legend_where_it_draws_several_series(name):
    fig = FIGURES[name]()
    w, h, n = SHAPES[name]
    assert len(fig.axes) == n and tuple(fig.get_size_inches()) == pytest.approx((w, h))
    for ax in fig.axes:
        assert ax.get_xlabel().strip(), (name, ax.get_title())
        assert ax.get_ylabel().strip(), (name, ax.get_title())
        if _series(ax) > 1:
            assert ax.get_legend() is not None, (name, ax.get_title())


def test_units_and_noise_parameter_on_the_axes():
    pend = figures.plot_picp_mpiw(_picp_curves(PEND, [0.5]), PEND, level_name="max noise")
    assert "(cos θ, sin θ)" in pend.axes[0].get_xlabel() and "max noise" in pend.axes[0].get_title()
    ped = figures.plot_picp_mpiw(_picp_curves(PED, [0.01]), PED, level_name="p")
    assert "(m)" in ped.axes[0].get_xlabel()
    assert "salt-and-pepper p" in ped.axes[0].get_title()  # "p" alone reads as a dropout rate here
    sweep = figures.plot_sweep(_sweep_summary(PED, [0.0, 0.05], "pedestrians"), PED, 0.01, xlabel="salt-and-pepper p")
    assert "(m)" in sweep.axes[0].get_ylabel() and "salt-and-pepper p" in sweep.axes[0].get_xlabel()
    bars = figures.plot_mae_bars(_sweep_summary(PED, [0.01], "pedestrians"), PED, ylabel="depth MAE (m)",
                                 level_name="p", width=5)
    assert "salt-and-pepper p" in bars.axes[0].get_xlabel()


def test_picp_panels_draw_the_nominal_line_and_stay_inside_picps_range():
    fig = FIGURES["picp_mpiw"]()
    for ax in fig.axes:
        assert _hline_at(ax, 95.0), ax.get_title()
        assert any("95" in t for t in _legend_texts(ax))  # the line is explained
        lo, hi = ax.get_ylim()
        assert 0 <= lo and hi <= 102
        for container in ax.containers:  # error bars: PICP never above 100 % nor below 0, MPIW never below 0
            for segments in (c.get_segments() for c in container.lines[2]):
                pts = np.concatenate(segments)
                assert pts[:, 1].max() <= 100 + 1e-9 and pts[:, 1].min() >= 0 and pts[:, 0].min() >= 0
    assert fig.axes[0].get_ylim() == fig.axes[1].get_ylim()  # a panel at 100 % is read on the others' scale


def test_picp_points_carry_their_dropout_rate():
    fig = FIGURES["picp_mpiw"]()
    for ax in fig.axes:
        texts = {t.get_text() for t in ax.texts}
        assert {"0.05", "0.1", "0.3"} <= texts, ax.get_title()
        assert any("dropout rate" in t for t in _legend_texts(ax))


def test_sweep_picp_panel_has_the_nominal_line_a_clipped_band_and_explained_lines():
    summary = _sweep_summary(PED, [0.0, 0.01, 0.05], "pedestrians")
    summary["picp_hi"] = summary["picp"] + summary["picp_ci"]  # a table written before summarise clipped its ends
    fig = figures.plot_sweep(summary, PED, 0.01, metrics=("mae", "picp", "nll"), xlabel="salt-and-pepper p")
    picp = next(ax for ax in fig.axes if "PICP" in ax.get_ylabel())
    assert _hline_at(picp, 95.0) and 0 <= picp.get_ylim()[0] and picp.get_ylim()[1] <= 102
    for band in picp.collections:
        assert band.get_paths()[0].vertices[:, 1].max() <= 100 + 1e-9
    for ax in fig.axes:
        texts = _legend_texts(ax)
        assert any("training noise" in t for t in texts) and any("95 %" in t and "band" in t for t in texts)


def test_calibration_titles_name_the_noise_parameter():
    pend = figures.plot_calibration(_calibration_points("pendulum", [0.5, 0.75], PEND), PEND)
    assert [ax.get_title() for ax in pend.axes] == ["max noise 0.5", "max noise 0.75"]
    ped = figures.plot_calibration(_calibration_points("pedestrians", [0.01, 0.05], PED), PED)
    assert [ax.get_title() for ax in ped.axes] == ["salt-and-pepper p 0.01", "salt-and-pepper p 0.05"]
    assert all(any("perfect calibration" in t for t in _legend_texts(ax)) for ax in pend.axes)


def test_regime_map_explains_the_training_noise_line_and_labels_every_panel():
    fig = FIGURES["regime"]()
    for ax in fig.axes[:-1]:
        assert any("training noise" in t for t in _legend_texts(ax)) and "(cos θ, sin θ)" in ax.get_ylabel()
    dark = fig.axes[-1]
    assert dark.get_legend() is not None and "(cos θ, sin θ)" in dark.get_ylabel()


@pytest.mark.parametrize("selected_on_l1", [(), ("monoloco",)])
def test_training_curves_mark_each_runs_best_epoch_and_show_the_selection_region(selected_on_l1):
    models = PED if selected_on_l1 else PEND
    curves = _history(models, selected_on_l1)
    fig = figures.plot_training_curves(curves)
    val = fig.axes[1] if not selected_on_l1 else None
    stars = [(x, y) for ax in fig.axes for line in ax.get_lines() if line.get_marker() == "*"
             for x, y in zip(line.get_xdata(), line.get_ydata())]
    for (kind, seed), run in curves.groupby(["model", "seed"]):
        metric = "val_l1" if kind in selected_on_l1 else "val_loss"
        best = run.loc[run[metric].idxmin()]
        assert any(x == best["epoch"] and np.isclose(y, best[metric]) for x, y in stars), (kind, seed)
    if val is not None:  # the first epoch's +60 does not set the scale: the minima are told apart
        lo, hi = val.get_ylim()
        assert lo < curves["val_loss"].min() and hi < 10


def test_blackout_panels_each_carry_their_axis_label_and_legend():
    fig = FIGURES["blackout"]()
    for ax in fig.axes:
        assert "(cos θ, sin θ)" in ax.get_ylabel() and any("pure-noise" in t for t in _legend_texts(ax))
