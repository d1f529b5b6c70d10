"""Tests for drfkit.methods.gating and drfkit.study.gating_study: the competency score, random gating,
threshold choice on validation data only, and gated inference (MC dropout on selected frames,
deterministic elsewhere) against the no-dropout and always-dropout results."""
from __future__ import annotations

from drfkit.study.profile import build_profile
import inspect
import math
from types import SimpleNamespace

import numpy as np
import pytest
import torch

import drfkit.models.parts as parts
from drfkit.methods import gating
from drfkit.methods import gate_evaluation
from drfkit.methods.timing import clock
from drfkit.study import gating_study
from drfkit.core.metrics import rank_correlation
from drfkit.models import build_model, default_config
from drfkit.methods.train import SequenceData

torch.set_num_threads(1)

B, T, LATENT = 6, 5, 4


def tiny_drf(seed: int = 0, kind: str = "drf"):
    torch.manual_seed(seed)
    extra = {"transition_hidden": 8} if kind == "drf" else {}
    cfg = default_config(kind, "keypoints", 1, latent=LATENT, feature_dim=8, decoder_hidden=16,
                         dropout_p=0.3, **extra)
    return build_model(cfg).eval()


def keypoint_data(seed: int = 0, offset: float = 0.0, padded: bool = True) -> SequenceData:
    g = torch.Generator().manual_seed(seed)
    x = torch.randn(B, T, 17, 3, generator=g)
    x[..., 2] = torch.rand(B, T, 17, generator=g)
    y = 10.0 + offset + torch.randn(B, T, 1, generator=g)
    mask = torch.ones(B, T, dtype=torch.bool)
    if padded:  # trailing padding on some sequences
        mask[0, 3:] = False
        mask[2, 4:] = False
    return SequenceData(x, y, mask)


def stage(model, data, setting, **kw):
    h, gains = model.features(data.inputs, return_gains=True)
    return gating.uncertainty_stage(model, h, gains, data.mask, setting, n_samples=8, dropout_p=0.3, **kw)


# --------------------------------------------------------------------------- scores
def test_mean_gain_and_competency_score_shapes_and_values():
    gains = torch.rand(3, 7, 5, 5)
    k = gating.mean_gain(gains)
    assert k.shape == (3, 7)
    torch.testing.assert_close(k[1, 2], gains[1, 2].diagonal().mean())
    torch.testing.assert_close(gating.competency_score(gains, 1), k)
    torch.testing.assert_close(gating.competency_score(gains, -1), 1.0 - k)
    with pytest.raises(ValueError, match="direction"):
        gating.competency_score(gains, 0)
    with pytest.raises(ValueError, match=r"\(B, T, n, n\)"):
        gating.mean_gain(torch.rand(3, 7, 5))


def test_score_from_a_real_filter_is_per_frame_and_first_gain_is_identity():
    model = tiny_drf()
    gains = model.kalman_gains(keypoint_data().inputs)
    assert gains.shape == (B, T, LATENT, LATENT)
    score = gating.competency_score(gains, 1)
    assert score.shape == (B, T)
    assert torch.allclose(score[:, 0], torch.ones(B))  # K_0 = I: mean gain 1
    assert torch.allclose(gating.competency_score(gains, -1)[:, 0], torch.zeros(B))


def test_rank_correlation_and_direction_known_answers():
    x = np.arange(20.0)
    assert rank_correlation(x, x ** 3) == pytest.approx(1.0)
    assert rank_correlation(x, -np.exp(x)) == pytest.approx(-1.0)
    assert math.isnan(rank_correlation(x, np.ones(20)))
    assert gating.choose_direction(x, x ** 2) == (1, pytest.approx(1.0))
    assert gating.choose_direction(x, -x)[0] == -1
    assert gating.choose_direction(x, np.ones(20))[0] == gating.DEFAULT_DIRECTION


# --------------------------------------------------------------------------- random gating
@pytest.mark.parametrize("fraction", [0.0, 0.1, 0.37, 0.5, 1.0])
def test_random_gating_selects_exactly_round_f_n_real_frames(fraction):
    mask = keypoint_data().mask
    n_real = int(mask.sum())
    sel = gating.random_gating(mask, fraction, seed=3)
    assert sel.shape == mask.shape and sel.dtype == torch.bool
    assert int(sel.sum()) == round(fraction * n_real)
    assert not (sel & ~mask).any()  # never a padded frame


def test_random_gating_is_seeded_and_seeds_differ():
    mask = torch.ones(20, 30, dtype=torch.bool)
    a, b = gating.random_gating(mask, 0.3, seed=1), gating.random_gating(mask, 0.3, seed=1)
    c = gating.random_gating(mask, 0.3, seed=2)
    assert torch.equal(a, b)
    assert not torch.equal(a, c)
    assert int(a.sum()) == int(c.sum()) == 180
    with pytest.raises(ValueError, match="n_selected"):
        gating.random_selection(mask, 601, seed=0)


# --------------------------------------------------------------------------- thresholds
def test_threshold_for_fraction_selects_that_fraction_of_validation_scores():
    scores = np.random.default_rng(0).permutation(100).astype(float)
    for f in (0.1, 0.3, 0.55):
        thr = gating.threshold_for_fraction(scores, f)
        assert int((scores > thr).sum()) == round(100 * f)
    assert gating.threshold_for_fraction(scores, 0.0) == gating.NEVER
    assert gating.threshold_for_fraction(scores, 1.0) == gating.ALWAYS
    assert not (torch.tensor(scores) > gating.NEVER).any() and (torch.tensor(scores) > gating.ALWAYS).all()


def test_choose_threshold_known_answer():
    """Targets far from the deterministic mean exactly on the 30 highest-score frames; MC
    intervals cover everything. PICP(f) = 0.7 + min(f, 0.3), so tolerance 0 picks f = 0.3,
    tolerance 0.15 picks the first grid fraction >= 0.15 (0.2)."""
    n = 100
    scores = np.arange(n, dtype=float)
    y = np.where(scores >= 70, 1.0, 0.0)[:, None]
    det = (np.zeros((n, 1)), np.full((n, 1), 0.01))
    mc = (np.zeros((n, 1)), np.full((n, 1), 10.0))
    thr, table = gating.choose_threshold(scores, y, det, mc, tolerance=0.0, n_points=11)
    assert int((scores > thr).sum()) == 30
    chosen = table[table["chosen"]].iloc[0]
    assert chosen["target_fraction"] == pytest.approx(0.3) and chosen["val_picp"] == pytest.approx(1.0)
    np.testing.assert_allclose(table["val_picp"], 0.7 + np.minimum(table["target_fraction"], 0.3))
    thr2, _ = gating.choose_threshold(scores, y, det, mc, tolerance=0.15, n_points=11)
    assert int((scores > thr2).sum()) == 20
    with pytest.raises(ValueError, match="N = 50 scores"):
        gating.choose_threshold(scores[:50], y, det, mc, tolerance=0.0, n_points=11)


def test_threshold_api_takes_validation_arrays_only():
    for fn in (gating.choose_threshold, gating.choose_direction, gating.fit_gate):
        params = inspect.signature(fn).parameters
        assert not any("test" in name for name in params), (fn.__name__, list(params))


def test_study_chooses_the_gate_without_reading_test_data(monkeypatch):
    """Test targets carry a sentinel (+1000); every array the direction and threshold are
    chosen from is recorded and must hold validation values only."""
    val, test = keypoint_data(seed=1), keypoint_data(seed=2, offset=1000.0)
    recorded = []
    real_direction, real_threshold = gating.choose_direction, gating.choose_threshold

    def record_direction(*args):
        recorded.append(("direction", args))
        return real_direction(*args)

    def record_threshold(*args, **kwargs):
        recorded.append(("threshold", args))
        return real_threshold(*args, **kwargs)

    monkeypatch.setattr(gating, "choose_direction", record_direction)
    monkeypatch.setattr(gating, "choose_threshold", record_threshold)
    served = []

    def fake_data(P, split, noise=None, protocol="paper"):
        served.append((split, noise))
        return val if split == "val" else test

    from drfkit.study import registry, studies

    def fake_study_data(P, study, split, noise=None, protocol="paper"):
        # what the studies layer serves: the entry's callable with the entry's Noise
        return fake_data(P, split, registry.study(study).noise(noise, P), protocol)

    monkeypatch.setattr(studies, "study_data", fake_study_data)
    P = build_profile(dict(ped_eval_p=[0.01, 0.05], ped_train_p=0.01, device="cpu", n_samples=4, gating_picp_tolerance=0.01,
                           gating_sweep_points=3, gating_timing_frames=0, interval_level=0.95), "a test")
    out = gating_study.gating_study(P, "pedestrians", models={("drf", 0): tiny_drf(), ("lstm", 0): None},
                                    min_run_time=0.001)
    # the gate at the test noise, the test set, the gate at the training noise: each fit on validation alone
    assert [(split, noise.level) for split, noise in served] == [("val", 0.05), ("test", 0.05), ("val", 0.01)]
    assert [kind for kind, _ in recorded] == ["direction", "threshold"] * 2
    for _, args in recorded:
        for a in args:
            for arr in (a if isinstance(a, tuple) else (a,)):
                assert np.abs(np.asarray(arr)).max() < 500, "a test array reached the gate's choice"
    val_targets = val.targets[val.mask].numpy()
    np.testing.assert_allclose(recorded[1][1][1], val_targets)
    np.testing.assert_allclose(recorded[3][1][1], val_targets)
    # the test set was used afterwards (sentinel targets: nothing is covered)
    assert (out["table"]["picp"] == 0).all() and set(out["table"]["seed"]) == {0}


def test_the_study_without_its_sweep_keeps_the_settings_metrics_and_times_only_them(monkeypatch):
    """sweep=False (the gate tuned at the training noise, whose sweep nothing reads): the same four
    settings with the same metrics as with the sweep, an empty sweep, and no sweep threshold timed."""
    import pandas as pd

    from drfkit.study import studies

    val, test = keypoint_data(seed=11), keypoint_data(seed=12)
    monkeypatch.setattr(studies, "study_data", lambda P, study, split, noise=None, protocol="paper":
                        val if split == "val" else test)
    timed = []
    real_measure = clock.measure_interleaved

    def counting(fns, *args, **kwargs):
        timed.append(set(fns))
        return real_measure(fns, *args, **kwargs)

    monkeypatch.setattr("drfkit.methods.gate_evaluation.measure_interleaved", counting)
    P = build_profile(dict(ped_eval_p=[0.01, 0.05], ped_train_p=0.01, device="cpu", n_samples=4, gating_picp_tolerance=0.01,
                           gating_sweep_points=3, gating_timing_frames=0, interval_level=0.95), "a test")
    models = {("drf", 0): tiny_drf()}
    full = gating_study.gating_study(P, "pedestrians", models=models, min_run_time=0.001)
    n_full = len(timed[0])
    timed.clear()
    alone = gating_study.gating_study(P, "pedestrians", models=models, min_run_time=0.001, sweep=False)
    assert len(full["sweep"]) > 0 and alone["sweep"].empty
    assert list(alone["sweep"].columns[:4]) == ["study", "seed", "noise", "val_noise"]
    metrics = ["setting", "threshold", "fraction", "n_selected", "picp", "mpiw", "nll", "mae"]
    pd.testing.assert_frame_equal(alone["table"][metrics], full["table"][metrics])
    assert timed[0] == {"no_dropout", "always", "kalman_gain", "random", "kalman_gain@train", "random@train"}
    assert n_full > len(timed[0])


def test_the_training_noise_gate_is_evaluated_and_timed_in_the_first_gates_pass(monkeypatch):
    """One pass of the test set per seed: the gate tuned at the training noise is fit on validation at that noise,
    its rows come from the same passes (no_dropout and always are the first table's own) and are timed in the
    same interleaved run; its table matches evaluating that gate on its own."""
    import pandas as pd

    from drfkit.methods import gate_evaluation as ge
    from drfkit.study import studies

    val_test, val_train, test = keypoint_data(seed=11), keypoint_data(seed=13), keypoint_data(seed=12)
    served = []

    def data(P, study, split, noise=None, protocol="paper"):
        served.append((split, noise))
        return test if split == "test" else (val_train if noise == 0.01 else val_test)

    monkeypatch.setattr(studies, "study_data", data)
    passes = []
    real_stage = ge.uncertainty_stage
    monkeypatch.setattr(ge, "uncertainty_stage", lambda *a, **k: passes.append(1) or real_stage(*a, **k))
    P = build_profile(dict(ped_eval_p=[0.01, 0.05], ped_train_p=0.01, device="cpu", n_samples=4,
                           gating_picp_tolerance=0.01, gating_sweep_points=3, gating_timing_frames=0,
                           interval_level=0.95), "a test")
    model = tiny_drf()
    out = gating_study.gating_study(P, "pedestrians", models={("drf", 0): model}, min_run_time=0.001, sweep=False)
    assert sorted(served) == [("test", 0.05), ("val", 0.01), ("val", 0.05)]  # each split read once
    train, first = out["table_train"].set_index("setting"), out["table"].set_index("setting")
    assert set(train.index) == set(first.index) == set(gating.SETTINGS)
    assert (train["val_noise"] == 0.01).all() and (first["val_noise"] == 0.05).all()
    for shared in ("no_dropout", "always"):
        assert train.loc[shared, ["picp", "time_ms", "head_ms"]].tolist() == first.loc[shared, ["picp", "time_ms", "head_ms"]].tolist()
    gate_train, _ = gating.fit_gate(model, val_train, n_samples=4, tolerance=0.01, n_points=3, seed=0)
    alone = ge.evaluate_gate(model, gate_train, test, n_samples=4, seed=0, min_run_time=0.001).set_index("setting")
    metrics = ["threshold", "fraction", "picp", "mpiw", "nll", "mae"]
    pd.testing.assert_frame_equal(train.loc[list(gating.SETTINGS), metrics], alone.loc[list(gating.SETTINGS), metrics])
    row = out["train_gate"].iloc[0]
    assert row["val_noise"] == 0.01 and row["test_fraction"] == train.loc["kalman_gain", "fraction"]
    assert row["direction"] == gate_train.direction and row["val_fraction"] == gate_train.val_fraction


# --------------------------------------------------------------------------- gated inference
def layout_free_dropout(h, n_samples, p, uniforms=None):
    """A dropout mask that depends only on a value and the sample index, not on where the
    frame sits in the batch, so gathered and full-batch passes draw the same masks."""
    s = torch.arange(1, n_samples + 1, dtype=h.dtype).view(-1, *([1] * h.ndim))
    keep = torch.sin(h.unsqueeze(0) * 37.0 * s + s) > -0.6
    return h.unsqueeze(0) * keep / (1.0 - p)


def test_gated_head_equals_always_on_selected_frames_and_deterministic_elsewhere(monkeypatch):
    monkeypatch.setattr(parts, "mc_dropout", layout_free_dropout)
    model, data = tiny_drf(), keypoint_data()
    always, det = stage(model, data, "always"), stage(model, data, "no_dropout")
    selected = gating.random_gating(data.mask, 0.4, seed=0)
    h, _ = model.features(data.inputs)
    gated = gating.gated_head(model, h, selected, n_samples=8, dropout_p=0.3)
    assert torch.equal(gated.selected, selected)
    assert (always.epistemic[selected] > 0).all()  # the comparison is not between zeros
    for field in ("mean", "aleatoric", "epistemic", "total"):
        g, a, d = (getattr(p, field) for p in (gated, always, det))
        torch.testing.assert_close(g[selected], a[selected], rtol=1e-5, atol=1e-6)
        torch.testing.assert_close(g[~selected], d[~selected], rtol=1e-5, atol=1e-6)
    assert (gated.epistemic[~selected] == 0).all()


def test_assembled_metrics_are_gated_inference_on_common_masks(monkeypatch):
    # with masks that depend on the frame alone, a gated pass and the assembly of two full passes agree
    monkeypatch.setattr(parts, "mc_dropout", layout_free_dropout)
    model, data = tiny_drf(), keypoint_data()
    always, det = stage(model, data, "always"), stage(model, data, "no_dropout")
    h, gains = model.features(data.inputs, return_gains=True)
    median = float(gating.competency_score(gains.detach(), 1)[data.mask].median())
    for setting, kw in (("kalman_gain", {"direction": 1, "threshold": median}), ("random", {"n_random": 11})):
        selected = gating.select_frames(setting, gains, data.mask, **kw)
        assert 0 < int(selected.sum()) < int(data.mask.sum())
        gated, built = gating.gated_head(model, h, selected, 8, 0.3), gating.assemble(det, always, selected)
        for field in ("mean", "aleatoric", "epistemic", "total"):
            torch.testing.assert_close(getattr(built, field), getattr(gated, field), rtol=1e-5, atol=1e-6)
    with pytest.raises(ValueError, match="gated settings"):
        gating.select_frames("always", gains, data.mask)


def test_never_threshold_is_no_dropout_and_always_threshold_is_always_with_real_dropout():
    model, data = tiny_drf(), keypoint_data(padded=False)
    torch.manual_seed(5)
    always = stage(model, data, "always")
    det = stage(model, data, "no_dropout")
    never = stage(model, data, "kalman_gain", direction=1, threshold=gating.NEVER)
    torch.manual_seed(5)  # same seed: the gathered (1, B*T) pass draws the same masks
    every = stage(model, data, "kalman_gain", direction=-1, threshold=gating.ALWAYS)
    assert not never.selected.any() and every.selected.all()
    for field in ("mean", "aleatoric", "epistemic", "total"):
        torch.testing.assert_close(getattr(never, field), getattr(det, field), rtol=0, atol=0)
        torch.testing.assert_close(getattr(every, field), getattr(always, field), rtol=1e-5, atol=1e-6)
    assert (always.epistemic > 0).all()


def test_run_setting_equals_features_then_stage_and_checks_its_arguments():
    model, data = tiny_drf(), keypoint_data()
    torch.manual_seed(0)
    whole = gating.run_setting(model, data.inputs, data.mask, "random", n_samples=8, dropout_p=0.3,
                               n_random=7, random_seed=1)
    torch.manual_seed(0)
    parts_ = stage(model, data, "random", n_random=7, random_seed=1)
    torch.testing.assert_close(whole.total, parts_.total)
    assert int(whole.selected.sum()) == 7
    with pytest.raises(ValueError, match="fit_gate"):
        stage(model, data, "kalman_gain")
    with pytest.raises(ValueError, match="n_random"):
        stage(model, data, "random")
    with pytest.raises(ValueError, match="drf"):
        gating.run_setting(tiny_drf(kind="no_dynamics"), data.inputs, data.mask, "kalman_gain",
                           n_samples=8, dropout_p=0.3, direction=1, threshold=0.5)


# --------------------------------------------------------------------------- evaluation
def test_evaluate_gate_and_sweep_rows_are_consistent():
    model, val, test = tiny_drf(), keypoint_data(seed=1), keypoint_data(seed=2, padded=False)
    gate, val_table = gating.fit_gate(model, val, n_samples=6, tolerance=0.0, n_points=4, seed=0)
    assert gate.direction in (1, -1) and len(gate.sweep_thresholds) == 4
    assert val_table["chosen"].sum() == 1
    table, sweep = gate_evaluation.sweep_gate(model, gate, test, n_samples=6, seed=0, min_run_time=0.001)
    assert list(table["setting"]) == ["no_dropout", "always", "kalman_gain", "random"]
    by = table.set_index("setting")
    assert by.loc["no_dropout", "fraction"] == 0 and by.loc["always", "fraction"] == 1
    assert by.loc["random", "n_selected"] == by.loc["kalman_gain", "n_selected"]
    assert table["picp"].between(0, 1).all() and (table["head_ms"] > 0).all() and (table["whole_ms"] > 0).all()
    np.testing.assert_allclose(table["time_ms"], table["features_ms"] + table["head_ms"])
    timed = sweep[sweep["method"] != "oracle"]
    assert sweep["whole_ms"].isna().all() and (timed["time_ms"] > 0).all()
    assert sweep.loc[sweep["method"] == "oracle", "time_ms"].isna().all()  # reads the targets: compared, never timed
    assert (table["frames"] == int(test.mask.sum())).all()
    assert len(sweep) == 12 and set(sweep["method"]) == {"kalman_gain", "random", "oracle"}
    for method in ("kalman_gain", "random", "oracle"):
        rows = sweep[sweep["method"] == method].sort_values("val_fraction")
        assert rows["fraction"].iloc[0] == 0 and rows["fraction"].iloc[-1] == 1
        # never = no dropout, always = always (same seed for the masks)
        for end, setting in ((0, "no_dropout"), (-1, "always")):
            for metric in ("picp", "mpiw", "nll"):
                assert rows[metric].iloc[end] == by.loc[setting, metric]  # assembled from the same two passes
    kg = sweep[sweep["method"] == "kalman_gain"].set_index("val_fraction")["fraction"]
    rnd = sweep[sweep["method"] == "random"].set_index("val_fraction")["fraction"]
    oracle = sweep[sweep["method"] == "oracle"].set_index("val_fraction")
    assert (kg == rnd).all() and (oracle["fraction"] == kg).all()


def test_oracle_selection_takes_the_largest_errors_among_real_frames():
    error = torch.tensor([[0.1, 0.9, 0.5], [0.7, 0.2, 0.95]])
    mask = torch.tensor([[True, True, True], [True, True, False]])
    sel = gating.oracle_selection(error, mask, 2)
    assert sel.tolist() == [[False, True, False], [True, False, False]]  # 0.95 is padding, never chosen
    assert not gating.oracle_selection(error, mask, 0).any()
    assert gating.oracle_selection(error, mask, 5).tolist() == mask.tolist()
    for bad in (6, -1, 1.5):
        with pytest.raises(ValueError, match="n_selected"):
            gating.oracle_selection(error, mask, bad)


def test_timing_subset_is_evenly_spaced_fixed_and_checked():
    lengths = torch.full((10,), 5)
    assert clock.timing_subset(lengths, 0).tolist() == list(range(10))
    assert clock.timing_subset(lengths, 50).tolist() == list(range(10))
    idx = clock.timing_subset(torch.full((1000,), 75), 7500)  # the paper's pendulum: 100 sequences
    assert idx.numel() == 100 and idx[0] == 0 and idx[-1] == 999 and bool((idx.diff() > 0).all())
    assert torch.equal(idx, clock.timing_subset(torch.full((1000,), 75), 7500))
    assert clock.timing_subset(torch.tensor([1, 2, 3, 4]), 5).numel() == 2  # ceil(4 * 5 / 10)
    for bad in (-1, 2.5, True):
        with pytest.raises(ValueError, match="gating_timing_frames"):
            clock.timing_subset(lengths, bad)


def test_times_come_from_the_timed_subset_and_metrics_from_every_test_sequence(monkeypatch):
    model, val, test = tiny_drf(), keypoint_data(seed=1), keypoint_data(seed=2)
    gate, _ = gating.fit_gate(model, val, n_samples=6, tolerance=0.0, n_points=4, seed=0)
    thresholds = gate_evaluation.sweep_thresholds(gate)
    full = gate_evaluation.evaluate_gate(model, gate, test, n_samples=6, seed=0, min_run_time=0.001,
                                         thresholds=thresholds)
    idx = clock.timing_subset(test.mask.sum(dim=1), 12)  # ceil(6 * 12 / 27) = 3: sequences 0, 2, 5
    assert idx.tolist() == [0, 2, 5]
    subset_mask = test.mask[idx]
    feature_batches, stage_calls = [], []
    real_features, real_stage = model.features, gating.uncertainty_stage

    def features(x, return_gains=False):
        feature_batches.append(x.shape[0])
        return real_features(x, return_gains=return_gains)

    def stage_(model_, h, gains, mask, setting, **kw):
        stage_calls.append((h.shape[0], setting, kw.get("threshold"), kw.get("n_random"), mask.clone()))
        return real_stage(model_, h, gains, mask, setting, **kw)

    monkeypatch.setattr(model, "features", features)
    monkeypatch.setattr(gating, "uncertainty_stage", stage_)  # run_setting's stage
    monkeypatch.setattr(gate_evaluation, "uncertainty_stage", stage_)  # evaluate_gate's
    sub = gate_evaluation.evaluate_gate(model, gate, test, n_samples=6, seed=0, min_run_time=0.001,
                                        thresholds=thresholds, timing_frames=12)
    # metrics: one pass over all B sequences, identical to the untimed-subset run
    metrics = ["setting", "threshold", "fraction", "n_selected", "picp", "mpiw", "nll", "mae"]
    assert sub[metrics].equals(full[metrics])
    assert (sub["frames"] == int(test.mask.sum())).all()
    assert (sub["timed_frames"] == int(subset_mask.sum())).all() and sub["timed_frames"].iloc[0] < sub["frames"].iloc[0]
    assert feature_batches[0] == B and set(feature_batches[1:]) == {3}
    n_full_stage = 2  # metrics: one deterministic and one always pass over every test sequence
    assert [c[1] for c in stage_calls[:n_full_stage]] == ["no_dropout", "always"]
    assert {c[0] for c in stage_calls[:n_full_stage]} == {B} and {c[0] for c in stage_calls[n_full_stage:]} == {3}
    # on the subset a random twin draws as many frames as its Kalman-gain gate selects there
    _, gains_sub = real_features(test.inputs[idx], return_gains=True)
    for _, setting, _, n_random, mask in stage_calls[n_full_stage:]:
        assert torch.equal(mask, subset_mask)
        if setting == "random":
            assert 0 <= n_random <= int(subset_mask.sum())
    timed_kg = {thr for b, s, thr, _, _ in stage_calls[n_full_stage:] if s == "kalman_gain"}
    timed_counts = {int(gating.Gate(**{**gate.__dict__, "threshold": thr}).select(gains_sub, subset_mask).sum())
                    for thr in timed_kg}
    timed_random = {n for b, s, _, n, _ in stage_calls[n_full_stage:] if s == "random"}
    assert timed_random == timed_counts
    timed = ~sub["setting"].str.startswith("oracle")  # the oracle twins read the targets: metrics only
    assert sub.loc[~timed, "time_ms"].isna().all() and timed.sum() == len(sub) - len(thresholds)
    sub = sub[timed]
    assert (sub["time_ms"] > 0).all() and np.allclose(sub["batch_ms"], sub["time_ms"] * sub["timed_frames"])


def test_selected_fraction_of_never_and_always_gates():
    model, data = tiny_drf(), keypoint_data()
    gate, _ = gating.fit_gate(model, data, n_samples=4, tolerance=0.0, n_points=3)
    for threshold, expected in ((gating.NEVER, 0.0), (gating.ALWAYS, 1.0)):
        g = gating.Gate(**{**gate.__dict__, "threshold": threshold})
        assert gate_evaluation.selected_fraction(model, g, data) == expected


def test_paper_table_has_picp_as_fraction():
    paper = gating_study.paper_table()
    assert len(paper) == 8 and set(paper["setting"]) == set(gating.SETTINGS)
    row = paper[(paper["study"] == "pendulum") & (paper["setting"] == "kalman_gain")].iloc[0]
    assert row["picp"] == pytest.approx(0.921) and row["time_ms"] == pytest.approx(16.8)


def test_measure_interleaved_reports_the_slower_function_as_slower():
    import time as _time

    out = clock.measure_interleaved({"fast": lambda: None, "slow": lambda: _time.sleep(0.002)},
                                    min_run_time=0.01, min_rounds=3)
    assert out["slow"] > 0.0015 and out["fast"] < out["slow"]


def _tiny_gating_profile():
    return build_profile(dict(ped_eval_p=[0.01, 0.05], ped_train_p=0.01, device="cpu", n_samples=4,
                              gating_picp_tolerance=0.01, gating_sweep_points=3, gating_timing_frames=0,
                              interval_level=0.95), "a test")


def test_what_is_not_timed_runs_as_one_thread_tasks_and_the_times_on_the_callers_threads(monkeypatch):
    """The gates' fitting and the metric passes are tasks (``map_tasks``: one torch thread each, here in this
    process); the interleaved timing rounds run afterwards on the caller's count, which is kept."""
    from drfkit.methods import gate_evaluation as ge
    from drfkit.study import studies

    val, test = keypoint_data(seed=11), keypoint_data(seed=12)
    monkeypatch.setattr(studies, "study_data", lambda P, study, split, noise=None, protocol="paper":
                        val if split == "val" else test)
    monkeypatch.delenv("DRF_WORKERS", raising=False)
    seen = {"fit": set(), "scored": set(), "timed": set()}
    order = []
    real_fit, real_score, real_measure = gating_study.fit_gate, gating_study.score_gate, ge.measure_interleaved
    monkeypatch.setattr(gating_study, "fit_gate", lambda *a, **k: seen["fit"].add(torch.get_num_threads())
                        or order.append("fit") or real_fit(*a, **k))
    monkeypatch.setattr(gating_study, "score_gate", lambda *a, **k: seen["scored"].add(torch.get_num_threads())
                        or order.append("score") or real_score(*a, **k))
    monkeypatch.setattr(ge, "measure_interleaved", lambda *a, **k: seen["timed"].add(torch.get_num_threads())
                        or order.append("time") or real_measure(*a, **k))
    models = {("drf", 0): tiny_drf(), ("drf", 1): tiny_drf(1)}
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        out = gating_study.gating_study(_tiny_gating_profile(), "pedestrians", models=models, min_run_time=0.001,
                                        sweep=False)
        assert torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(before)
    assert seen == {"fit": {1}, "scored": {1}, "timed": {2}}
    # every seed's untimed work first, then the timing alone: no task runs beside a timed round
    assert order == ["fit", "fit", "score"] * 2 + ["time", "time"] * 2
    assert sorted(out["table"]["seed"].unique()) == [0, 1]


@pytest.mark.slow
def test_the_gating_tables_are_the_same_at_one_and_two_workers(monkeypatch):
    """The metrics (everything but the times) of the gating study, scored in this process and on two worker
    processes, byte for byte."""
    from drfkit.study import studies

    val, test = keypoint_data(seed=11), keypoint_data(seed=12)
    monkeypatch.setattr(studies, "study_data", lambda P, study, split, noise=None, protocol="paper":
                        val if split == "val" else test)
    models = {("drf", 0): tiny_drf(), ("drf", 1): tiny_drf(1), ("drf", 2): tiny_drf(2)}
    timed = ["time_ms", "head_ms", "features_ms", "whole_ms", "batch_ms", "threads"]
    tables = {}
    for workers in (1, 2):
        out = gating_study.gating_study(_tiny_gating_profile(), "pedestrians", models=models, min_run_time=0.001,
                                        workers=workers)
        tables[workers] = {k: (t.drop(columns=timed, errors="ignore").to_csv(index=False)) for k, t in out.items()}
    assert tables[1] == tables[2]
    assert len(tables[1]["sweep"].splitlines()) > 1
