"""The MC-dropout prediction cache: a hit gives the very numbers a fresh prediction gives, and
any change to what made a prediction (weights, inputs, rates, samples, seed) misses."""
from __future__ import annotations

import pytest
import torch

import drfkit.methods.predictions as predictions
from drfkit.study.evaluate import evaluate_model_rates
from drfkit.models import build_model, default_config
from drfkit.methods.train import SequenceData
from drfkit.methods.uncertainty import predict_rates

torch.set_num_threads(1)


def small_case():
    torch.manual_seed(0)
    model = build_model(default_config("drf", "keypoints", 1)).eval()
    g = torch.Generator().manual_seed(1)
    x = torch.randn(4, 5, 17, 3, generator=g)
    x[..., 2] = torch.rand(4, 5, 17, generator=g)
    return model, SequenceData(x, torch.rand(4, 5, 1, generator=g) * 20 + 5)


def fields(p):
    return (p.mean, p.aleatoric, p.epistemic, p.total)


def test_cached_equals_uncached_bit_for_bit_and_a_hit_computes_nothing(tmp_path, monkeypatch):
    model, data = small_case()
    torch.manual_seed(3)
    fresh = predict_rates(model, data.inputs, n_samples=7, dropout_rates=[None, 0.3], batch_size=2)
    first = predictions.cached_predict_rates(model, data.inputs, cache=tmp_path, n_samples=7,
                                             dropout_rates=[None, 0.3], seed=3, batch_size=2)
    assert len(list(tmp_path.glob("*.pt"))) == 2      # one entry per rate
    monkeypatch.setattr(predictions, "predict_rates", lambda *a, **k: pytest.fail("a cache hit must not predict"))
    again = predictions.cached_predict_rates(model, data.inputs, cache=tmp_path, n_samples=7,
                                             dropout_rates=[None, 0.3], seed=3, batch_size=2)
    for a, b, c in zip(fresh, first, again):
        assert all(torch.equal(u, v) and torch.equal(v, w) for u, v, w in zip(fields(a), fields(b), fields(c)))
        assert a.dropout_p == c.dropout_p and a.n_samples == c.n_samples


def test_a_rate_is_the_same_whatever_rates_it_was_asked_with_so_each_is_found_alone(tmp_path, monkeypatch):
    """The masks' uniforms are drawn once per head chunk for every rate: a rate's prediction is bitwise the same
    asked alone or among others, so a call finds it in another call's entries and computes only what is missing."""
    model, data = small_case()
    torch.manual_seed(4)
    alone = predict_rates(model, data.inputs, n_samples=6, dropout_rates=[0.3], batch_size=2)[0]
    torch.manual_seed(4)
    among = predict_rates(model, data.inputs, n_samples=6, dropout_rates=[0.1, 0.3, 0.5], batch_size=2)[1]
    assert all(torch.equal(a, b) for a, b in zip(fields(alone), fields(among)))
    args = dict(cache=tmp_path, n_samples=6, seed=4, batch_size=2)
    predictions.cached_predict_rates(model, data.inputs, dropout_rates=[0.3], **args)
    asked = []
    real = predictions.predict_rates
    monkeypatch.setattr(predictions, "predict_rates", lambda *a, **k: asked.append(k["dropout_rates"]) or real(*a, **k))
    both = predictions.cached_predict_rates(model, data.inputs, dropout_rates=[0.1, 0.3], **args)
    assert asked == [[0.1]] and all(torch.equal(a, b) for a, b in zip(fields(both[1]), fields(alone)))
    torch.manual_seed(4)
    fresh = predict_rates(model, data.inputs, n_samples=6, dropout_rates=[0.1], batch_size=2)[0]
    assert all(torch.equal(a, b) for a, b in zip(fields(both[0]), fields(fresh)))
    predictions.cached_predict_rates(model, data.inputs, dropout_rates=[0.3, 0.1, 0.3], **args)  # all found
    assert asked == [[0.1]]


def test_the_metrics_through_the_cache_are_those_without_it(tmp_path):
    model, data = small_case()
    torch.manual_seed(5)
    plain = evaluate_model_rates(model, data, n_samples=6, dropout_rates=[None, 0.2])
    cold = evaluate_model_rates(model, data, n_samples=6, dropout_rates=[None, 0.2], seed=5, cache=tmp_path)
    warm = evaluate_model_rates(model, data, n_samples=6, dropout_rates=[None, 0.2], seed=5, cache=tmp_path)
    assert plain == cold == warm


@pytest.mark.parametrize("change", ["seed", "n_samples", "rates", "weights", "inputs", "batch"])
def test_any_change_to_what_made_a_prediction_misses(tmp_path, change):
    model, data = small_case()
    args = dict(cache=tmp_path, n_samples=5, dropout_rates=[None], seed=0, batch_size=None)
    predictions.cached_predict_rates(model, data.inputs, **args)
    inputs = data.inputs
    if change == "weights":
        with torch.no_grad():
            next(model.parameters()).add_(1e-3)
    elif change == "inputs":
        inputs = inputs.clone()
        inputs[0, 0, 0, 0] += 1e-3
    else:
        args |= {"seed": {"seed": 1}, "n_samples": {"n_samples": 6}, "rates": {"dropout_rates": [0.3]},
                 "batch": {"batch_size": 2}}[change]
    predictions.cached_predict_rates(model, inputs, **args)
    assert len(list(tmp_path.glob("*.pt"))) == 2


def test_a_damaged_entry_is_computed_again(tmp_path):
    model, data = small_case()
    args = dict(cache=tmp_path, n_samples=4, dropout_rates=[None], seed=2)
    good = predictions.cached_predict_rates(model, data.inputs, **args)[0]
    (path,) = tmp_path.glob("*.pt")
    path.write_bytes(b"truncated")
    again = predictions.cached_predict_rates(model, data.inputs, **args)[0]
    assert torch.equal(good.mean, again.mean) and path.stat().st_size > 100


def test_the_prediction_key_follows_the_code_that_computes_it(tmp_path, monkeypatch):
    """An edit to a model's source drops a cached prediction; an edit elsewhere keeps it."""
    from drfkit.methods import predictions
    from drfkit.util import paths

    (tmp_path / "drfkit" / "models").mkdir(parents=True)
    (tmp_path / "drfkit" / "report").mkdir(parents=True)
    model_src, figure_src = tmp_path / "drfkit" / "models" / "m.py", tmp_path / "drfkit" / "report" / "f.py"
    model_src.write_text("a = 1\n"), figure_src.write_text("b = 1\n")
    monkeypatch.setattr(paths, "REPO_ROOT", tmp_path)
    first = predictions.prediction_code_sha256()
    figure_src.write_text("b = 2\n")
    predictions._code_sha256.cache_clear()  # a new process reads the sources again
    assert predictions.prediction_code_sha256() == first
    model_src.write_text("a = 2\n")
    predictions._code_sha256.cache_clear()
    assert predictions.prediction_code_sha256() != first


def model_of(kind: str):
    """A small model of ``kind`` on the input it takes (keypoints where it can, else 24 x 24 images)."""
    from drfkit.models import MODEL_CLASSES, build_model, default_config

    torch.manual_seed(0)
    g = torch.Generator().manual_seed(1)
    try:
        model = build_model(default_config(kind, "keypoints", 1)).eval()
        x = torch.randn(5, 4, 17, 3, generator=g)
        x[..., 2] = torch.rand(5, 4, 17, generator=g)
    except ValueError:
        model = build_model(default_config(kind, "pendulum", 2)).eval()
        x = torch.randint(0, 256, (5, 4, 24, 24), generator=g, dtype=torch.uint8)
    assert kind in MODEL_CLASSES
    return model, x


@pytest.mark.parametrize("kind", list(__import__("drfkit.models", fromlist=["MODEL_CLASSES"]).MODEL_CLASSES))
def test_a_later_rate_runs_only_the_heads_on_the_stored_features_with_the_same_numbers(tmp_path, monkeypatch, kind):
    """The features (encoder, then filter or LSTM) are stored by the first prediction of a model on some inputs; a
    later call at another rate reads them and never runs ``model.features``, and gives what a fresh prediction gives,
    bit for bit: the features draw no random numbers, so the masks' draws start where they would."""
    model, x = model_of(kind)
    args = dict(cache=tmp_path, n_samples=6, seed=7, batch_size=2)
    predictions.cached_predict_rates(model, x, dropout_rates=[0.3], **args)
    assert len(list((tmp_path / "features").glob("*.pt"))) == 1
    torch.manual_seed(7)
    fresh = predict_rates(model, x, n_samples=6, dropout_rates=[0.1], batch_size=2)[0]
    monkeypatch.setattr(type(model), "features", lambda *a, **k: pytest.fail("the stored features must be read"))
    later = predictions.cached_predict_rates(model, x, dropout_rates=[0.1], **args)[0]
    assert all(torch.equal(a, b) for a, b in zip(fields(fresh) + (fresh.point,), fields(later) + (later.point,)))


def test_the_features_store_misses_on_other_inputs_or_chunks_and_recomputes_a_damaged_entry(tmp_path):
    model, data = small_case()
    first = predictions.cached_features(model, data.inputs, cache=tmp_path, batch_size=2)
    predictions.cached_features(model, data.inputs, cache=tmp_path, batch_size=3)
    predictions.cached_features(model, data.inputs[:3], cache=tmp_path, batch_size=2)
    assert len(list((tmp_path / "features").glob("*.pt"))) == 3
    path = tmp_path / "features" / f"{predictions.features_key(model, data.inputs, 2, None)}.pt"
    path.write_bytes(b"truncated")
    again = predictions.cached_features(model, data.inputs, cache=tmp_path, batch_size=2)
    assert torch.equal(first, again) and path.stat().st_size > 100


def test_features_that_are_not_these_inputs_are_refused():
    model, data = small_case()
    h = predictions.model_features(model, data.inputs, batch_size=2)
    with pytest.raises(ValueError, match="model_features of these inputs"):
        predict_rates(model, data.inputs[:3], n_samples=2, features=h)
    with pytest.raises(ValueError, match="cannot give gains"):
        predict_rates(model, data.inputs, n_samples=2, features=h, return_gains=True)


def test_the_features_store_tool_checks_both_savings_bit_for_bit(load_tool, capsys):
    """tools/features_store.py (docs/rerun_time.md's measurement) on random models of the quick profile: every
    book-protocol pendulum kind gets a row, and each saving gives the same numbers bit for bit."""
    assert load_tool("features_store").main(["--profile", "quick", "--untrained", "--sequences", "3",
                                             "--rounds", "1"]) == 0
    out = capsys.readouterr().out
    rows = [line for line in out.splitlines() if line.startswith("| ") and not line.startswith("| model")]
    assert len(rows) >= 5 and all(line.endswith("| True |") for line in rows)
    assert "distinct frames of" in out
