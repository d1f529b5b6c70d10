"""The dissection of one filter with its passes in one ``distinct_frames_once`` block against a block per call,
in one run.

    .venv/bin/python tools/dissection_encodes.py                      # the book protocol's steep DRF, seed 0
    .venv/bin/python tools/dissection_encodes.py --profile quick --untrained --sequences 20 --rounds 1

``drfkit.study.dissection`` passes a filter over three sets made from the same test sequences (training noise,
highest noise, and the blackout: the training noise set with frames [30, 45) pure noise) and over their noiseless
frames. Since the eighth round the whole task is one block, so the encoder sees each distinct frame once per filter
(``drfkit.models.frame_codes``); before, each call was its own block (each distinct frame once per call). This
times ``_dissect_one`` both ways on the first ``--sequences`` test sequences, in alternating rounds at one torch
thread, after one untimed call, checks that both give the same rows byte for byte, and prints per way the median
seconds and the frames the encoder ran on. The checkpoint is the profile's committed one (``--untrained``: a random
model of the kind, for a test). Nothing is written under results/ beyond the test sets the profile makes anyway.
"""
from __future__ import annotations

import argparse
import contextlib
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

    from drfkit.models import build_model
    from drfkit.models.parts import ImageEncoder
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
    real_sets, real_block, real_encode = dissection._sets, dissection.distinct_frames_once, ImageEncoder.encode_frames
    frames = []

    def counted(self, x):
        frames.append(x.shape[0])
        return real_encode(self, x)

    ways = {"one block per filter": real_block, "a block per call": lambda model_: contextlib.nullcontext()}
    seconds = {way: [] for way in ways}
    rows, counts = {}, {}
    shared = portable({key: model})
    try:
        dissection._sets, ImageEncoder.encode_frames = (lambda P_, split: sets), counted
        dissection._dissect_one(P, "test", *key, float("nan"), shared)  # untimed: the first call's one-off costs
        for r in range(args.rounds):
            for way in (list(ways) if r % 2 == 0 else list(ways)[::-1]):
                dissection.distinct_frames_once = ways[way]
                frames.clear()
                t0 = time.perf_counter()
                out = dissection._dissect_one(P, "test", *key, float("nan"), shared)
                seconds[way].append(time.perf_counter() - t0)
                rows[way], counts[way] = repr(out), sum(frames)
    finally:
        dissection._sets, dissection.distinct_frames_once, ImageEncoder.encode_frames = real_sets, real_block, real_encode
    same = rows["one block per filter"] == rows["a block per call"]
    base = statistics.median(seconds["a block per call"])
    print(f"{args.kind} seed {args.seed}, {args.sequences} sequences per set, {args.rounds} round(s), one thread")
    print("| encoded | frames encoded | median s | vs a block per call |")
    print("|---|---|---|---|")
    for way in ways:
        median = statistics.median(seconds[way])
        print(f"| {way} | {counts[way]} | {median:.1f} | {base / median:.2f}x |")
    per_set = sets["train"]["images"].shape[0] * sets["train"]["images"].shape[1]
    print(f"(one set is {per_set} frames)")
    print(f"rows byte for byte the same: {same}")
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
