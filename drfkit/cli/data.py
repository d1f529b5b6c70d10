"""The data layer's commands: ``nuscenes`` (noisy copies of the nuScenes camera images) and
``rodbank`` (the pendulum's rod bank checked against PIL's drawing)."""
from __future__ import annotations

from drfkit.cli import parser


def nuscenes(argv: list[str]) -> int:
    """``python -m drfkit nuscenes noisify --root R --out O --p 0.025``: salt-and-pepper (or another
    registered noise kind's) copies of the keyframe camera images, same relative paths."""
    from drfkit.data.noise import Noise
    from drfkit.data.nuscenes import write_noisy_images
    from drfkit.data.nuscenes_tables import ALL_CAMERAS, DEFAULT_CAMERAS

    ap = parser("nuscenes")
    sub = ap.add_subparsers(dest="command", required=True)
    noisify = sub.add_parser("noisify", help="write salt-and-pepper copies of the keyframe camera images")
    noisify.add_argument("--root", required=True, help="nuScenes folder holding '<version>/' and 'samples/'")
    noisify.add_argument("--out", required=True, help="output folder (same relative paths)")
    noisify.add_argument("--p", type=float, required=True, help="the noise level (salt-and-pepper: probability "
                         "that a pixel is replaced)")
    noisify.add_argument("--kind", default="salt_and_pepper", help="the noise kind (drfkit.data.noise.NOISE_KINDS)")
    noisify.add_argument("--seed", type=int, default=0)
    noisify.add_argument("--version", default="v1.0-mini")
    noisify.add_argument("--cameras", nargs="+", default=list(DEFAULT_CAMERAS), choices=ALL_CAMERAS)
    noisify.add_argument("--format", default="png", choices=("png", "jpg"), dest="image_format")
    args = ap.parse_args(argv)
    noise = Noise(args.kind, args.p)
    written = write_noisy_images(args.root, args.out, noise, args.seed, args.version, args.cameras, args.image_format)
    print(f"wrote {len(written)} noisy images ({noise}) under {args.out}")
    return 0


def rodbank(argv: list[str]) -> int:
    """``python -m drfkit rodbank [N]``: the bank against PIL on N random angles (default 10^6);
    exit 1 if any differ."""
    import time

    from drfkit.data.rod_bank import rod_bank, verify

    ap = parser("rodbank", rodbank.__doc__)
    ap.add_argument("n_angles", nargs="?", type=int, default=1_000_000)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    bad = verify(args.n_angles, args.seed)
    print(f"{len(rod_bank())} bank images; {args.n_angles} random angles drawn by the bank and by PIL: {bad} differ "
          f"({time.perf_counter() - t0:.0f} s)")
    return 1 if bad else 0
