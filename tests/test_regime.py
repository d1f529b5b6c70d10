"""The noise-regime map: its variants are the book's protocol at another training noise, its rows
are computed once on a test split of their own, and its summary is what the rows say."""
from __future__ import annotations

import json

import numpy as np
import pytest

from drfkit.study import ablation, regime
from drfkit.methods.protocols import REGIME_BASES, REGIME_TRAIN_NOISE, VARIANTS, regime_variant, variant_spec
from drfkit.cli import main as cli

LEVELS = [0.0, 0.5, 1.0]


def test_regime_variants_are_the_book_protocol_at_another_noise():
    for kind, base in REGIME_BASES.items():
        assert regime_variant(kind, 0.5) == base and VARIANTS[base]["kind"] == kind
        for level in REGIME_TRAIN_NOISE:
            spec, book = variant_spec(regime_variant(kind, level)), variant_spec(base)
            assert spec["train_max_noise"] == level and book["train_max_noise"] == 0.5
            assert {k: v for k, v in spec.items() if k != "train_max_noise"} == \
                   {k: v for k, v in book.items() if k != "train_max_noise"}
    with pytest.raises(ValueError, match="regime map trains"):
        regime_variant("monoloco", 0.5)


@pytest.fixture(scope="module")
def tiny_map(tmp_path_factory):
    from drfkit.study.params import for_notebook, load_profile

    out = tmp_path_factory.mktemp("regime")
    with pytest.MonkeyPatch.context() as mp:  # the data cache beside the rows, for the module's tests
        mp.setenv("DRF_RESULTS", str(out))
        P = for_notebook("02_pendulum_dynamics", load_profile("quick"))
        table = regime.regime_map(P, [0.5], [0], "tiny", out, LEVELS, n_test=3, n_samples=4, n_particles=30)
    return out, table, P


def test_map_has_every_model_level_and_the_blackout(tiny_map):
    _, table, _ = tiny_map
    assert set(table["model"]) == set(REGIME_BASES) | {"physics_reference"}
    for _, rows in table.groupby("model"):
        assert sorted(rows["test"]) == sorted([f"{lv:g}" for lv in LEVELS] + ["blackout", "after_blackout"])
    assert table["mae"].between(0, 2).all()
    assert table.loc[table["test"].str.contains("blackout"), "test_noise"].isna().all()


def test_rows_are_cached_and_recomputed_when_a_setting_changes(tiny_map, monkeypatch):
    out, table, P = tiny_map
    monkeypatch.setenv("DRF_RESULTS", str(out))
    files = sorted((out / "tiny" / "regime").glob("*.json"))
    assert len(files) == len(REGIME_BASES) + 1
    assert list((out / "quick" / "data").glob("pendulum-test-*.npz"))  # its own test split, beside the ablation's

    def no_training(*args, **kwargs):
        raise AssertionError("a cached regime row was trained again")

    monkeypatch.setattr(ablation, "train_variant", no_training)
    again = regime.regime_map(P, [0.5], [0], "tiny", out, LEVELS, n_test=3, n_samples=4, n_particles=30)
    assert again.equals(table)
    with pytest.raises(AssertionError, match="trained again"):  # another test size needs the models
        regime.regime_map(P, [0.5], [0], "tiny", out, LEVELS, n_test=2, n_samples=4, n_particles=30)


def test_the_test_split_is_not_the_validation_split(tiny_map, monkeypatch):
    from drfkit.data.noise import Noise
    from drfkit.study.pendulum_runs import load_split

    out, _, P = tiny_map
    monkeypatch.setenv("DRF_RESULTS", str(out))
    test = regime._test_sets(P, "tiny", [0.5], 3)[0.5]
    val = load_split(ablation.budget_splits(P, "tiny"), "val", Noise("rkn_uniform", 0.5))
    assert not np.allclose(test["targets"][:, 0], val["targets"][:3, 0])
    assert ablation.regime_test_seed(P) == P.pendulum.data_seed + 2 != P.pendulum.test_seed  # not the study's test split


def test_summary_ratios_follow_the_rows(tiny_map):
    _, table, _ = tiny_map
    summary = regime.regime_summary(table).set_index(["train_noise", "test"])
    row = summary.loc[(0.5, "0.5")]
    mae = table[(table["test"] == "0.5")].set_index("model")["mae"]
    assert row["drf_over_no_dynamics"] == pytest.approx(mae["drf"] / mae["no_dynamics"])
    assert row["drf_over_reference"] == pytest.approx(mae["drf"] / mae["physics_reference"])


def test_the_figure_has_a_panel_per_training_noise_and_the_blackout(tiny_map):
    import matplotlib

    matplotlib.use("Agg")
    from drfkit.report.figures import plot_regime

    _, table, _ = tiny_map
    fig = plot_regime(table, list(REGIME_BASES))
    assert len(fig.axes) == 2


def test_reference_row_records_its_calibration(tiny_map):
    out, _, _ = tiny_map
    row = json.loads((out / "tiny" / "regime" / "physics_reference-train0.5-seed0.json").read_text())
    assert row["sigma_scale"] > 0 and 0 <= row["outlier"] < 1 and row["n_particles"] == 30


def test_the_command_names_a_bad_profile(capsys):
    assert cli(["regime", "--profile", "no-such-profile"]) == 2
    assert "does not exist" in capsys.readouterr().out


def test_the_paper_profile_finds_every_regime_row_committed(monkeypatch):
    """A reproduction of the committed paper profile trains nothing: every (training noise, model, seed)
    of its regime map, the physics reference included, is a committed row whose key matches the
    profile's settings (a missing or stale row would make notebook 02 train for about an hour)."""
    from drfkit.study.params import for_notebook, load_profile

    def refuse(P, name, seed, *args):
        raise AssertionError(f"the regime map would train {name} seed {seed}: commit its row "
                             f"(python -m drfkit regime --profile paper)")

    monkeypatch.setattr(regime, "_model", refuse)
    P = for_notebook("02_pendulum_dynamics", load_profile("paper"))
    table = regime.profile_map(P)
    assert set(table["model"]) == {*REGIME_BASES, "physics_reference"}
    assert set(table["train_noise"]) == set(map(float, P.dynamics.regime.train_noise))
