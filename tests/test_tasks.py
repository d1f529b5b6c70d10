"""drfkit.util.tasks: evaluation tasks on worker processes, results in the items' order and the same numbers at
any worker count."""
from __future__ import annotations

import pandas as pd
import pytest
import torch

from drfkit.util import tasks


def test_worker_setting_parses_and_refuses_with_the_forms(monkeypatch):
    monkeypatch.delenv(tasks.ENV, raising=False)
    assert tasks.task_workers() == 1
    monkeypatch.setenv(tasks.ENV, "3")
    assert tasks.task_workers() == 3
    monkeypatch.setenv(tasks.ENV, "auto")
    assert tasks.task_workers() == tasks.usable_cores()
    monkeypatch.setenv(tasks.ENV, "tcp://host:8786")
    assert tasks.task_workers() == "tcp://host:8786"
    monkeypatch.setenv(tasks.ENV, "two")
    with pytest.raises(ValueError, match="DRF_WORKERS='two'.*'auto'"):
        tasks.task_workers()
    with pytest.raises(ValueError, match=">= 1"):
        tasks.task_workers(0)


def test_in_process_tasks_keep_the_order_run_at_one_thread_and_restore_it(monkeypatch):
    monkeypatch.delenv(tasks.ENV, raising=False)
    seen = []

    def fn(i, shared):
        seen.append(torch.get_num_threads())
        return shared["base"] + i

    before = torch.get_num_threads()
    assert tasks.map_tasks(fn, [(3,), (1,), (2,)], shared={"base": 10}) == [13, 11, 12]
    assert seen == [1, 1, 1] and torch.get_num_threads() == before


@pytest.mark.slow
def test_the_evaluation_tables_are_byte_for_byte_the_same_at_one_and_two_workers(monkeypatch, tmp_path):
    """Two random-weight models of the quick profile: the tables of two worker processes (each task on whichever
    worker is free) equal those made in this process, byte for byte, each run from an empty results folder (no
    cached prediction shared between them): the evaluation at two test levels, the mechanism checks and the
    blackout curves, the validation sigma scales, the calibration table, the dissection, the limit on pixels,
    rounding or truncation and the true-physics reference."""
    from drfkit.data.pendulum import blackout_frames
    from drfkit.models import build_model
    from drfkit.study import dynamics, studies
    from drfkit.study.dissection import dissect_filters
    from drfkit.study.evaluate import calibration_table, evaluate_study, uncertainty_scales
    from drfkit.study.params import for_notebook, load_profile

    P = for_notebook("04_ood_noise_evaluation", load_profile("quick"))
    torch.manual_seed(0)
    models = {(kind, 0): build_model(studies.model_config("pendulum", kind, P)).eval()
              for kind in ("no_dynamics", "drf")}
    tables = {}
    for workers in ("1", "2"):  # in this process first: a model that has run (an LSTM's flat-weight references) still goes
        monkeypatch.setenv("DRF_RESULTS", str(tmp_path / workers))
        monkeypatch.setenv(tasks.ENV, workers)
        try:
            sequences = {0.5: 6, 0.75: 6}
            scales = uncertainty_scales(P, "pendulum", models)
            made = [evaluate_study(P, "pendulum", [0.5, 0.75], models=models, sequences=sequences),
                    dynamics.mechanism_table(P, models, 0.75), dynamics.blackout_curves(P, models),
                    pd.DataFrame({"scale": scales}),
                    calibration_table(P, "pendulum", [0.5, 0.75], models, scales, sequences=sequences),
                    *dissect_filters(P, models),
                    *dynamics.pixel_limit(dynamics.limit_profile(P), [0.5], n_sequences=2, particle_counts=(50, 100)),
                    dynamics.quantisation_effect(P, models, [0.5, 0.75], n_sequences=2, n_particles=50),
                    *dynamics.physics_reference(P, {0: models[("no_dynamics", 0)]}, [0.5], n_particles=50)]
        finally:
            tasks.close_workers()
        tables[workers] = [table.to_csv(index=False) for table in made]
    assert tables["2"] == tables["1"]
    evals, mechanism, curves, scales, calibration, _, interventions, horizons, _, limit, conv, quant, ref, _ = tables["1"]
    assert limit.count("\n") == 1 + 3 * 4 and conv.count("\n") == 1 + 3 * 2   # clean, 0.5, blackout
    assert quant.count("\n") == 1 + 2 * 2 * (2 * 2 + 2) and ref.count("\n") == 1 + 2   # 0.5 and the blackout
    assert evals.count("\n") == 1 + 4 and mechanism.count("\n") == 1 + 2 and "gain_ratio_blackout" in mechanism
    assert scales.count("\n") == 1 + 2 and calibration.count("\n") == 1 + 2 * 2 * 2  # (model, level) x intervals
    start, stop = blackout_frames(P.pendulum.seq_len)
    assert interventions.count("\n") == 1 + 1 and horizons.count("\n") == 1 + stop - start  # the DRF, each gap frame


def test_a_portable_model_crosses_as_its_config_and_weights():
    """Pickled, a model that has run comes back rebuilt from its configuration and weights, in its mode, computing
    the same outputs; in this process ``.model`` is the caller's own object."""
    import pickle

    from drfkit.models import build_model, default_config
    from drfkit.models.portable import Portable, portable

    torch.manual_seed(0)
    model = build_model(default_config("lstm", "pendulum", 2)).eval()
    frames = torch.randint(0, 255, (2, 4, 24, 24), dtype=torch.uint8)
    with torch.no_grad():
        before = model.features(frames)
    wrapped = portable({("lstm", 0): model})
    assert wrapped[("lstm", 0)].model is model
    back = pickle.loads(pickle.dumps(wrapped))[("lstm", 0)].model
    assert back is not model and not back.training and back.config == model.config
    with torch.no_grad():
        after = back.features(frames)
    assert all((a is None and b is None) or torch.equal(a, b) for a, b in zip(after, before))
    with pytest.raises(TypeError, match="no .config"):
        pickle.dumps(Portable(object()))


@pytest.mark.slow
def test_the_workers_keep_glibcs_own_trim_threshold(monkeypatch):
    """Dask starts its workers with MALLOC_TRIM_THRESHOLD_=65536, under which the models' evaluation ran about 3x
    slower per task than in this process; ``local_cluster`` (the evaluation's and the training grid's) drops it."""
    from distributed import Client

    monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", "65536")  # what an earlier plain LocalCluster leaves in os.environ
    with tasks.local_cluster(1, dashboard_address=None) as cluster, Client(cluster) as client:
        seen = client.run(_trim_threshold)
    assert list(seen.values()) == [None]


def _trim_threshold():
    import os

    return os.environ.get("MALLOC_TRIM_THRESHOLD_")
