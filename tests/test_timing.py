"""drfkit.methods.timing: the inference benchmark's table, the models' streaming steps it times and its
modes, the CLI; the training-speed studies and the clock."""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
import torch

from drfkit.methods import timing
from drfkit.study import bench
from drfkit.models import DeepRecursiveFilter, LSTMBaseline, NoDynamics, build_model, default_config, parts
from drfkit.models.sequence import _EncodedSequenceModel
from drfkit.study.params import write_profile
from drfkit.study.bench import (COLUMNS, MODES, STUDIES, add_ratios, build_timing_model, example_frames,
                                inference_benchmark, make_frame_fn)
from drfkit.cli import main as cli

TINY = dict(n_samples=3, batch_sizes=[1, 2], threads=[1], min_run_time=0.01)


@pytest.fixture(scope="module")
def tiny_table() -> pd.DataFrame:
    return inference_benchmark(device="auto", **TINY)


def expected_cells(devices):
    return {(study, kind, mode, batch, dev) for dev in devices for study, (_, _, kinds) in STUDIES.items()
            for kind in kinds for mode in MODES[kind] for batch in TINY["batch_sizes"]}


def test_table_has_every_model_mode_batch_once(tiny_table):
    devices = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
    assert list(tiny_table.columns) == COLUMNS
    cells = list(zip(tiny_table["study"], tiny_table["model"], tiny_table["mode"], tiny_table["batch"],
                     tiny_table["device"]))
    assert len(cells) == len(set(cells)) and set(cells) == expected_cells(devices)
    assert set(tiny_table["threads"]) == {1}
    if not torch.cuda.is_available():
        assert set(tiny_table["device"]) == {"cpu"}
    assert (tiny_table["median_ms_per_frame"] > 0).all() and np.isfinite(tiny_table["median_ms_per_frame"]).all()
    assert (tiny_table["iqr_ms_per_frame"] >= 0).all()
    np.testing.assert_allclose(tiny_table["median_ms_per_call"],
                               tiny_table["median_ms_per_frame"] * tiny_table["batch"], rtol=1e-12)
    sampled = tiny_table["mode"] != "no_sampling"
    assert (tiny_table.loc[sampled, "n_samples"] == TINY["n_samples"]).all()
    assert (tiny_table.loc[~sampled, "n_samples"] == 0).all()


def test_ratios_divide_medians_within_the_same_group(tiny_table):
    ped = tiny_table[tiny_table["study"] == "pedestrians"]
    for (batch, threads, dev), group in ped.groupby(["batch", "threads", "device"]):
        base = group[(group["model"] == "monoloco") & (group["mode"] == "published")]["median_ms_per_frame"]
        assert len(base) == 1
        np.testing.assert_allclose(group["ratio_to_monoloco_published"],
                                   group["median_ms_per_frame"] / base.iloc[0], rtol=1e-12)
        for kind, rows in group.groupby("model"):
            det = rows[rows["mode"] == "no_sampling"]["median_ms_per_frame"].iloc[0]
            np.testing.assert_allclose(rows["ratio_to_no_sampling"], rows["median_ms_per_frame"] / det, rtol=1e-12)
    assert tiny_table[tiny_table["study"] == "pendulum"]["ratio_to_monoloco_published"].isna().all()
    assert (tiny_table[tiny_table["mode"] == "no_sampling"]["ratio_to_no_sampling"] == 1.0).all()


def test_add_ratios_never_mixes_groups():
    # two thread counts with different Monoloco times: each row must use its own group's
    rows = []
    for threads, mono, drf in ((1, 10.0, 2.0), (2, 4.0, 2.0)):
        for model, mode, ms in (("monoloco", "published", mono), ("monoloco", "no_sampling", mono / 20),
                                ("drf", "batched", drf), ("drf", "no_sampling", drf / 2)):
            rows.append({"study": "pedestrians", "model": model, "mode": mode, "n_samples": 25, "batch": 1,
                         "threads": threads, "device": "cpu", "median_ms_per_frame": ms,
                         "iqr_ms_per_frame": 0.0, "median_ms_per_call": ms, "load_1min": math.nan})
    rows.append({**rows[-1], "study": "pendulum"})  # a pendulum DRF pass: no Monoloco to divide by
    out = add_ratios(pd.DataFrame(rows))
    drf = out[(out["study"] == "pedestrians") & (out["model"] == "drf") & (out["mode"] == "batched")]
    assert drf["ratio_to_monoloco_published"].tolist() == [0.2, 0.5]
    assert drf["ratio_to_no_sampling"].tolist() == [2.0, 2.0]
    assert math.isnan(out[out["study"] == "pendulum"]["ratio_to_monoloco_published"].iloc[0])
    assert bench.speedup_vs_monoloco(out, batch=1, threads=2, device="cpu") == pytest.approx(2.0)
    with pytest.raises(ValueError, match="more than one"):
        add_ratios(pd.DataFrame(rows + [rows[0]]))


def stream(model, seq):
    """h of ``seq`` (B, T, ...) stepped frame by frame with the model's own streaming step; the
    first frame's h is that of ``features`` on it alone (a sequence of one frame)."""
    first = seq[:, :1]
    carry = model.initial_carry(first)
    steps = [model.features(first)[0]]
    for t in range(1, seq.shape[1]):
        h, carry = model.stream_step(seq[:, t:t + 1], carry)
        assert h.shape == (seq.shape[0], 1, steps[0].shape[-1])
        steps.append(h)
    return torch.cat(steps, dim=1)


STREAM_CASES = [(study, kind) for study, (_, _, kinds) in STUDIES.items() for kind in kinds]


@pytest.mark.parametrize("study,kind", STREAM_CASES)
def test_streaming_steps_reproduce_the_whole_sequence(study, kind):
    assert {k for _, k in STREAM_CASES} == {"drf", "drf_calibrated", "drf_calibrated_steep", "lstm", "no_dynamics",
                                            "monoloco", "known_dynamics"}
    model = build_timing_model(kind, study)
    seq = example_frames(study, batch=3, n_frames=5, seed=1)
    with torch.no_grad():
        whole, _ = model.features(seq)
        torch.testing.assert_close(stream(model, seq), whole, rtol=1e-4, atol=1e-5)
    if kind in ("no_dynamics", "monoloco"):  # per-frame models: no state to carry
        assert model.per_frame and model.initial_carry(seq[:, :1]) is None


@pytest.mark.parametrize("overrides", [{"transition_kind": "basis"}, {"memory_dims": 4}])
def test_drf_streaming_steps_reproduce_the_protocol_variants(overrides):
    # memory dims: a streamed later frame is not a sequence's first (prior variance 1 there)
    torch.manual_seed(0)
    model = build_model(default_config("drf", "keypoints", 1, **overrides)).eval()
    seq = example_frames("pedestrians", batch=3, n_frames=5, seed=1)
    with torch.no_grad():
        torch.testing.assert_close(stream(model, seq), model.features(seq)[0], rtol=1e-4, atol=1e-5)


class FeaturesOnlyDRF(DeepRecursiveFilter):  # changes the computation, keeps the parent's step
    def features(self, inputs, return_gains=False):
        h, gains = super().features(inputs, return_gains)
        return 2 * h, gains


class FilterOnlyDRF(DeepRecursiveFilter):
    def run_filter(self, w, r, return_gains=False, whole_sequence=None):
        return super().run_filter(w, r, return_gains, whole_sequence)


class FeaturesOnlyLSTM(LSTMBaseline):
    def features(self, inputs, return_gains=False):
        return super().features(inputs.flip(1), return_gains)


class RecursiveNoDynamics(NoDynamics):  # a recursion on top of a per-frame model
    def features(self, inputs, return_gains=False):
        h, _ = super().features(inputs)
        return h.cumsum(dim=1), None


class NewSequenceModel(_EncodedSequenceModel):  # a new model with state and no streaming step
    kind = "new"

    def features(self, inputs, return_gains=False):
        w, r = self.observe(inputs)
        return parts.mean_and_log_variance(w, r).cumsum(dim=1), None


class StreamingDRF(FeaturesOnlyDRF):  # defines its step again: allowed
    def stream_step(self, frame, carry):
        h, carry = super().stream_step(frame, carry)
        return 2 * h, carry


@pytest.mark.parametrize("cls,overridden", [(FeaturesOnlyDRF, "features"), (FilterOnlyDRF, "run_filter"),
                                            (FeaturesOnlyLSTM, "features"), (RecursiveNoDynamics, "features"),
                                            (NewSequenceModel, None)])
def test_a_model_without_its_own_streaming_step_raises_instead_of_going_stateless(cls, overridden):
    model = cls(input_kind="keypoints", out_dim=1).eval()
    seq = example_frames("pedestrians", batch=2, n_frames=3)
    model.features(seq)  # the whole-sequence computation itself works
    match = f"overrides {overridden} but not its streaming step" if overridden else "defines no streaming step"
    with pytest.raises(NotImplementedError, match=match):
        model.initial_carry(seq[:, :1])
    with pytest.raises(NotImplementedError, match=match):
        model.stream_step(seq[:, 1:2], None)
    if cls.kind in MODES:  # the benchmark's timed call goes through the same step
        with pytest.raises(NotImplementedError, match=match):
            make_frame_fn(model, "no_sampling", seq[:, 1:2], None, 1)()


def test_a_subclass_that_defines_its_step_again_streams_its_own_computation():
    model = StreamingDRF(input_kind="keypoints", out_dim=1).eval()
    seq = example_frames("pedestrians", batch=2, n_frames=4)
    with torch.no_grad():
        torch.testing.assert_close(stream(model, seq), model.features(seq)[0], rtol=1e-4, atol=1e-5)


class MaskBank:
    """Stand-in for ``parts.mc_dropout`` that hands out pre-drawn masks in order, so the
    batched (one call, S masks) and sequential (S calls, one mask each) paths see the
    same dropout masks."""

    def __init__(self, n_samples, shape, p, seed=0):
        gen = torch.Generator().manual_seed(seed)
        self.masks = (torch.rand(n_samples, *shape, generator=gen) > p).float() / (1 - p)
        self.used = 0

    def __call__(self, h, n_samples, p, uniforms=None):
        masks = self.masks[self.used:self.used + n_samples]
        self.used += n_samples
        return h.unsqueeze(0) * masks


@pytest.mark.parametrize("study", ["pedestrians", "pendulum"])
def test_drf_modes_agree_given_the_same_masks_and_filter_once(study, monkeypatch):
    n_samples, batch = 4, 3
    model = build_timing_model("drf", study)
    frames = example_frames(study, batch, 2, seed=2)
    with torch.no_grad():
        carry = model.initial_carry(frames[:, :1])
    transition_calls = []
    model.transition.register_forward_hook(lambda *_: transition_calls.append(1))
    outputs = {}
    for mode in ("batched", "sequential", "naive"):
        bank = MaskBank(n_samples, (batch, 1, model.decoder.linear3.out_features), model.default_dropout_p)
        monkeypatch.setattr(parts, "mc_dropout", bank)
        transition_calls.clear()
        outputs[mode] = make_frame_fn(model, mode, frames[:, 1:], carry, n_samples)()
        assert bank.used == n_samples
        assert len(transition_calls) == (n_samples if mode == "naive" else 1), mode
    assert len(outputs["batched"]) == 4  # mean, aleatoric, epistemic, total
    assert outputs["batched"][2].abs().sum() > 0  # the masks differ: a real spread
    for mode in ("sequential", "naive"):
        for got, want in zip(outputs[mode], outputs["batched"]):
            assert got.shape == (batch, 1, model.out_dim)
            torch.testing.assert_close(got, want, rtol=1e-5, atol=1e-6)
    transition_calls.clear()
    mean, sigma = make_frame_fn(model, "no_sampling", frames[:, 1:], carry, n_samples)()
    assert mean.shape == sigma.shape == (batch, 1, model.out_dim) and len(transition_calls) == 1


def test_monoloco_published_runs_the_whole_net_once_per_sample():
    n_samples, batch = 5, 2
    frames = example_frames("pedestrians", batch, 2)
    # batched: the input layer once (only its dropout is sampled), the rest on all S x batch rows
    for mode, calls, rows in (("published", n_samples, batch), ("batched", 1, batch),
                              ("no_sampling", 1, batch)):
        model = build_timing_model("monoloco", "pedestrians", mode)
        seen = []
        model.input_layer.register_forward_hook(lambda mod, inp, out: seen.append(inp[0].shape[0]))
        out = make_frame_fn(model, mode, frames[:, 1:], None, n_samples)()
        assert seen == [rows] * calls, mode
        assert all(t.shape == (batch, 1, 1) for t in out)
    with pytest.raises(ValueError, match="mc_mode='sequential'"):
        make_frame_fn(build_timing_model("monoloco", "pedestrians", "batched"), "published",
                      frames[:, 1:], None, n_samples)


def test_bad_arguments_fail_early_with_the_fix():
    model = build_timing_model("lstm", "pedestrians")
    frames = example_frames("pedestrians", 2, 3)
    with pytest.raises(ValueError, match="not timed for lstm"):
        make_frame_fn(model, "naive", frames[:, :1], None, 3)
    with pytest.raises(ValueError, match=r"\(B, 1, \.\.\.\)"):
        model.stream_step(frames, None)
    with pytest.raises(ValueError, match="not part of the pendulum study"):
        build_timing_model("monoloco", "pendulum")
    with pytest.raises(ValueError, match="batch_sizes"):
        inference_benchmark(3, batch_sizes=[0], threads=[1], min_run_time=0.01)
    with pytest.raises(ValueError, match="n_samples"):
        inference_benchmark(0, batch_sizes=[1], threads=[1], min_run_time=0.01)
    if not torch.cuda.is_available():
        with pytest.raises(RuntimeError, match="no GPU"):
            bench.timing_devices("cuda")


def test_cli_writes_timing_csv(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("DRF_RESULTS", str(tmp_path / "results"))
    profile = tmp_path / "tiny.yaml"
    write_profile(profile, {
        "profile": "tiny", "seeds": [0], "device": "cpu", "threads": 0, "n_samples": 2,
        "timing_batch_sizes": [1], "timing_threads": [1], "timing_min_run_time": 0.01})
    assert cli(["bench", "--profile", str(profile)]) == 0
    written = pd.read_csv(tmp_path / "results" / "tiny" / "bench" / "timing.csv")
    assert list(written.columns) == COLUMNS
    assert len(written) == sum(len(MODES[k]) for _, _, kinds in STUDIES.values() for k in kinds)
    assert set(written["device"]) == {"cpu"} and set(written["batch"]) == {1}
    assert "median_ms_per_frame" in capsys.readouterr().out
    # the record names the command and the parameters; notebook 05 reads the table only for the same parameters
    from drfkit.book.bench_store import read_bench
    from drfkit.study.params import for_notebook, load_profile

    P = for_notebook("bench", load_profile(str(profile)))
    table, record = read_bench(P)
    assert record["command"] == "make bench PROFILE=tiny" and record["params"]["batch_sizes"] == [1]
    assert table.equals(written)
    other = for_notebook("bench", load_profile(str(profile)) | {"timing_batch_sizes": [1, 4]})
    assert read_bench(other) is None


def test_training_step_times_still_reports_epochs():
    from drfkit.models import default_config

    configs = {k: default_config(k, "keypoints", 1) for k in ("no_dynamics", "drf")}
    inputs = example_frames("pedestrians", 2, 3)
    speed = timing.training_step_times(configs, inputs, torch.rand(2, 3, 1) + 5.0, n_batches_per_epoch=4,
                                       min_run_time=0.01, threads=1)
    assert speed["model"].tolist() == ["no_dynamics", "drf"]
    np.testing.assert_allclose(speed["epoch_s"], 4 * speed["step_median_s"])
    assert speed["ratio_to_no_dynamics"].iloc[0] == 1.0 and (speed["step_median_s"] > 0).all()


def test_count_flops_of_known_products():
    a, b = torch.randn(3, 4), torch.randn(4, 5)
    assert timing.count_flops(lambda: a @ b) == 2 * 3 * 4 * 5
    A, B = torch.randn(6, 3, 4), torch.randn(6, 4, 5)
    assert timing.count_flops(lambda: (A @ B, a + a)) == 6 * 2 * 3 * 4 * 5  # elementwise ops are not counted
    w = torch.randn(5, 4, requires_grad=True)  # backward of x w^T: dL/dw = g^T x, one more product
    assert timing.count_flops(lambda: torch.autograd.grad((a @ w.T).sum(), w)) == 2 * (2 * 3 * 4 * 5)


def test_count_flops_of_the_cpu_lstm_layer_matches_its_cells():
    # nn.LSTM runs one oneDNN kernel per layer on the CPU, which torch's counter has no formula
    # for; drfkit.methods.timing adds one: the forward counts as the same network run as nn.LSTMCells
    T, B, n_in, H = 7, 5, 12, 16
    lstm = torch.nn.LSTM(n_in, H, num_layers=2, batch_first=True)
    cells = [torch.nn.LSTMCell(n_in, H), torch.nn.LSTMCell(H, H)]
    x = torch.randn(B, T, n_in)

    def looped():
        state = [(torch.zeros(B, H), torch.zeros(B, H)) for _ in cells]
        for t in range(T):
            inp = x[:, t]
            for layer, cell in enumerate(cells):
                state[layer] = cell(inp, state[layer])
                inp = state[layer][0]

    with torch.no_grad():
        forward = timing.count_flops(lambda: lstm(x))
        assert forward == timing.count_flops(looped) == 2 * T * B * 4 * H * ((n_in + H) + (H + H))
    # backward: dL/dx and dL/dh, and the weights' gradients, twice the forward
    assert timing.count_flops(lambda: torch.autograd.grad(lstm(x)[0].sum(), list(lstm.parameters()))) == 3 * forward


def test_training_step_flops_count_the_filter_recursion():
    from drfkit.models import default_config

    configs = {k: default_config(k, "pendulum", 2) for k in ("no_dynamics", "drf")}
    inputs = example_frames("pendulum", 3, 4)
    targets = torch.rand(3, 4, 2)
    plain = timing.training_step_times(configs, inputs, targets, n_batches_per_epoch=1, min_run_time=0.01,
                                       min_rounds=2, threads=1)
    assert "gflop" not in plain  # counting is asked for, not done by default
    speed = timing.training_step_times(configs, inputs, targets, n_batches_per_epoch=1, min_run_time=0.01,
                                       min_rounds=2, threads=1, with_flops=True).set_index("model")
    nd, drf = speed.loc["no_dynamics"], speed.loc["drf"]
    assert nd["flop_ratio_to_no_dynamics"] == 1.0
    assert drf["flop_ratio_to_no_dynamics"] == pytest.approx(drf["gflop"] / nd["gflop"])
    assert drf["gflop_per_s"] == pytest.approx(drf["gflop"] / drf["step_median_s"])
    # the DRF shares the encoder, heads and decoder; on top, per filter step (3 here) its forward
    # alone runs five batched n x n products (two for F P F^T, three for the Joseph form)
    n, batch, filter_steps = configs["drf"]["latent"], 3, 3
    extra = (drf["gflop"] - nd["gflop"]) * 1e9
    assert extra > filter_steps * 5 * batch * 2 * n ** 3


def test_interleaved_times_rotates_the_order_and_times_every_fn_each_round():
    import time as _time

    calls = []
    fns = {name: (lambda name=name: calls.append(name) or (_time.sleep(0.002) if name == "slow" else None))
           for name in ("fast", "slow", "mid")}
    out = timing.interleaved_times(fns, min_run_time=0.0, block_s=0.0, min_rounds=4)
    assert {k: len(v) for k, v in out.items()} == {"fast": 4, "slow": 4, "mid": 4}
    measured = calls[6:]  # after two warm-up calls each
    assert measured == ["fast", "slow", "mid", "slow", "mid", "fast", "mid", "fast", "slow", "fast", "slow", "mid"]
    assert min(out["slow"]) > 0.0015 and max(out["fast"]) < min(out["slow"])
    with pytest.raises(ValueError, match="empty"):
        timing.interleaved_times({}, min_run_time=0.1)


def test_paired_rounds_time_claim_c6s_pair_round_by_round(monkeypatch):
    """One row per round; each round's ratio is that round's Monoloco over that round's DRF (paired), and the
    pair is Monoloco as published against the DRF's sequential passes."""
    timed = []
    real = bench.make_frame_fn
    monkeypatch.setattr(bench, "make_frame_fn", lambda model, mode, *a: timed.append((model.kind, mode)) or real(model, mode, *a))
    out = bench.paired_rounds(n_samples=2, rounds=3, block_s=0.0)
    assert timed == [("monoloco", "published"), ("drf", "sequential")]
    assert list(out["round"]) == [0, 1, 2] and (out["monoloco_ms"] > 0).all() and (out["drf_ms"] > 0).all()
    assert np.allclose(out["ratio"], out["monoloco_ms"] / out["drf_ms"])
    with pytest.raises(ValueError, match="interval needs two"):
        bench.paired_rounds(n_samples=2, rounds=1)


def test_training_step_ratio_is_the_median_of_per_round_ratios(monkeypatch):
    from drfkit.models import default_config

    # per-round ratios 5, 1, 1, 3, 2 (median 2); the ratio of the medians would be 5 / 3
    fake = {"no_dynamics": [1.0, 2.0, 3.0, 4.0, 5.0], "drf": [5.0, 2.0, 3.0, 12.0, 10.0]}
    monkeypatch.setattr(timing.training, "interleaved_times", lambda fns, *a, **k: {n: fake[n] for n in fns})
    configs = {k: default_config(k, "keypoints", 1) for k in ("no_dynamics", "drf")}
    speed = timing.training_step_times(configs, example_frames("pedestrians", 2, 3), torch.rand(2, 3, 1) + 5.0,
                                       n_batches_per_epoch=2, min_run_time=0.01, threads=1)
    row = speed.set_index("model").loc["drf"]
    assert row["ratio_to_no_dynamics"] == 2.0 and row["step_median_s"] == 5.0 and row["rounds"] == 5
    assert row["ratio_to_no_dynamics_iqr"] == pytest.approx(3.0 - 1.0)  # quartiles of 5, 1, 1, 3, 2
    assert row["epoch_s"] == 10.0 and row["step_iqr_s"] == pytest.approx(10.0 - 3.0)


def test_training_step_times_sets_model_attributes_and_rejects_unknown_ones(monkeypatch):
    from drfkit.models import default_config, recursion

    config = default_config("drf", "keypoints", 1)
    inputs, targets = example_frames("pedestrians", 2, 3), torch.rand(2, 3, 1) + 5.0
    calls = []
    real = recursion.drf_recursion
    monkeypatch.setattr("drfkit.models.drf.drf_recursion", lambda *a: calls.append(1) or real(*a))
    for attrs, one_node in (({}, True), ({"whole_sequence": False}, False)):
        calls.clear()
        speed = timing.training_step_times({"drf": config}, inputs, targets, n_batches_per_epoch=1,
                                           min_run_time=0.01, min_rounds=2, model_attrs={"drf": attrs})
        assert (speed["step_median_s"] > 0).all() and bool(calls) == one_node
    with pytest.raises(ValueError, match="no attribute 'whole_sequnce'"):
        timing.training_step_times({"drf": config}, inputs, targets, n_batches_per_epoch=1, min_run_time=0.01,
                                   model_attrs={"drf": {"whole_sequnce": False}})


def test_fit_fixed_and_per_item_recovers_a_line():
    fixed, per_item = timing.fit_fixed_and_per_item([2, 4, 8], [0.1 + 0.02 * s for s in (2, 4, 8)])
    assert fixed == pytest.approx(0.1) and per_item == pytest.approx(0.02)
    with pytest.raises(ValueError, match="2 distinct sizes"):
        timing.fit_fixed_and_per_item([4, 4], [0.1, 0.2])


def test_recursion_scaling_splits_fixed_cost_and_takes_per_round_floors(monkeypatch):
    from drfkit.models import default_config

    # recursion t(b) = 0.03 + 0.01 b exactly; per round base and drf steps
    base, drf = np.array([0.2, 0.1, 0.4]), np.array([0.2, 0.5, 0.6])
    rec = {b: np.array([0.03 + 0.01 * b] * 3) for b in (1, 2, 4)}
    seen = []

    def fake(fns, *a, **k):
        seen.append(sorted(fns))
        return {"base": base, "drf": drf} | {f"recursion_{b}": t for b, t in rec.items()}

    monkeypatch.setattr(timing.training, "interleaved_times", fake)
    configs = {k: default_config(k, "pendulum", 2) for k in ("no_dynamics", "drf")}
    inputs, targets = example_frames("pendulum", 2, 3), torch.rand(2, 3, 2)
    table = timing.recursion_scaling(configs["no_dynamics"], configs["drf"], inputs, targets, threads=1)
    assert seen == [["base", "drf", "recursion_1", "recursion_2", "recursion_4"]]  # default sizes B/2, B, 2B
    assert list(zip(table["model"], table["part"], table["batch"])) == [
        ("no_dynamics", "step", 2), ("drf", "step", 2), ("drf", "recursion", 1), ("drf", "recursion", 2),
        ("drf", "recursion", 4)]
    assert table["fixed_s"].iloc[0] == pytest.approx(0.03) and table["per_sequence_s"].iloc[0] == pytest.approx(0.01)
    recursion_rows = table[table["part"] == "recursion"]
    assert np.allclose(recursion_rows["fit_s"], recursion_rows["median_s"])
    row = table.iloc[1]
    assert row["ratio"] == pytest.approx(1.5)  # per round 1, 5, 1.5: not the ratio of medians (2.5)
    # per round (drf - t(2) + 0.01 * 2) / base = (drf - 0.03) / base: 0.85, 4.7, 1.425
    assert row["floor_ratio"] == pytest.approx(1.425)
    assert table.loc[[0, 2, 3, 4], ["ratio", "floor_ratio"]].isna().all().all()


def test_recursion_scaling_times_the_recursion_with_its_backward(monkeypatch):
    from drfkit.models import default_config, recursion

    configs = {k: default_config(k, "pendulum", 2) for k in ("no_dynamics", "drf")}
    inputs, targets = example_frames("pendulum", 3, 4), torch.rand(3, 4, 2)
    batches = []
    real = recursion.drf_recursion
    monkeypatch.setattr(recursion, "drf_recursion", lambda tr, w, r: batches.append(w.shape[0]) or real(tr, w, r))
    table = timing.recursion_scaling(configs["no_dynamics"], configs["drf"], inputs, targets, sizes=(2, 5),
                                     min_run_time=0.0, min_rounds=2, threads=1)
    assert set(batches) == {2, 3, 5}  # the step's own B = 3 is always timed
    assert (table["median_s"] > 0).all() and table["rounds"].eq(2).all()
    with pytest.raises(ValueError, match="must build a DRF"):
        timing.recursion_scaling(configs["no_dynamics"], configs["no_dynamics"], inputs, targets, min_run_time=0.0)
    with pytest.raises(ValueError, match="positive ints"):
        timing.recursion_scaling(configs["no_dynamics"], configs["drf"], inputs, targets, sizes=(2.5,))
    with pytest.raises(ValueError, match="disagree on the batch"):
        timing.recursion_scaling(configs["no_dynamics"], configs["drf"], inputs, targets[:2])


def test_epoch_times_rotates_models_and_takes_per_round_ratios(monkeypatch):
    from types import SimpleNamespace

    import drfkit.methods.train

    per_round = {"no_dynamics": [2.0, 1.0, 4.0], "drf": [2.0, 5.0, 6.0]}  # per-round ratios 1, 5, 1.5
    calls = []

    def fake_train_model(config, train, val, cfg, stem, progress, stop_after_epochs):
        calls.append((config["kind"], stem.name, progress, stop_after_epochs))
        seconds = per_round[config["kind"]][sum(c[0] == config["kind"] for c in calls) - 1]
        return SimpleNamespace(history=[{"seconds": seconds}])

    monkeypatch.setattr(drfkit.methods.train, "train_model", fake_train_model)
    cfg = drfkit.methods.train.TrainConfig(epochs=5, lr=1e-3, batch_size=4, seed=0)
    configs = {"no_dynamics": {"kind": "no_dynamics"}, "drf": {"kind": "drf"}}
    table = timing.epoch_times(configs, list(range(10)), None, {k: cfg for k in configs}, rounds=3, threads=1)
    assert [c[0] for c in calls] == ["no_dynamics", "drf", "drf", "no_dynamics", "no_dynamics", "drf"]
    assert len({c[1] for c in calls}) == 6 and all(c[2:] == (False, 1) for c in calls)
    row = table.set_index("model").loc["drf"]
    assert row["epoch_median_s"] == 5.0 and row["ratio_to_no_dynamics"] == 1.5  # not 5 / 2
    assert row["ratio_to_no_dynamics_iqr"] == pytest.approx(3.25 - 1.25) and row["sequences"] == 10
    with pytest.raises(ValueError, match="same models"):
        timing.epoch_times(configs, [], None, {"drf": cfg})
    with pytest.raises(ValueError, match="rounds"):
        timing.epoch_times(configs, [], None, {k: cfg for k in configs}, rounds=0)


def test_epoch_times_trains_real_epochs_in_a_temporary_folder(tmp_path, monkeypatch):
    from drfkit.models import default_config
    from drfkit.methods.train import SequenceData, TrainConfig

    monkeypatch.chdir(tmp_path)
    g = torch.Generator().manual_seed(0)
    data = SequenceData(torch.randint(0, 256, (6, 4, 24, 24), dtype=torch.uint8, generator=g),
                        torch.randn(6, 4, 2, generator=g))
    configs = {k: default_config(k, "pendulum", 2) for k in ("no_dynamics", "drf")}
    cfg = TrainConfig(epochs=3, lr=1e-3, batch_size=3, seed=0)
    table = timing.epoch_times(configs, data, data, {k: cfg for k in configs}, rounds=1, threads=1)
    assert (table["epoch_median_s"] > 0).all() and table["batch"].eq(3).all() and table["rounds"].eq(1).all()
    assert list(tmp_path.iterdir()) == []  # checkpoints went to a temporary folder, now gone


def test_torch_threads_restores_the_count_even_after_an_error():
    before = torch.get_num_threads()
    other = 1 if before != 1 else 2
    with pytest.raises(RuntimeError, match="inside"):
        with timing.torch_threads(other):
            assert torch.get_num_threads() == other
            raise RuntimeError("inside")
    assert torch.get_num_threads() == before


@pytest.mark.parametrize("study", ["pendulum", "pedestrians"])
@pytest.mark.parametrize("kind", ["drf", "lstm"])
def test_streaming_with_a_non_identity_transition(study, kind):
    """A fresh DRF's transition gives F = I, under which a streaming step using F^T (or no F at all)
    still matches; with the transition head (the LSTM's weights) perturbed it must match too. A
    stream_step that applies F transposed fails this."""
    torch.manual_seed(0)
    model = build_timing_model(kind, study)
    seq = example_frames(study, batch=3, n_frames=6, seed=2)
    with torch.no_grad():
        before = model.features(seq)[0]
        g = torch.Generator().manual_seed(1)
        for name, p in model.named_parameters():
            if "transition" in name or kind == "lstm":
                p.add_(0.3 * torch.randn(p.shape, generator=g))
        whole = model.features(seq)[0]
        assert not torch.allclose(whole, before, atol=1e-3)  # the perturbation reaches the features
        torch.testing.assert_close(stream(model, seq), whole, rtol=1e-4, atol=1e-5)


def test_device_ratios_divide_cpu_by_gpu_within_a_run():
    from drfkit.study.bench import device_ratios

    rows = [{"study": "pendulum", "model": "drf", "mode": "batched", "batch": 16, "threads": t, "device": d,
             "median_ms_per_frame": ms} for t, d, ms in ((1, "cpu", 8.0), (2, "cpu", 5.0), (1, "cuda (H100)", 0.5))]
    ratios = device_ratios(pd.DataFrame(rows))
    assert ratios["gpu_over_cpu_speedup"].tolist() == [10.0] and ratios["cpu_threads"].tolist() == [2]
    assert device_ratios(pd.DataFrame(rows[:2])).empty   # no GPU in the run: nothing to compare
