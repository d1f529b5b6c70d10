"""The simulated pedestrian source of a profile, in memory, for its statistics (``drfkit.data.sim_stats``
computes them; ``python -m drfkit simstats --profile paper`` prints them)."""
from __future__ import annotations

import numpy as np


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
