"""What the evaluation's two savings buy, in one run: each distinct frame encoded once, and the dropout-rate
curves' later rates run on stored features instead of computing them again.

    .venv/bin/python tools/features_store.py                     # the paper profile's book-protocol pendulum models
    .venv/bin/python tools/features_store.py --profile quick --untrained --sequences 8 --rounds 1

Notebook 04's PICP–MPIW curves ask every model at four dropout rates besides its own on test sets that the
evaluations before them already predicted at its own rate. ``drfkit.methods.predictions`` stores the deterministic
part of the first prediction (``model.features``: the encoder, then the filter or LSTM), so the curves run only the
heads. And the evaluation encodes each distinct frame once (``drfkit.models.frame_codes.distinct_frames_once``): the
pendulum's clean frames come from the rod bank's few hundred images. Per model kind (seed ``--seed``), on the first
``--sequences`` test sequences at ``--noise``, at one torch thread, in alternating rounds after one untimed call,
this prints the median seconds of the encoder (``model.observe``) on every frame and on the distinct ones, of the
features (as the evaluation runs them), and of the four other rates predicted with the features computed and with
them read; it checks that each pair gives the same numbers bit for bit. Nothing is written under results/ beyond
the test sets the profile makes anyway (the store is a temporary folder).
"""
from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

FIELDS = ("mean", "aleatoric", "epistemic", "total", "point")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--profile", default="paper")
    ap.add_argument("--protocol", default="book")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--noise", type=float, default=0.5)
    ap.add_argument("--sequences", type=int, default=256, help="the first N test sequences (one evaluation chunk)")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--untrained", action="store_true", help="random models of the kinds (no checkpoint read)")
    args = ap.parse_args(argv)
    if args.sequences < 1 or args.rounds < 1:
        ap.error("--sequences and --rounds must be >= 1")

    import torch

    from drfkit.methods import predictions
    from drfkit.models import build_model
    from drfkit.models.frame_codes import distinct_frames_once
    from drfkit.study import studies
    from drfkit.study.params import for_notebook, load_profile

    torch.set_num_threads(1)
    P = for_notebook("04_ood_noise_evaluation", load_profile(args.profile))
    if args.untrained:
        models = {}
        for kind in studies.study_models(P, "pendulum", protocol=args.protocol):
            torch.manual_seed(args.seed)
            models[kind] = build_model(studies.model_config("pendulum", kind, P, protocol=args.protocol)).eval()
    else:
        trained = studies.trained_models(P, "pendulum", protocol=args.protocol)
        models = {kind: m for (kind, seed), m in trained.items() if seed == args.seed}
        if not models:
            ap.error(f"no trained seed {args.seed} in the {args.protocol} protocol of {args.profile}")
    x = studies.study_data(P, "pendulum", "test", args.noise).inputs[:args.sequences]
    n, rates = P.uncertainty.n_samples, P.uncertainty.dropout_rates
    distinct = torch.unique(x.flatten(2).flatten(0, 1), dim=0).shape[0]
    print(f"{args.sequences} test sequences at {args.noise}: {distinct:,} distinct frames of {x.shape[0] * x.shape[1]:,}; "
          f"seed {args.seed}, {args.rounds} round(s), one thread; {n} samples")
    print("| model | encoder, every frame s | distinct frames s | features s | 4 other rates, features computed s | "
          "on stored features s | ratio | same bit for bit |")
    print("|---|---|---|---|---|---|---|---|")
    all_same = True
    for kind, model in models.items():
        other = [p for p in rates if p != model.default_dropout_p][:4]
        with tempfile.TemporaryDirectory() as stored, tempfile.TemporaryDirectory() as empty:
            kw = dict(n_samples=n, dropout_rates=other, seed=args.seed, batch_size=predictions.EVAL_BATCH_SIZE)
            predictions.cached_features(model, x, cache=Path(stored), batch_size=predictions.EVAL_BATCH_SIZE)
            def distinct_observe():
                with distinct_frames_once(model):
                    return model.observe(x)

            ways = {"encoder": lambda: model.observe(x), "distinct": distinct_observe,
                    "features": lambda: predictions.model_features(model, x, batch_size=predictions.EVAL_BATCH_SIZE),
                    # a fresh folder per call: the features and the rates computed, nothing found
                    "computed": lambda: predictions.cached_predict_rates(model, x, cache=Path(tempfile.mkdtemp(dir=empty)), **kw),
                    "stored": lambda: _later_rates(predictions, model, x, Path(stored), kw)}
            seconds = {way: [] for way in ways}
            out = {}
            with torch.no_grad():
                for way, fn in ways.items():
                    fn()  # untimed: the first call's one-off costs
                for r in range(args.rounds):
                    for way in (list(ways) if r % 2 == 0 else list(ways)[::-1]):
                        t0 = time.perf_counter()
                        out[way] = ways[way]()
                        seconds[way].append(time.perf_counter() - t0)
        same = all(torch.equal(getattr(a, f), getattr(b, f)) for a, b in zip(out["computed"], out["stored"])
                   for f in FIELDS) and all(torch.equal(a, b) for a, b in zip(out["encoder"], out["distinct"]))
        all_same &= same
        med = {way: statistics.median(s) for way, s in seconds.items()}
        print(f"| {kind} | {med['encoder']:.2f} | {med['distinct']:.2f} | {med['features']:.2f} | "
              f"{med['computed']:.2f} | {med['stored']:.2f} | {med['computed'] / med['stored']:.1f}x | {same} |")
    return 0 if all_same else 1


def _later_rates(predictions, model, x, stored: Path, kw: dict):
    """The other rates with the features read from ``stored`` (the rates' own entries removed first: computed)."""
    for f in stored.glob("*.pt"):
        f.unlink()
    return predictions.cached_predict_rates(model, x, cache=stored, **kw)


if __name__ == "__main__":
    raise SystemExit(main())
