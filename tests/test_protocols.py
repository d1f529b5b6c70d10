"""Protocols and the protocol ablation: the paper's runs keep their names, the book's protocol
changes exactly what it says, and an ablation row is trained once, on validation data only."""
from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
import torch

from drfkit.study import ablation, dynamics, studies
from drfkit.study.params import load_profile, notebook_params, validate
from drfkit.methods.protocols import FIT_THE_MEAN, PROTOCOLS, VARIANTS, protocol_spec, summarise_ablation, variant_spec
from drfkit.cli import main as cli

torch.set_num_threads(1)


def quick(tmp_path, monkeypatch, **over):
    monkeypatch.setenv("DRF_RESULTS", str(tmp_path))
    values = load_profile("quick") | {"pend_train_sequences": 6, "pend_val_sequences": 3, "pend_test_sequences": 3,
                                      "pend_seq_len": 12} | over
    return validate("01_pendulum_training", notebook_params("01_pendulum_training", values))


def test_every_protocol_names_a_variant_per_model():
    for protocol, kinds in PROTOCOLS.items():
        # the book's protocol adds the calibrated-gain DRF, the fifth round's choice (its steep-link version) and the
        # known-dynamics filter, the model-based reference
        assert set(kinds) == {"drf", "no_dynamics", "lstm"} | (
            {"drf_calibrated", "drf_calibrated_steep", "known_dynamics"} if protocol == "book" else set())
        for kind, variant in kinds.items():
            assert VARIANTS[variant]["kind"] == kind
    assert protocol_spec("paper", "drf") == {"kind": "drf", "model": {}, "blackouts": None, "train_max_noise": 0.5,
                                             "train": {}}
    with pytest.raises(ValueError, match="unknown protocol"):
        protocol_spec("fancy", "drf")
    with pytest.raises(ValueError, match="unknown variant"):
        variant_spec("nope")


def test_paper_protocol_keeps_its_checkpoint_names_and_book_differs(tmp_path, monkeypatch):
    P = quick(tmp_path, monkeypatch)
    assert studies.checkpoint_stem(P, "pendulum", "drf", 0) == studies.checkpoint_stem(P, "pendulum", "drf", 0, "paper")
    assert "noise_head" not in studies.model_config("pendulum", "drf", P)
    book = studies.model_config("pendulum", "drf", P, "book")
    # the paper's architecture (LSTM transition, 30-dim latent, ELU + 1 r, decoder with dropout), the wider encoder
    assert not {"transition_kind", "memory_dims", "noise_head", "readout"} & set(book)
    assert book["latent"] == 30 and book["dropout_p"] == 0.1 and book["encoder_channels"] == 32
    assert "memory_dims" not in studies.model_config("pendulum", "lstm", P, "book")
    # the models of the book's protocol share its recipe and its training data (no pure-noise frames)
    kinds = ("drf", "lstm", "no_dynamics", "known_dynamics", "drf_calibrated")
    specs = [protocol_spec("book", kind) for kind in kinds]
    assert all(s["blackouts"] is None and s["train_max_noise"] == 0.5 for s in specs)
    assert all({k: v for k, v in s["train"].items() if k not in ("prior_weight", "obs_weight")} == FIT_THE_MEAN
               for s in specs)
    for kind in kinds[:3]:
        assert studies.checkpoint_stem(P, "pendulum", kind, 0, "book") != studies.checkpoint_stem(P, "pendulum", kind, 0)
    cfg = studies.train_config(P, "pendulum", "drf", 0, "book")
    assert (cfg.epochs, cfg.lr, cfg.batch_size) == (P.pendulum.book.epochs, P.pendulum.book.lr, P.pendulum.book.batch_size)
    with pytest.raises(ValueError, match="pedestrians study has no training protocol 'blackout'"):
        studies.model_config("pedestrians", "drf", None, "blackout")


def test_training_blackouts_touch_the_training_sequences_only(tmp_path, monkeypatch):
    # a protocol with training blackouts (the second round's) blacks out training frames, never the first
    # five, never validation; the book's protocol (the third round's) has none, so its data are the paper's
    import dataclasses

    from drfkit.models import DeepRecursiveFilter

    P = quick(tmp_path, monkeypatch)
    paper_train = studies.pendulum_data(P, "train")
    assert torch.equal(paper_train.inputs, studies.pendulum_data(P, "train", protocol="book").inputs)
    # the protocols are what the kinds' specs name: the DRF's spec, as the second round had it
    spec = DeepRecursiveFilter.spec
    monkeypatch.setattr(DeepRecursiveFilter, "spec", dataclasses.replace(
        spec, protocols=spec.protocols | {"book": "fit_prior_split_book"}))
    book_train = studies.pendulum_data(P, "train", protocol="book")
    changed = (paper_train.inputs != book_train.inputs).flatten(2).any(-1)          # (N, T) frames that differ
    assert changed.any() and not changed[:, :5].any()
    assert torch.equal(studies.pendulum_data(P, "val").inputs, studies.pendulum_data(P, "val", protocol="book").inputs)
    assert torch.equal(paper_train.targets, book_train.targets)


def test_protocol_table_joins_the_three_measurements():
    evals = pd.DataFrame({"model": ["drf", "drf", "lstm", "lstm"], "seed": [0, 0, 0, 0], "noise": [0.5, 0.75] * 2,
                          "mae": [0.1, 0.2, 0.3, 0.4]})
    mech = pd.DataFrame({"model": ["drf", "lstm"], "seed": [0, 0], "r_noise_spearman": [0.9, 0.1],
                         "gain_ratio_blackout": [0.2, np.nan]})
    dark = pd.DataFrame({"model": ["drf", "lstm"], "seed": [0, 0], "mae_blackout": [0.05, 0.5],
                         "mae_after_blackout": [0.01, 0.02]})
    table = dynamics.protocol_table("book", evals, mech, dark).set_index("model")
    assert table.loc["drf", "mae_0.75"] == 0.2 and table.loc["lstm", "mae_blackout"] == 0.5
    assert table.loc["drf", "gain_ratio_blackout"] == 0.2 and np.isnan(table.loc["lstm", "prior_ratio"])
    assert (table["protocol"] == "book").all()


def test_ablation_row_is_trained_once_and_reused(tmp_path, dynamics_profile):
    from drfkit.util.paths import data_dir

    P = dynamics_profile("quick")
    row = ablation.run_variant(P, "book", 0, "tiny", tmp_path, progress=False)
    assert row["variant"] == "book" and row["kind"] == "drf" and 0 < row["mae_0.5"] < 2
    for key in ("mae_0.75", "mae_1", "mae_blackout", "r_noise_spearman", "gain_ratio_blackout", "prior_ratio"):
        assert key in row
    path = tmp_path / "tiny" / "book-seed0.json"
    stamp = path.stat().st_mtime_ns
    assert ablation.run_variant(P, "book", 0, "tiny", tmp_path, progress=False) == json.loads(path.read_text())
    assert path.stat().st_mtime_ns == stamp
    assert list(data_dir(P.profile).glob("*val*")) and not list(data_dir(P.profile).glob("*test*"))  # never a test split
    ablation.run_variant(P, "no_dynamics_book", 0, "tiny", tmp_path, progress=False)
    table = ablation.ablation_table(P, "tiny", tmp_path)
    assert set(table["variant"]) == {"book", "no_dynamics_book"} and "mae_per_frame_blackout" not in table
    summary = summarise_ablation(table)
    assert list(summary.columns[:2]) == ["variant", "kind"] and (summary["n_seeds"] == 1).all()
    assert cli(["ablation", "--profile", "quick", "--budget", "tiny", "--out", str(tmp_path), "--summary"]) == 0
    assert table["current"].all() and summary["current"].all()
    # a row the present code would train differently (older frames, another schedule) is kept but marked
    stale = tmp_path / "tiny" / "no_dynamics_book-seed0.json"
    stale.write_text(json.dumps(json.loads(stale.read_text()) | {"key": "former"}))
    table = ablation.ablation_table(P, "tiny", tmp_path).set_index("variant")
    assert bool(table.loc["book", "current"]) and not bool(table.loc["no_dynamics_book", "current"])
    retired = tmp_path / "tiny" / "retired_variant-seed0.json"
    retired.write_text(json.dumps(json.loads(path.read_text()) | {"variant": "retired_variant"}))
    assert not bool(ablation.ablation_table(P, "tiny", tmp_path).set_index("variant").loc["retired_variant", "current"])


def test_ablation_cli_rejects_unknown_variants(capsys):
    assert cli(["ablation", "--variants", "nope", "--budget", "tiny"]) == 2
    assert "unknown variant" in capsys.readouterr().err


def test_the_third_rounds_choice_stays_an_ablation_row_and_the_book_trains_the_papers_drf(dynamics_profile):
    """The third round's rule (``ablation.mechanism_targets``: most of F1's and F2's targets met, then the
    lowest MAE at 0.75) still ranks the output-units DRF first on the committed validation rows, and the
    second round's its own choice; those stay ablation rows. The book protocol's DRF is the paper's
    architecture fit with the recipe that fits the mean and the wider encoder, as its baselines are."""
    from drfkit.methods.protocols import ROUND2_VARIANTS, ROUND3_VARIANTS, WIDE_ENCODER, variant_spec

    rows = ablation.ablation_table(dynamics_profile("paper", tmp=False), "fit")
    round2 = ablation.mechanism_targets(ablation.summarise_ablation(rows[rows["variant"].isin(list(ROUND2_VARIANTS))]))
    assert round2.iloc[0]["variant"] == "fit_prior_split_book"
    summary = ablation.summarise_ablation(rows[rows["variant"].isin(list(ROUND3_VARIANTS))])
    ranked = ablation.mechanism_targets(summary, pure_noise_free=True)
    assert ranked.iloc[0]["targets_met"] > ranked.iloc[1]["targets_met"] or \
        ranked.iloc[0]["mae_0.75"] <= ranked.iloc[1]["mae_0.75"]
    assert ranked.iloc[0]["variant"] == "fit_physical_book"
    chosen = variant_spec(PROTOCOLS["book"]["drf"])
    assert chosen == variant_spec("paper") | {"model": WIDE_ENCODER, "train": FIT_THE_MEAN}
    for kind in ("no_dynamics", "lstm", "known_dynamics", "drf_calibrated"):   # the same data, the same encoder
        spec = variant_spec(PROTOCOLS["book"][kind])
        assert spec["blackouts"] is None and spec["train_max_noise"] == 0.5 and spec["train"]["fresh_noise"]
        assert {k: spec["model"][k] for k in WIDE_ENCODER} == WIDE_ENCODER


def test_mechanism_targets_use_the_claims_thresholds_at_their_boundaries():
    from drfkit.study import claims

    row = {"variant": "fit_book", "kind": "drf", "n_seeds": 2, "r_noise_spearman": claims.F1_RANK_CORRELATION,
           "gain_ratio_blackout": claims.F1_GAIN_RATIO, "prior_ratio": claims.F1_PREDICTION_RATIO,
           "mae_blackout": claims.F2_BLACKOUT_MAE, "mae_0.5": 0.01, "mae_0.75": 0.05}
    noise1 = row | {"variant": "fit_paper_noise1", "prior_ratio": 0.5}
    one_seed = row | {"variant": "fit_paper", "n_seeds": 1}
    table = ablation.mechanism_targets(pd.DataFrame([row, noise1, one_seed]))
    assert table["variant"].tolist() == ["fit_book"]  # trained at 0.5, with two seeds
    assert table.iloc[0][["r_follows_noise", "gain_drops", "f_predicts", "coasts"]].tolist() == [True, True, False, True]


def test_the_pendulum_test_split_has_its_own_seed(tmp_path, monkeypatch):
    P = quick(tmp_path, monkeypatch)
    assert studies.split_seed(P, "test") == P.pendulum.test_seed != P.pendulum.data_seed + 2
    assert studies.split_seed(P, "val") == P.pendulum.data_seed + 1 and studies.split_seed(P, "train") == P.pendulum.data_seed
    test, val = studies.pendulum_split(P, "test"), studies.pendulum_split(P, "val")
    assert not np.array_equal(test["clean"][:, 0], val["clean"][:, 0])
    clash = quick(tmp_path, monkeypatch, pend_test_seed=P.pendulum.data_seed + 1)
    with pytest.raises(ValueError, match="pend_test_seed .* validation split's seed"):
        studies.pendulum_split(clash, "test")


def test_the_variants_are_data_and_every_committed_ablation_row_is_still_current(dynamics_profile):
    """params/protocols.yaml holds every variant; resolved, each names the same runs as before it moved there:
    every committed row of the protocol ablation (whose key is its run's ``run_key``) is current."""
    P = dynamics_profile("paper", tmp=False)

    assert set(VARIANTS) >= {"paper", "fit_paper_wide", "fit_calibrated_prior_wide", "fit_known_dynamics_wide"}
    assert variant_spec("fit_prior_split_book")["train"] == FIT_THE_MEAN | {"prior_weight": 1.0}
    assert variant_spec("book")["blackouts"] == {"fraction": 0.5, "lengths": (5, 20)}
    # the fit budget's rows, and the small budget's that notebook 02 reads (its other rows were made on the first
    # generator's frames and were stale before the variants moved)
    for budget, variants in (("fit", list(VARIANTS)), ("small", ["paper", "book", "no_dynamics_book", "lstm_book"])):
        table = ablation.ablation_table(P, budget)
        known = table[table["variant"].isin(variants)]
        assert len(known) and known["current"].all(), known.loc[~known["current"], ["variant", "seed"]]


def test_the_run_key_migration_moved_only_rows_that_were_current(dynamics_profile, load_tool):
    """tools/migrate_run_keys.py moved the ablation's and the regime map's rows from the ablation's former key to
    the one ``run_key``: every moved row's ``key_before`` is the former formula's key for it (it was current
    before the move), and nothing is left to move; the stale rows (the first generator's frames) stayed stale."""
    import json as _json

    from drfkit.util.paths import results_dir

    tool = load_tool("migrate_run_keys")
    P = dynamics_profile("paper", tmp=False)
    out = results_dir(P.profile, "ablation")
    moved = [(p, _json.loads(p.read_text())) for p in sorted(out.glob("*/*.json"))]
    moved = [(p, r) for p, r in moved if "key_before" in r]
    assert len(moved) >= 88
    for path, row in moved:
        assert row["key_before"] == tool.legacy_key(row["variant"], int(row["seed"]), path.parent.name), path
    counts = tool.migrate(P, out, write=False)
    assert counts["migrated"] == 0 and counts["already"] >= 120, counts


def test_the_ablation_trains_what_its_former_path_trained(dynamics_profile, load_tool):
    """The ablation goes the studies' way (``variant_run``): for every variant at the test budget, the same
    ``TrainConfig``, the same model (configuration and initial weights) and the same data as the former formula
    (tools/migrate_run_keys.py's frozen copy); and one ``run_key`` names a profile's checkpoint and an ablation run."""
    from drfkit.methods.run_config import run_key

    tool = load_tool("migrate_run_keys")
    P = dynamics_profile("quick")
    assert tool.verify(P, ["fit_tiny"], None) == []
    P1 = validate("01_pendulum_training", notebook_params("01_pendulum_training", load_profile("quick")))
    stem = studies.checkpoint_stem(P1, "pendulum", "drf", 0, "book")
    cfg = studies.model_config("pendulum", "drf", P1, "book")
    train = studies.train_config(P1, "pendulum", "drf", 0, "book")
    assert stem.name.endswith(run_key(cfg, train, studies.study_data_key(P1, "pendulum", "book")))


@pytest.mark.parametrize("entry,message", [
    ("x: {kind: drf, model: nope}", "unknown part 'nope'"),
    ("x: {kind: drf, colour: red}", r"fields \['colour'\] unknown"),
    ("x: {model: wide}", "'kind' missing"),
    ("x: {kind: drf, train: [fit_the_mean, {epochs: 3}]}", r"recipe fields \['epochs'\] unknown"),
    ("x: {kind: drf, train_max_noise: 1.5}", r"train_max_noise must lie in \[0, 1\]"),
    ("x: {kind: drf, blackouts: {fraction: 0.5}}", "blackouts need 'fraction' and 'lengths'"),
])
def test_a_bad_recipe_file_is_refused_with_what_to_fix(tmp_path, entry, message):
    from drfkit.methods.protocols import load_variants

    path = tmp_path / "protocols.yaml"
    path.write_text("parts:\n  wide: {encoder_channels: 32}\n  fit_the_mean: {objective: beta_nll}\nrounds:\n  1:\n    "
                    + entry + "\n")
    with pytest.raises(ValueError, match=message):
        load_variants(path)
    with pytest.raises(FileNotFoundError, match="restore it from git"):
        load_variants(tmp_path / "missing.yaml")


def test_a_local_checkpoint_of_the_former_path_is_moved_not_retrained(tmp_path, dynamics_profile, load_tool,
                                                                       monkeypatch):
    """tools/migrate_run_keys.py's ``migrate_checkpoints``: a run stored under the former stem and fingerprint (as
    the ablation wrote them) is renamed and re-fingerprinted, and then found finished by ``train_variant``."""
    from drfkit.methods import train as train_module
    from drfkit.methods.run_config import fingerprint
    from drfkit.util.io import atomic_torch_save, torch_load_checked

    tool = load_tool("migrate_run_keys")
    P = dynamics_profile("quick")
    res, run = ablation.train_variant(P, "book", 0, "tiny", tmp_path, progress=False)
    legacy = tool.legacy_key("book", 0, "tiny")
    former_fp = fingerprint(tool.legacy_model_config(run.spec), run.train, legacy)
    old_stem = run.folder / "models" / f"book-seed0-{legacy}"
    best, last = torch_load_checked(res.best_path), torch_load_checked(res.last_path)
    best = best | {"config": tool.legacy_model_config(run.spec), "meta": best["meta"] | {"fingerprint": former_fp, "data": legacy}}
    atomic_torch_save(f"{old_stem}-best.pt", best)
    atomic_torch_save(f"{old_stem}-last.pt", last | {"fingerprint": former_fp, "best": best})
    res.best_path.unlink()
    res.last_path.unlink()
    assert tool.migrate_checkpoints(P, tmp_path, write=True) == {"moved": 1, "already": 0, "skipped": 0}
    assert not list((run.folder / "models").glob(f"*{legacy}*"))
    assert tool.migrate_checkpoints(P, tmp_path, write=False) == {"moved": 0, "already": 1, "skipped": 0}

    def no_training(*args, **kwargs):
        raise AssertionError("a moved checkpoint was trained again")

    monkeypatch.setattr(train_module, "train_model", no_training)
    again, _ = ablation.train_variant(P, "book", 0, "tiny", tmp_path, progress=False)
    assert again.best_epoch == res.best_epoch and again.best_path == res.best_path
