"""The dissection of one filter with its noiseless frames encoded once per model against once per set, in one run.

    .venv/bin/python tools/dissection_encodes.py                      # the paper profile's fifth-round DRF, seed 0
    .venv/bin/python tools/dissection_encodes.py --profile quick --untrained --sequences 20 --rounds 1

``drfkit.study.dissection`` encodes each of its three sets (training noise, highest noise, blackout) and the
noiseless frames of each, which show the same motions: once per model since the sixth round, once per set before.
This times ``_dissect_one`` both ways on the first ``--sequences`` test sequences, in alternating rounds at one torch
thread, after one untimed call, checks that both give the same rows byte for byte, and prints per way the median seconds and the encoder
passes made. The checkpoint is the profile's committed one (``--untrained``: a random model of the kind, for a test).
Nothing is written under results/ beyond the test sets the profile makes anyway.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--profile", default="paper")
    ap.add_argument("--protocol", default="book")
    ap.add_argument("--kind", default="drf_calibrated_steep")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--sequences", type=int, default=200, help="the first N test sequences of each set")
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--untrained", action="store_true", help="a random model of the kind (no checkpoint read)")
    args = ap.parse_args(argv)
    if args.sequences < 1 or args.rounds < 1:
        ap.error("--sequences and --rounds must be >= 1")

    import torch

    from drfkit.methods import dissection as dis
    from drfkit.models import build_model
    from drfkit.models.portable import portable
    from drfkit.study import dissection, studies
    from drfkit.study.params import for_notebook, load_profile

    torch.set_num_threads(1)
    P = for_notebook("02_pendulum_dynamics", load_profile(args.profile))
    key = (args.kind, args.seed)
    if args.untrained:
        torch.manual_seed(args.seed)
        model = build_model(studies.model_config("pendulum", args.kind, P)).eval()
    else:
        trained = studies.trained_models(P, "pendulum", protocol=args.protocol)
        if key not in trained:
            ap.error(f"no trained {args.kind} seed {args.seed} in the {args.protocol} protocol of {args.profile}; "
                     f"trained: {sorted(trained)}")
        model = trained[key]
    sets = {name: {k: v[:args.sequences] for k, v in arrays.items()} for name, arrays in dissection._sets(P, "test").items()}
    real_sets, real_prepared, real_observations = dissection._sets, dissection._prepared, dis.observations
    passes = []

    def counted(model_, images, **kw):
        passes.append(tuple(images.shape))
        return real_observations(model_, images, **kw)

    def once_per_set(model_, arrays, codes):  # the code before the sixth round
        w, r = dis.observations(model_, torch.from_numpy(arrays["images"]))
        w_clean, _ = dis.observations(model_, torch.from_numpy(arrays["clean"]))
        return w, r, model_.observed_truth(w_clean, torch.from_numpy(arrays["targets"]))

    ways = {"once per model": real_prepared, "once per set": once_per_set}
    seconds = {way: [] for way in ways}
    rows, counts = {}, {}
    shared = portable({key: model})
    try:
        dissection._sets, dis.observations = (lambda P_, split: sets), counted
        dissection._dissect_one(P, "test", *key, float("nan"), shared)  # untimed: the first call's one-off costs
        for r in range(args.rounds):
            for way in (list(ways) if r % 2 == 0 else list(ways)[::-1]):
                dissection._prepared = ways[way]
                passes.clear()
                t0 = time.perf_counter()
                out = dissection._dissect_one(P, "test", *key, float("nan"), shared)
                seconds[way].append(time.perf_counter() - t0)
                rows[way], counts[way] = repr(out), len(passes)
    finally:
        dissection._sets, dissection._prepared, dis.observations = real_sets, real_prepared, real_observations
    same = rows["once per model"] == rows["once per set"]
    base = statistics.median(seconds["once per set"])
    print(f"{args.kind} seed {args.seed}, {args.sequences} sequences per set, {args.rounds} round(s), one thread")
    print("| encoded | encoder passes | median s | vs once per set |")
    print("|---|---|---|---|")
    for way in ways:
        median = statistics.median(seconds[way])
        print(f"| {way} | {counts[way]} | {median:.1f} | {base / median:.2f}x |")
    print(f"rows byte for byte the same: {same}")
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
