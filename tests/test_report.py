"""The README's results section is built from results/<profile>/ only."""
import json
from pathlib import Path

import pandas as pd

from drfkit.study import claims
from drfkit.report.writers import results_section


def test_results_section_reports_last_run_claims_and_budget_left(tmp_path, monkeypatch):
    monkeypatch.setenv("DRF_RESULTS", str(tmp_path))
    assert "No results for profile `p` yet" in results_section("p", "make reproduce", False)
    claims.upsert("p", [claims.c6_paired([2.9, 3.1] * 20)])
    (tmp_path / "p" / "manifest.json").write_text(json.dumps({
        "pipeline": {"status": "ok", "total_s": 12.0, "notebooks": ["04_ood_noise_evaluation"]},
        "overrides": {"eval_studies": ["pedestrians"]},
        "notebooks": {"04_ood_noise_evaluation": {"status": "ok"}, "03_ood_noise_evaluation": {"status": "ok"}}}))
    pd.DataFrame([{"study": "pendulum", "model": "drf", "epoch_s": 10.0, "epochs": 200, "seeds": 3, "hours": 6.0,
                   "epochs_done": 300, "hours_left": 3.0, "threads": 1}]).to_csv(tmp_path / "p" / "training_budget.csv")
    text = results_section("p", "make reproduce", False)
    assert "last pipeline run: 04_ood_noise_evaluation with --set eval_studies=['pedestrians'], status ok" in text
    # a notebook since renamed (its old entry still in the manifest) is not listed as this book's
    assert "Notebooks run for this profile so far: 04_ood_noise_evaluation (ok)." in text
    assert "| C6 |" in text and "Not evaluated yet in this profile: C1" in text
    assert "**6.0 hours** in all, **3.0 hours left**" in text and "| pendulum | drf | 10 |  |  | 200 × 3 | 300 |" in text
    assert "Pendulum training speed" not in text  # no notebook 01 table yet


def test_results_section_reports_step_ratios_and_the_training_speed_table(tmp_path, monkeypatch):
    monkeypatch.setenv("DRF_RESULTS", str(tmp_path))
    claims.upsert("p", [claims.c6_paired([2.9, 3.1] * 20)])
    base = {"study": "pendulum", "epochs": 200, "seeds": 3, "hours": 1.0, "epochs_done": 0, "hours_left": 1.0,
            "threads": 1, "ratio_to": "no_dynamics"}
    pd.DataFrame([{**base, "model": "no_dynamics", "epoch_s": 20.0, "step_ratio": 1.0},
                  {**base, "model": "drf", "epoch_s": 29.0, "step_ratio": 1.456}]).to_csv(
        tmp_path / "p" / "training_budget.csv")
    (tmp_path / "p" / "tables").mkdir()
    pd.DataFrame([{"model": "no_dynamics", "batch": 50, "frames": 75, "threads": 2, "step_median_s": 0.5,
                   "ratio_to_no_dynamics": 1.0},
                  {"model": "drf", "batch": 50, "frames": 75, "threads": 2, "step_median_s": 0.8,
                   "ratio_to_no_dynamics": 1.61}]).to_csv(tmp_path / "p" / "tables" / "pendulum_training_speed.csv")
    text = results_section("p", "make reproduce", False)
    assert "| pendulum | drf | 29 | 1.46× no_dynamics |  | 200 × 3 |" in text  # a budget written before FLOPs were counted
    budget = pd.read_csv(tmp_path / "p" / "training_budget.csv", index_col=0).assign(flop_ratio=[1.0, 1.614])
    budget.to_csv(tmp_path / "p" / "training_budget.csv")
    assert "| pendulum | drf | 29 | 1.46× no_dynamics | 1.61× | 200 × 3 |" in results_section("p", "make reproduce", False)
    assert "(one run, 2 torch thread(s), batch 50 × 75 frames): a DRF step costs **1.61×** a no_dynamics step" in text
    assert "step by step" not in text  # no per-step row in that table
    speed = pd.read_csv(tmp_path / "p" / "tables" / "pendulum_training_speed.csv", index_col=0)
    pd.concat([speed, speed.tail(1).assign(model="drf_per_step", ratio_to_no_dynamics=1.78)]).to_csv(
        tmp_path / "p" / "tables" / "pendulum_training_speed.csv")
    assert "target ≤ 1.5×; 1.78× when autograd differentiates the filter step by step" in \
        results_section("p", "make reproduce", False)
    assert "counted arithmetic" not in results_section("p", "make reproduce", False)  # no FLOP columns yet
    speed = pd.read_csv(tmp_path / "p" / "tables" / "pendulum_training_speed.csv", index_col=0)
    speed["gflop"], speed["flop_ratio_to_no_dynamics"] = [7.5, 12.0, 12.0], [1.0, 1.6, 1.6]
    speed["gflop_per_s"] = speed["gflop"] / speed["step_median_s"]  # 15 and 15: the same rate
    speed.to_csv(tmp_path / "p" / "tables" / "pendulum_training_speed.csv")
    assert ("; its counted arithmetic is 1.60× a no_dynamics step's (12 against 7.5 GFLOP of matrix products "
            "and convolutions), run at 1.00× its rate;") in results_section("p", "make reproduce", False)
    speed["ratio_to_no_dynamics_iqr"] = [0.0, 0.04, 0.05]
    speed.to_csv(tmp_path / "p" / "tables" / "pendulum_training_speed.csv")
    assert "costs **1.61×** a no_dynamics step (per-round IQR 0.04; 0.8 s against 0.5 s; target" in \
        results_section("p", "make reproduce", False)


def test_results_section_reports_the_recursion_scaling_per_thread_count(tmp_path, monkeypatch):
    monkeypatch.setenv("DRF_RESULTS", str(tmp_path))
    claims.upsert("p", [claims.c6_paired([2.9, 3.1] * 20)])
    (tmp_path / "p" / "tables").mkdir()
    assert "Per-call cost" not in results_section("p", "make reproduce", False)
    rows = []
    for threads, fixed, floor in ((1, 0.028, 1.51), (2, 0.036, 1.53)):
        common = {"frames": 75, "threads": threads, "fixed_s": fixed, "per_sequence_s": 0.0015}
        rows += [{**common, "model": "no_dynamics", "part": "step", "batch": 50, "median_s": 0.15},
                 {**common, "model": "drf", "part": "step", "batch": 50, "median_s": 0.27, "ratio": 1.75,
                  "floor_ratio": floor},
                 {**common, "model": "drf", "part": "recursion", "batch": 25, "median_s": 0.07},
                 {**common, "model": "drf", "part": "recursion", "batch": 50, "median_s": 0.108}]
    pd.DataFrame(rows).to_csv(tmp_path / "p" / "tables" / "pendulum_recursion_scaling.csv", index=False)
    text = results_section("p", "make reproduce", False)
    assert ("at 1 thread(s) the recursion takes 108 ms at batch 50, 28 ms of it per-call cost (the intercept of "
            "its time against the batch), and without that cost the DRF step would cost **1.51×** a no_dynamics "
            "step instead of 1.75× (the step ratio timed in this same run; the training-speed line times steps in "
            "a separate run); at 2 thread(s)") in text
    assert "**1.53×**" in text and "`tables/pendulum_recursion_scaling.csv`" in text


def test_results_section_reports_whole_epochs(tmp_path, monkeypatch):
    monkeypatch.setenv("DRF_RESULTS", str(tmp_path))
    claims.upsert("p", [claims.c6_paired([2.9, 3.1] * 20)])
    (tmp_path / "p" / "tables").mkdir()
    common = {"threads": 2, "rounds": 3, "sequences": 2000, "batch": 50}
    pd.DataFrame([{**common, "model": "no_dynamics", "epoch_median_s": 7.0, "ratio_to_no_dynamics": 1.0,
                   "ratio_to_no_dynamics_iqr": 0.0},
                  {**common, "model": "lstm", "epoch_median_s": 7.4, "ratio_to_no_dynamics": 1.06,
                   "ratio_to_no_dynamics_iqr": 0.02},
                  {**common, "model": "drf", "epoch_median_s": 11.8, "ratio_to_no_dynamics": 1.69,
                   "ratio_to_no_dynamics_iqr": 0.11}]).to_csv(tmp_path / "p" / "tables" / "pendulum_epoch_times.csv",
                                                              index=False)
    text = results_section("p", "make reproduce", False)
    assert ("(the training loop itself, validation and checkpoints included, 3 interleaved rounds, 2 torch "
            "thread(s), 2000 sequences): against a no_dynamics epoch of 7 s, lstm **1.06×** (IQR 0.02; 7.4 s), "
            "drf **1.69×** (IQR 0.11; 11.8 s); target ≤ 1.5× for the DRF") in text


def test_an_interrupted_run_is_reported_with_its_note_and_no_total(tmp_path, monkeypatch):
    monkeypatch.setenv("DRF_RESULTS", str(tmp_path))
    claims.upsert("p", [claims.c6_paired([2.9, 3.1] * 20)])
    (tmp_path / "p" / "manifest.json").write_text(json.dumps({
        "pipeline": {"status": "interrupted", "total_s": None, "notebooks": ["06_competency_gating"],
                     "note": "killed during 06_competency_gating"}}))
    text = results_section("p", "make reproduce", False)
    assert "status interrupted: killed during 06_competency_gating" in text and "None s" not in text


def test_dynamics_lines_show_both_protocols_the_reference_and_the_ablation(tmp_path):
    from drfkit.report.writers import dynamics_lines

    assert dynamics_lines(tmp_path) == []
    pd.DataFrame({"protocol": ["paper", "book"], "model": ["drf", "drf"], "seed": [0, 0], "mae_0.5": [0.02, 0.01],
                  "mae_blackout": [0.55, 0.08], "mae_after_blackout": [0.1, 0.02], "r_noise_spearman": [0.05, 0.9],
                  "gain_ratio_blackout": [0.92, 0.2], "prior_ratio": [7.9, 0.7]}).to_csv(tmp_path / "pendulum_protocols.csv",
                                                                                       index=False)
    pd.DataFrame({"seed": [0, 0], "noise": ["0.5", "blackout"], "mae": [0.006, 0.033]}).to_csv(
        tmp_path / "pendulum_physics_reference.csv", index=False)
    text = "\n".join(dynamics_lines(tmp_path))
    assert "| paper | DRF (ours) | 0.0200 | 0.5500 | 0.05 | 0.92 | 7.90 |" in text
    assert "| book | DRF (ours) | 0.0100 | 0.0800 | 0.90 | 0.20 | 0.70 |" in text
    assert "| — | true-physics reference on its no_dynamics | 0.0060 | 0.0330 |" in text
    # each protocol's reference on its own no_dynamics, once notebook 02 has written them (like for like)
    pd.DataFrame({"protocol": ["paper", "paper", "book", "book"], "seed": [0] * 4, "noise": ["0.5", "blackout"] * 2,
                  "mae": [0.006, 0.033, 0.004, 0.021]}).to_csv(tmp_path / "pendulum_physics_reference_protocols.csv",
                                                               index=False)
    text = "\n".join(dynamics_lines(tmp_path))
    assert "| paper | true-physics reference on its no_dynamics | 0.0060 | 0.0330 |" in text
    assert "| book | true-physics reference on its no_dynamics | 0.0040 | 0.0210 |" in text and "| — |" not in text
    pd.DataFrame({"variant": ["book", "book", "paper"], "kind": ["drf"] * 3, "seed": [0, 1, 0], "budget": ["small"] * 3,
                  "mae_0.5": [0.01, 0.03, 0.02], "mae_blackout": [0.1, 0.2, 0.5]}).to_csv(tmp_path / "pendulum_ablation.csv",
                                                                                       index=False)
    text = "\n".join(dynamics_lines(tmp_path))
    assert "budget small" in text and "| book | DRF (ours) | 2 | 0.02 |" in text
    assert text.index("| book | DRF (ours) | 2") < text.index("| paper | DRF (ours) | 1")


def test_dynamics_lines_show_the_regime_map(tmp_path):
    from drfkit.study.regime import regime_summary
    from drfkit.report.writers import dynamics_lines

    rows = [{"train_noise": tn, "model": m, "seed": 0, "test": "0.75", "test_noise": 0.75, "mae": mae}
            for tn, m, mae in [(0.5, "drf", 0.04), (0.5, "lstm", 0.05), (0.5, "no_dynamics", 0.08),
                               (0.5, "physics_reference", 0.02), (1.0, "drf", 0.03), (1.0, "lstm", 0.03),
                               (1.0, "no_dynamics", 0.06), (1.0, "physics_reference", 0.015)]]
    regime_summary(pd.DataFrame(rows)).to_csv(tmp_path / "pendulum_regime_summary.csv", index=False)
    text = "\n".join(dynamics_lines(tmp_path))
    # the model columns are the kinds the map holds, in the registry's order, under their display labels
    assert "| trained at | test | DRF (ours) | No dynamics | LSTM | reference |" in text
    assert "| 0.5 | 0.75 | 0.0400 | 0.0800 | 0.0500 | 0.0200 | 0.50 | 2.00 |" in text
    assert "| 1 | 0.75 | 0.0300 | 0.0600 | 0.0300 | 0.0150 | 0.50 | 2.00 |" in text


def test_readme_claims_table_has_one_row_per_claim_and_a_verdict_per_protocol(tmp_path):
    from drfkit.report.writers import claims_summary_table

    rows = [("C1", "paper", "not reproduced"), ("C1", "book", "partly"), ("C4", "paper", "reproduced")]
    pd.DataFrame([{"id": i, "protocol": p, "claim": f"claim {i}", "paper": "1 | 2", "ours": "x", "verdict": v,
                   "rule": "r"} for i, p, v in rows]).to_csv(tmp_path / "claims.csv", index=False)
    lines = claims_summary_table(tmp_path / "claims.csv")
    assert lines[0] == "| id | claim | paper | verdict, paper protocol | verdict, book protocol |"
    assert lines[2] == "| C1 | claim C1 | 1 / 2 | **not reproduced** | **partly** |"
    assert lines[3] == "| C4 | claim C4 | 1 / 2 | **reproduced** (simulated source) | — |"
    pd.DataFrame([{"id": "C4", "protocol": "paper", "claim": "c", "paper": "p", "ours": "x", "verdict": "partly",
                   "rule": "r"}]).to_csv(tmp_path / "claims.csv", index=False)
    table = claims_summary_table(tmp_path / "claims.csv")
    assert table[:3] == ["| id | claim | paper | verdict |", "|---|---|---|---|", "| C4 | c | p | **partly** (simulated source) |"]


def test_readme_section_links_claims_md_and_report_md_where_they_are(tmp_path, monkeypatch):
    """The README's section names each claim once and links claims.md (evidence) and report.md; the
    report's links are relative to its own folder, so both hold on GitHub and in the book."""
    from drfkit.report.writers import readme_section, report_text

    monkeypatch.setenv("DRF_RESULTS", str(tmp_path))
    root = tmp_path / "p"
    (root / "figures").mkdir(parents=True)
    pd.DataFrame([{"id": "C1", "protocol": "paper", "claim": "c", "paper": "p", "ours": "x", "verdict": "partly",
                   "rule": "r"}]).to_csv(root / "claims.csv", index=False)
    (root / "claims.md").write_text("# Claims\n\nintro\n\n| id |\n|---|\n| [x](executed/01_a.ipynb) |\n")
    (root / "figures" / "pendulum_mae.png").write_bytes(b"png")
    (root / "figures" / "pedestrians_mae.png").write_bytes(b"png")
    text = readme_section("p", "make reproduce PROFILE=p")
    assert "[results/p/claims.md](results/p/claims.md)" in text and "(results/p/report.md)" in text
    assert "![Pedestrian depth MAE" in text and "(results/p/figures/pedestrians_mae.png)" in text
    assert "executed/" not in text and "pendulum_mae.png" not in text  # evidence stays in claims.md; README_FIGURES only
    report = report_text("p", "make reproduce PROFILE=p")
    assert "(figures/pendulum_mae.png)" in report and "(executed/01_a.ipynb)" in report and "../" not in report


def test_every_claim_links_evidence_that_the_paper_profile_has():
    """The claim map names files the committed paper profile holds (a renamed table or figure fails)."""
    from drfkit.study.claims import CLAIM_EVIDENCE, CLAIM_SOURCES
    from drfkit.util.paths import REPO_ROOT

    assert set(CLAIM_EVIDENCE) == set(CLAIM_SOURCES)
    root = REPO_ROOT / "results" / "paper"
    for cid, (notebook, section, tables, figures) in CLAIM_EVIDENCE.items():
        assert (root / "executed" / f"{notebook}.ipynb").exists(), cid
        assert f"## {section}" in (REPO_ROOT / "notebooks" / "src" / f"{notebook}.py").read_text(), (cid, section)
        for name in tables:
            assert (root / "tables" / name).exists(), (cid, name)
        for name in figures:
            assert (root / "figures" / name).exists(), (cid, name)


def test_blackout_figure_draws_one_panel_per_protocol_with_the_reference_in_each():
    import matplotlib

    matplotlib.use("Agg")
    from drfkit.report.figures import plot_blackout

    frames = list(range(10))
    curve = lambda model, protocol, level: pd.DataFrame(  # noqa: E731
        {"model": model, "seed": 0, "frame": frames, "mae": level, "protocol": protocol})
    curves = pd.concat([curve("drf", "paper", 0.5), curve("drf", "book", 0.1), curve("physics_reference", None, 0.02)])
    fig = plot_blackout(curves, (3, 6), ["drf", "physics_reference"])
    axes = fig.axes
    assert [ax.get_title() for ax in axes] == ["paper protocol", "book protocol"]
    for ax, level in zip(axes, (0.5, 0.1)):
        lines = {line.get_label(): line.get_ydata() for line in ax.get_lines()}
        assert len(lines) == 2 and any((y == level).all() for y in lines.values())
        assert any((y == 0.02).all() for y in lines.values())  # the reference in every panel
    assert axes[0].get_ylim() == axes[1].get_ylim()
    single = plot_blackout(curves.drop(columns="protocol").query("model != 'drf' or mae == 0.5"), (3, 6), ["drf"])
    assert len(single.axes) == 1 and single.axes[0].get_title() == ""
    unlabelled = plot_blackout(curves.assign(protocol=None), (3, 6), ["drf"])  # no protocol named: one panel
    assert len(unlabelled.axes) == 1


def test_the_committed_readme_section_and_report_are_what_the_generator_writes():
    """The README's results section and results/paper/report.md are generated, never edited: after a
    change to the generator or to the committed results, `python -m drfkit report --profiles paper`
    writes them again (a link or caption changed by hand, or left behind, fails here)."""
    from drfkit.report.writers import README_END, README_START, readme_section, report_text
    from drfkit.util.paths import REPO_ROOT

    readme = (REPO_ROOT / "README.md").read_text()
    block = readme.split(README_START, 1)[1].split(README_END, 1)[0]
    assert block.strip() == readme_section("paper", "make reproduce").strip(), \
        "README's results section is stale: run `python -m drfkit report --profiles paper`"
    assert (REPO_ROOT / "results" / "paper" / "report.md").read_text() == report_text("paper", "make reproduce"), \
        "results/paper/report.md is stale: run `python -m drfkit report --profiles paper`"
