"""Where an MC-dropout evaluation spends its time, and what the two evaluation speed-ups save, in one run.

    .venv/bin/python tools/bench_evaluation.py                 # the paper profile's test set, 1 thread
    .venv/bin/python tools/bench_evaluation.py --sequences 8   # a smoke run (what the test does)

Measured with ``torch.utils.benchmark`` on one torch thread, each pair in the same run:
  pooling   the image encoder's 2x2 max pooling: ``F.max_pool2d`` against ``parts.max_pool_2x2`` (strided
            maxima, the same values) on 256 frames, at the narrow (12) and wide (32) encoder's channels;
  masks     the MC-dropout head at five rates on the frames of 8 sequences: a ``bernoulli_`` mask per rate
            (the former draw) against one shared uniform draw (``parts.SharedUniforms``);
  predict   ``uncertainty.predict_rates`` (25 samples, batch 256) of an untrained model of each pendulum kind
            (the DRF also with the book protocol's wide encoder) on ``--sequences`` sequences at max noise
            0.75, at the default rate and at the curves' five, as it was ("former": F.max_pool2d, a
            ``bernoulli_`` mask per rate, the head on the whole chunk) and now, one after the other; and the
            DRF at batches of 64, 256 (the book's) and 1024 sequences per call.
Prints a table; nothing is written.
"""
from __future__ import annotations

import argparse
import sys
import time
from contextlib import contextmanager, nullcontext
from pathlib import Path

import torch
import torch.nn.functional as F
from torch.utils import benchmark

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from drfkit.data.noise import Noise  # noqa: E402
from drfkit.data.pendulum import generate_pendulum  # noqa: E402
from drfkit.models import build_model, default_config  # noqa: E402
from drfkit.models import parts  # noqa: E402
from drfkit.models.parts import Decoder, SharedUniforms, max_pool_2x2  # noqa: E402
from drfkit.methods import uncertainty  # noqa: E402
from drfkit.methods.uncertainty import predict_rates, summarise_samples  # noqa: E402

RATES = (0.05, 0.1, 0.2, 0.3, 0.5)


def seconds(fn, min_run_time: float) -> float:
    return benchmark.Timer("fn()", globals={"fn": fn}).blocked_autorange(min_run_time=min_run_time).median


def pooling_rows(min_run_time: float) -> list[tuple[str, str, float]]:
    rows = []
    for channels in (12, 32):
        for size in (24, 12):
            x = torch.randn(256, channels, size, size)
            assert torch.equal(F.max_pool2d(x, 2), max_pool_2x2(x))
            rows.append((f"pool {channels}x{size}x{size}, 256 frames", "F.max_pool2d",
                         seconds(lambda: F.max_pool2d(x, 2), min_run_time)))
            rows.append((f"pool {channels}x{size}x{size}, 256 frames", "max_pool_2x2",
                         seconds(lambda: max_pool_2x2(x), min_run_time)))
    return rows


def mask_rows(min_run_time: float) -> list[tuple[str, str, float]]:
    dec = Decoder(8, 2, hidden=64, dropout_p=0.1).eval()
    x = torch.randn(8, 75, 8)

    def bernoulli():
        h = dec.hidden(x)
        for p in RATES:
            mask = torch.empty((25, *h.shape)).bernoulli_(1 - p).div_(1 - p)
            summarise_samples(*dec.readout(h.unsqueeze(0) * mask))

    def shared():
        uniforms = SharedUniforms()
        for p in RATES:
            summarise_samples(*dec(x, n_samples=25, dropout_p=p, uniforms=uniforms))

    with torch.inference_mode():
        return [("head, 5 rates, 600 frames", "bernoulli_ per rate", seconds(bernoulli, min_run_time)),
                ("head, 5 rates, 600 frames", "shared uniforms", seconds(shared, min_run_time))]


def former_mc_dropout(h, n_samples, p, uniforms=None):
    """The mask draw before the speed-ups: ``bernoulli_`` per call, nothing shared."""
    if p == 0.0:
        return h.unsqueeze(0).expand(n_samples, *h.shape)
    mask = torch.empty((n_samples, *h.shape), dtype=h.dtype).bernoulli_(1.0 - p)
    return h.unsqueeze(0) * mask.div_(1.0 - p)


@contextmanager
def former_evaluation():
    """predict_rates as it was: F.max_pool2d, a bernoulli_ mask per rate, the head on the whole chunk."""
    saved = parts.max_pool_2x2, parts.mc_dropout, uncertainty.HEAD_CHUNK_FRAMES
    parts.max_pool_2x2 = lambda x: F.max_pool2d(x, 2)
    parts.mc_dropout, uncertainty.HEAD_CHUNK_FRAMES = former_mc_dropout, 10 ** 9
    try:
        yield
    finally:
        parts.max_pool_2x2, parts.mc_dropout, uncertainty.HEAD_CHUNK_FRAMES = saved


def predict_rows(n_sequences: int) -> list[tuple[str, str, float]]:
    images = torch.from_numpy(generate_pendulum(n_sequences, 75, Noise("rkn_uniform", 0.75), 7)["images"])
    models = {"drf": {}, "drf (wide encoder)": {"encoder_channels": 32, "feature_dim": 128},
              "no_dynamics": {}, "lstm": {}, "known_dynamics": {}}
    rows = []
    for label, options in models.items():
        model = build_model(default_config(label.split()[0], "pendulum", 2, **options))
        for rates in ((None,), RATES):
            for how, context in (("former", former_evaluation), ("now", nullcontext)):
                with context():
                    start = time.perf_counter()
                    predict_rates(model, images, n_samples=25, dropout_rates=rates, batch_size=256)
                    rows.append((f"predict_rates {label}, {n_sequences} seq, {len(rates)} rate(s)", how,
                                 time.perf_counter() - start))
    # batching more sequences per call (as stacking seeds or noise levels would): the per-step work of the
    # recursion is what a bigger batch amortises
    model = build_model(default_config("drf", "pendulum", 2))
    for batch in (64, 256, 1024):
        start = time.perf_counter()
        predict_rates(model, images, n_samples=25, dropout_rates=(None,), batch_size=batch)
        rows.append((f"predict_rates drf, {n_sequences} seq, 1 rate(s)", f"batch {batch}", time.perf_counter() - start))
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sequences", type=int, default=1000, help="test sequences for predict_rates")
    parser.add_argument("--min-run-time", type=float, default=1.0, help="seconds per torch.utils.benchmark timer")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    torch.manual_seed(0)
    rows = pooling_rows(args.min_run_time) + mask_rows(args.min_run_time) + predict_rows(args.sequences)
    print(f"{'what':52s} {'how':22s} {'ms':>10s}")
    for what, how, s in rows:
        print(f"{what:52s} {how:22s} {s * 1e3:10.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
