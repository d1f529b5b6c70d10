"""Writing what a run produces: tables (CSV) and figures (PNG) under results/<profile>/, always
atomically; ours beside the paper's numbers; and the generated results text (``results/<profile>/
report.md`` and the README's results section, ``python -m drfkit report``). The plots themselves
are ``drfkit.report.figures``."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from drfkit.models.kinds import MODEL_CLASSES, model_spec
from drfkit.report.figures import label, paper_value
from drfkit.util.io import atomic_savefig, atomic_write_csv
from drfkit.util.paths import figures_dir, tables_dir
from drfkit.methods.protocols import summarise_ablation


def save_table(profile: str, name: str, frame: pd.DataFrame) -> Path:
    """Write ``results/<profile>/tables/<name>.csv`` atomically and return its path."""
    return atomic_write_csv(tables_dir(profile) / f"{name}.csv", frame)


def save_figure(profile: str, name: str, fig) -> Path:
    """Write ``results/<profile>/figures/<name>.png`` atomically and return its path."""
    return atomic_savefig(figures_dir(profile) / f"{name}.png", fig)


def paper_comparison(summary: pd.DataFrame, paper: dict, metric: str = "mae") -> pd.DataFrame:
    """Ours next to the paper's value for every (model, noise) the paper reports.

    summary: ``drfkit.study.evaluate.summarise`` by model, noise; paper: noise -> model -> value.
    Columns: model, noise, ours, ours_ci (95 % half-width over seeds), paper, ours_over_paper.
    """
    rows = []
    for r in summary.itertuples():
        ref = paper_value(paper, r.noise, r.model)
        if np.isnan(ref):
            continue
        ours = getattr(r, metric)
        rows.append({"model": r.model, "noise": r.noise, "ours": ours, "ours_ci": getattr(r, f"{metric}_ci"),
                     "paper": ref, "ours_over_paper": ours / ref})
    return pd.DataFrame(rows)


README_START, README_END = "<!-- results:start -->", "<!-- results:end -->"
HEADLINE_FIGURES = [
    ("pendulum_mae", "Pendulum MAE at max noise 0.5 and 0.75 (paper values as black ticks)"),
    ("pendulum_picp_mpiw", "Pendulum PICP against MPIW as the dropout rate varies"),
    ("pedestrians_mae", "Pedestrian depth MAE with Monoloco at p = 0.01, 0.025, 0.05"),
    ("pedestrians_picp_mpiw", "Pedestrian PICP against MPIW at the three noise levels"),
    ("pendulum_sweep", "Pendulum: MAE, PICP and NLL along the noise sweep"),
    ("pedestrians_sweep", "Pedestrians: MAE, PICP and NLL along the noise sweep"),
    ("pendulum_book_mae", "Pendulum MAE of the book's training protocol (whether each filter filters: notebook 02)"),
    ("pendulum_blackout", "Pendulum: MAE per frame through 15 pure-noise frames, with the true-physics reference "
                          "(a particle filter on no_dynamics' outputs)"),
    ("pendulum_blackout_protocols", "Pendulum blackout under the paper's and the book's protocol, with the "
                                    "true-physics reference"),
    ("pendulum_mae_with_reference", "Pendulum MAE (paper's protocol) beside the true-physics reference and the "
                                    "paper's values (black ticks)"),
    ("pendulum_regime_map", "Noise-regime map: MAE along the test noise for each training noise, and on the blackout"),
]


def epoch_times_line(epochs: pd.DataFrame) -> str:
    """One sentence of a ``drfkit.methods.timing.epoch_times`` table (notebook 05); the first row is the base."""
    base = epochs["model"].iloc[0]
    rows = epochs.set_index("model")
    others = [f"{model} **{row[f'ratio_to_{base}']:.2f}×** (IQR {row[f'ratio_to_{base}_iqr']:.2f}; "
              f"{row['epoch_median_s']:.3g} s)" for model, row in rows.iloc[1:].iterrows()]
    return (f"Whole training epochs in notebook 05 (the training loop itself, validation and checkpoints "
            f"included, {int(rows['rounds'].iloc[0])} interleaved rounds, {int(rows['threads'].iloc[0])} torch "
            f"thread(s), {int(rows['sequences'].iloc[0])} sequences): against a {base} epoch of "
            f"{rows.loc[base, 'epoch_median_s']:.3g} s, " + ", ".join(others) + "; target ≤ 1.5× for the DRF "
            "(`tables/pendulum_epoch_times.csv`).")


def recursion_scaling_line(scaling: pd.DataFrame) -> str:
    """One sentence per thread count of a ``drfkit.methods.timing.recursion_scaling`` table (notebook 05)."""
    parts = []
    for threads, rows in scaling.groupby("threads"):
        step = rows[(rows["model"] == "drf") & (rows["part"] == "step")].iloc[0]
        rec = rows[(rows["part"] == "recursion") & (rows["batch"] == step["batch"])].iloc[0]
        parts.append(f"at {int(threads)} thread(s) the recursion takes {1e3 * rec['median_s']:.0f} ms at batch "
                     f"{int(step['batch'])}, {1e3 * step['fixed_s']:.0f} ms of it per-call cost (the intercept of its "
                     f"time against the batch), and without that cost the DRF step would cost "
                     f"**{step['floor_ratio']:.2f}×** a no_dynamics step instead of {step['ratio']:.2f}× (the step ratio timed in "
                     f"this same run; the training-speed line times steps in a separate run)")
    return ("Per-call cost or arithmetic, in notebook 05 (the recursion alone at half, one and two times the batch, "
            "in one run with both training steps): " + "; ".join(parts)
            + " (`tables/pendulum_recursion_scaling.csv`, `figures/pendulum_recursion_scaling.png`).")


def dynamics_lines(tables: Path) -> list[str]:
    """README lines of the dynamics study (notebook 02): both protocols beside the true-physics
    reference, and the protocol ablation on validation data; [] when notebook 02 has not written them."""
    lines: list[str] = []
    protocols, reference = tables / "pendulum_protocols.csv", tables / "pendulum_physics_reference.csv"
    if protocols.exists() and reference.exists():
        pt = pd.read_csv(protocols)
        mae_cols = [c for c in pt if c.startswith("mae_") and c != "mae_after_blackout"]
        mean = pt.groupby(["protocol", "model"], sort=False).mean(numeric_only=True)
        b = pd.read_csv(reference).groupby("noise")["mae"].mean()
        lines += ["Does the filter filter? Test MAE (dropout-off, seed means) of each protocol's models beside "
                  "the true-physics reference (a particle filter with the generator's equations on no_dynamics' "
                  "per-frame estimates: knowledge no learned model has; a comparison, not a bound, since a DRF "
                  "can do better than it), and the DRF's mechanism checks "
                  f"(`tables/pendulum_protocols.csv`, `tables/{reference.name}`, notebook 02):", "",
                  "| protocol | model | " + " | ".join(c.replace("mae_", "MAE ") for c in mae_cols)
                  + " | rank corr(r, noise) | gain pure / clean | ‖Fz − w‖ / ‖z − w‖ |",
                  "|---|---|" + "---|" * (len(mae_cols) + 3)]
        fmt = lambda v, d=4: "" if pd.isna(v) else f"{v:.{d}f}"  # noqa: E731
        for (protocol, model), r in mean.iterrows():
            lines.append(f"| {protocol} | {label(model)} | " + " | ".join(fmt(r[c]) for c in mae_cols) + " | "
                         + " | ".join(fmt(r.get(c), 2) for c in ("r_noise_spearman", "gain_ratio_blackout", "prior_ratio"))
                         + " |")
        # each protocol's reference on its own no_dynamics when notebook 02 wrote them (like for like), else the
        # paper protocol's; the noise column holds levels and 'blackout': named as the protocol table's columns
        per_protocol = tables / "pendulum_physics_reference_protocols.csv"
        references = ({name: g.groupby("noise")["mae"].mean() for name, g in
                       pd.read_csv(per_protocol).groupby("protocol", sort=False)} if per_protocol.exists() else {"—": b})
        for name, rp in references.items():
            reference_of = {("mae_blackout" if k == "blackout" else f"mae_{float(k):g}"): v for k, v in rp.items()}
            lines.append(f"| {name} | true-physics reference on its no_dynamics | "
                         + " | ".join(fmt(reference_of.get(c)) for c in mae_cols) + " | | | |")
        lines.append("")
    ablation = tables / "pendulum_ablation.csv"
    if ablation.exists():
        raw = pd.read_csv(ablation)
        ab = summarise_ablation(raw)
        budgets = ", ".join(sorted(raw["budget"].astype(str).unique()))
        lines += [f"Protocol ablation on **validation** data (`tables/pendulum_ablation.csv`; budget {budgets} of "
                  "`drfkit.methods.protocols.ABLATION_BUDGETS`, `python -m drfkit ablation`), sorted by blackout MAE:", "",
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
                  "`python -m drfkit regime`): DRF against no_dynamics (< 1: the filter helps) and against the "
                  "true-physics reference (the particle filter on no_dynamics' outputs; below 1 the DRF does "
                  "better than it):", "",
                  ]
        # every model kind the map holds a column for, in the registry's order, so a new kind needs no edit here
        kinds = [k for k in MODEL_CLASSES if model_spec(k).report_column and k in rg.columns]
        lines += ["| trained at | test | " + " | ".join(label(k) for k in kinds)
                  + " | reference | DRF / no_dynamics | DRF / reference |",
                  "|---|---|" + "---|" * (len(kinds) + 3)]
        for _, r in rg.iterrows():
            lines.append(f"| {r['train_noise']:g} | {r['test']} | " + " | ".join(f"{r[k]:.4f}" for k in kinds)
                         + f" | {r['physics_reference']:.4f} | {r['drf_over_no_dynamics']:.2f} "
                           f"| {r['drf_over_reference']:.2f} |")
        lines.append("")
    return lines


# the README shows these, in this order; report.md all of HEADLINE_FIGURES
README_FIGURES = ("pendulum_mae_with_reference", "pendulum_blackout_protocols", "pedestrians_mae")


def claims_summary_table(claims_csv: Path) -> list[str]:
    """The README's short claims table from ``claims.csv``: one row per claim (id, claim, the paper's
    number) and a verdict per protocol when there is more than one ("—" where a claim is judged
    under one protocol only). Ours, the rules and each claim's evidence (notebook section, tables,
    figures) are claims.md's, which the README links once instead of repeating them."""
    from drfkit.study.claims import CLAIMS, read_claims
    from drfkit.study.claims.standins import protocol_words, split_label

    c = read_claims(claims_csv)
    protocols = list(dict.fromkeys(c["protocol"]))
    verdict_cols = [f"verdict, {protocol_words(p)}" for p in protocols] if len(protocols) > 1 else ["verdict"]
    head = ["id", "claim", "paper"] + verdict_cols
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for cid, rows in c.groupby("id", sort=False):
        by_protocol = dict(zip(rows["protocol"], rows["verdict"]))
        first = rows.iloc[0]
        sim = " (simulated source)" if cid in CLAIMS and CLAIMS[cid].simulated else ""
        verdicts = [f"**{by_protocol[p]}**{sim}" if p in by_protocol else "—" for p in protocols]
        cells = [cid, first["claim"], first["paper"]] + verdicts
        lines.append("| " + " | ".join(str(x).replace("|", "/") for x in cells) + " |")
    if len(protocols) > 1:
        lines += ["", "— : the claim is not judged under that protocol (its study's models were not trained "
                      "under it in this profile)" + (", or for that model (it is judged in the paper's DRF's place "
                      "for the DRF claims only)" if any(split_label(p)[1] for p in protocols) else "") + "."]
    return lines


def figure_lines(profile: str, names, command: str, prefix: str) -> list[str]:
    """An image and its caption for each of ``names`` (HEADLINE_FIGURES) the profile has, linked as
    ``<prefix>figures/<name>.png``: ``prefix`` is results/<profile>/ as seen from the page."""
    from drfkit.util.paths import results_dir

    captions = dict(HEADLINE_FIGURES)
    lines = []
    for name in names:
        path = results_dir(profile) / "figures" / f"{name}.png"
        if path.exists():
            lines += [f"![{captions[name]}]({prefix}figures/{path.name})", f"*{captions[name]}* (`{command}`)", ""]
    return lines


def readme_section(profile: str, command: str) -> str:
    """The README's short results section: where the run came from, the verdicts, links to
    ``results/<profile>/claims.md`` (ours, rules, evidence) and ``report.md`` (every number), and
    the headline figures. Links are relative to the repository root, where the README is."""
    from drfkit.util.paths import results_dir

    root = results_dir(profile)
    if not (root / "claims.csv").exists():
        return f"No results for profile `{profile}` yet: run `{command}`.\n"
    prefix = f"results/{profile}/"
    full = results_section(profile, command, link_figures=False)
    lines = [full.split("\n", 2)[0], "",  # the provenance line
             f"Our numbers, the rule behind each verdict and where each claim is judged (notebook section, "
             f"tables, figures): [{prefix}claims.md]({prefix}claims.md). Every number, the training cost, the "
             f"speed measurements and the dynamics tables: [{prefix}report.md]({prefix}report.md) (both "
             f"regenerated with this section by `python -m drfkit report --profiles {profile}`).", ""]
    lines += claims_summary_table(root / "claims.csv") + [""]
    lines += figure_lines(profile, README_FIGURES, command, prefix)
    return "\n".join(lines)


def report_text(profile: str, command: str) -> str:
    """``results/<profile>/report.md``'s text: the whole generated results section, figures included,
    its links relative to results/<profile>/ (where the report is)."""
    body = results_section(profile, command, link_figures=True)
    return (f"# Results of profile `{profile}`\n\nGenerated by `python -m drfkit report --profiles {profile}`; "
            f"never edit by hand.\n\n{body}\n")


def write_report(profile: str, command: str) -> Path:
    """Write ``report_text`` to ``results/<profile>/report.md``."""
    from drfkit.util.io import atomic_write_text
    from drfkit.util.paths import results_dir

    path = results_dir(profile) / "report.md"
    atomic_write_text(path, report_text(profile, command))
    return path


def results_section(profile: str, command: str, link_figures: bool) -> str:
    """The whole results section for ``profile``, built from its claims.md and manifest; its links
    (claims.md's, the figures') are relative to results/<profile>/."""
    import json

    from drfkit.study.params import NOTEBOOKS
    from drfkit.util.paths import results_dir

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
                 f"{name} ({entry.get('status', '?')})" for name, entry in sorted(manifest.get("notebooks", {}).items())
                 if name in NOTEBOOKS)  # a notebook since renamed or removed is not this book's
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
        lines += [f"Training cost of this profile on this machine, measured by `python -m drfkit budget --profile "
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
            lines += [f"Pendulum training speed in notebook 05 (one run, {int(sp['threads'].iloc[0])} torch "
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
        lines += figure_lines(profile, [name for name, _ in HEADLINE_FIGURES], command, "")
    return "\n".join(lines)


def update_readme(sections: list[tuple[str, str, bool]], readme: Path | None = None) -> None:
    """Replace the text between the results markers of ``readme`` (default: the repository's
    README.md) by the sections of (profile, command, link_figures), and write each profile's
    report.md beside its claims.md."""
    from drfkit.util.io import atomic_write_text
    from drfkit.util.paths import REPO_ROOT, results_dir

    path = Path(readme) if readme is not None else REPO_ROOT / "README.md"
    text = path.read_text()
    if README_START not in text or README_END not in text:
        raise ValueError(f"{path} lacks the markers {README_START} ... {README_END}")
    body = "\n".join(readme_section(profile, command) for profile, command, _ in sections)
    for profile, command, _ in sections:
        if (results_dir(profile) / "claims.md").exists():
            write_report(profile, command)
    head, rest = text.split(README_START, 1)
    tail = rest.split(README_END, 1)[1]
    atomic_write_text(path, f"{head}{README_START}\n{body}\n{README_END}{tail}")
