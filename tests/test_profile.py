"""The typed profile (drfkit.study.profile): the schema's sections as frozen dataclasses."""
from __future__ import annotations

import dataclasses
import pickle

import pytest

from drfkit.study.params import NOTEBOOKS, ParameterError, for_notebook, load_profile
from drfkit.study.profile import Profile, ProfileSection, build_profile
from drfkit.study.schema import PATHS, SPECS


def _read(P, path: tuple[str, ...]):
    for part in path:
        P = getattr(P, part)
    return P


@pytest.mark.parametrize("notebook", sorted(NOTEBOOKS))
def test_every_declared_parameter_sits_at_its_schema_path(notebook):
    values = load_profile("paper")
    P = for_notebook(notebook, values)
    for name in NOTEBOOKS[notebook]:
        assert _read(P, PATHS[name]) == values[name], name
    assert P.as_dict() == {name: values[name] for name in NOTEBOOKS[notebook]}  # the flat names, back


def test_sections_are_typed_frozen_dataclasses_named_by_their_path():
    P = for_notebook("02_pendulum_dynamics", load_profile("quick"))
    assert type(P) is Profile and type(P.pendulum).__name__ == "PendulumSection"
    assert type(P.pendulum.book).__name__ == "PendulumBookSection"
    assert type(P.dynamics.ablation.round2).__name__ == "DynamicsAblationRound2Section"
    fields = {f.name: f.type for f in dataclasses.fields(type(P.pendulum))}
    assert fields["epochs"] is int and fields["eval_max_noise"] == list[float] and fields["book"] is type(P.pendulum.book)
    with pytest.raises(dataclasses.FrozenInstanceError):
        P.pendulum.epochs = 3
    # one attribute per parameter: the schema's flat names and the profile's leaves are the same set
    def leaves(cls, path=()):
        for f in dataclasses.fields(cls):
            if isinstance(f.type, type) and issubclass(f.type, ProfileSection):
                yield from leaves(f.type, path + (f.name,))
            else:
                yield path + (f.name,)
    assert sorted(leaves(Profile)) == sorted(PATHS[n] for n in SPECS)


def test_an_undeclared_parameter_is_an_error_that_says_where_to_declare_it():
    P = for_notebook("05_timing", load_profile("quick"))
    assert P.uncertainty.n_samples >= 1
    with pytest.raises(ParameterError, match=r"notebook 05_timing does not declare parameter 'gating_sweep_points' "
                                             r"\[gating\.sweep_points\]; add it .*NOTEBOOKS"):
        P.gating.sweep_points
    bench = for_notebook("bench", load_profile("quick"))
    with pytest.raises(ParameterError, match="python -m drfkit bench does not declare parameter 'pend_models'"):
        bench.pendulum.models


def test_a_profile_pickles_with_its_values_and_its_holder():
    """Grid workers receive the profile pickled."""
    P = for_notebook("03_nuscenes_training", load_profile("quick"))
    Q = pickle.loads(pickle.dumps(P))
    assert Q.as_dict() == P.as_dict() and Q.pedestrians.sim_detector == P.pedestrians.sim_detector
    with pytest.raises(ParameterError, match="notebook 03_nuscenes_training does not declare"):
        Q.gating.sweep_points


def test_the_measurement_cache_keys_a_profile_by_its_declared_values():
    from drfkit.book.measurements import fingerprint

    a = build_profile({"seeds": [0, 1], "pend_lr": 1e-3}, "a test")
    b = build_profile({"pend_lr": 1e-3, "seeds": [0, 1]}, "another test")
    c = build_profile({"seeds": [0, 1], "pend_lr": 2e-3}, "a test")
    assert fingerprint(a) == fingerprint(b) != fingerprint(c)


def test_build_profile_refuses_a_name_the_schema_lacks():
    with pytest.raises(ParameterError, match=r"a test: unknown parameter\(s\) \['pend_nonsense'\]"):
        build_profile({"pend_nonsense": 1}, "a test")
