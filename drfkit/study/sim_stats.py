"""The simulated pedestrian source's statistics for a profile (``drfkit.data.sim_stats`` computes them):

    python -m drfkit simstats --profile paper
"""
from __future__ import annotations

import numpy as np

from drfkit.data.sim_stats import body_span_m, dataset_size, error_autocorrelation, simulator_table


def simulate_profile(P) -> tuple[dict[str, np.ndarray], dict[float, dict[str, np.ndarray]]]:
    """The truth and the records at every ``ped_eval_p`` of a profile's simulated source, as
    ``drfkit.study.studies.pedestrian_records`` builds them (same scenes, seed and detector), in memory
    (nothing cached). ``P``: a typed profile that declares the pedestrians' data parameters
    (``for_notebook("simstats", load_profile(...))``)."""
    from drfkit.data.noise import Noise
    from drfkit.data.sim_detector import DetectorConfig, simulate_records
    from drfkit.data.sim_world import simulate_truth

    truth = simulate_truth(P.pedestrians.n_scenes, P.pedestrians.frames_per_scene, P.pedestrians.data_seed)
    detector = DetectorConfig.from_dict(P.pedestrians.sim_detector)
    records = {float(p): simulate_records(truth, Noise("salt_and_pepper", float(p)), P.pedestrians.data_seed, detector)
               for p in P.pedestrians.eval_p}
    return truth, records


def main(argv: list[str] | None = None) -> int:
    """``python -m drfkit simstats --profile paper``: the simulator's statistics at the
    profile's evaluation noise levels (markdown tables on stdout)."""
    import argparse

    from drfkit.study.params import for_notebook, load_profile

    parser = argparse.ArgumentParser(description=main.__doc__.splitlines()[0])
    parser.add_argument("--profile", default="paper")
    args = parser.parse_args(argv)
    P = for_notebook("simstats", load_profile(args.profile))
    truth, records = simulate_profile(P)
    print(f"profile {args.profile}: {P.pedestrians.n_scenes} scenes x {P.pedestrians.frames_per_scene} keyframes, seed "
          f"{P.pedestrians.data_seed}; body span of the pinhole estimate {body_span_m(truth):.3f} m\n")
    for p, rec in records.items():
        print(f"p = {p:g}: " + ", ".join(f"{k} {v}" for k, v in dataset_size(truth, rec).items()))
    print()
    table = simulator_table(truth, records)
    cols = ["p", "bin", "n_true", "miss_rate", "height_px", "kp_miss_rate", "err_px_median", "err_rel_median",
            "gross_rate", "conf_mean", "pinhole_mae_m", "pinhole_bias_m"]
    print(table[cols].to_markdown(index=False, floatfmt=".3f"))
    print()
    for p, rec in records.items():
        ac = error_autocorrelation(truth, rec)
        print(f"p = {p:g}, lag 1 keyframe: keypoint error correlation {ac['keypoint']:+.4f} "
              f"({ac['n_keypoint_pairs']} keypoint pairs), pinhole relative depth error correlation "
              f"{ac['pinhole_rel']:+.3f} ({ac['n_pairs']} detection pairs)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
