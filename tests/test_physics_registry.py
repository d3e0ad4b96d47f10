"""The physics registry and the physics document: every model by one name, stored without Python code."""

from __future__ import annotations

import json

import numpy as np
import pytest

from nnfmu.errors import CheckpointError, ConfigError, ShapeError
from nnfmu.physics import (PhysicsEntry, StudyPreset, physics_entry, physics_names, register_physics,
                           resolve_physics, study_names, study_preset, system_from_document, system_to_document)


def test_the_built_in_models_are_registered():
    assert {"valve", "arm", "slider"} <= set(physics_names())


def test_each_study_compares_with_the_model_of_its_entry():
    assert set(study_names()) >= {"valve", "arm", "robot", "slider"}
    entry, robot = study_preset("robot")
    assert entry is physics_entry("arm") and robot.data_sizes is None and robot.data_kind == "robot-benchmark"
    assert study_preset("valve")[1].data_sizes == physics_entry("valve").sizes  # the full size first
    with pytest.raises(ConfigError, match="unknown system 'pump'; choose one of arm, robot, slider, valve"):
        study_preset("pump")


def test_an_entry_refuses_a_study_it_cannot_generate_data_for():
    lag = lambda: resolve_physics("slider")  # noqa: E731
    with pytest.raises(ConfigError, match="asks for data sizes .*'paper'.* choose among those"):
        PhysicsEntry("lag", lag, studies=(StudyPreset(name="lag", title="Lag", data_sizes=("paper", "small")),))
    with pytest.raises(ConfigError, match="without a generator of its own its sizes are standard, small"):
        PhysicsEntry("lag", lag, sizes=("huge",))
    with pytest.raises(ConfigError, match="no other braces"):
        StudyPreset(name="lag", title="Lag", data_sizes=None, note="x = {1, 2}")
    with pytest.raises(ConfigError, match="already the study of 'arm'"):
        register_physics(PhysicsEntry("lag", lag, studies=(StudyPreset(name="robot", title="R", data_sizes=None),)))


def test_an_unknown_name_lists_the_choices():
    with pytest.raises(ConfigError, match="choose one of .*slider"):
        resolve_physics("no_such_model")


def test_a_taken_name_cannot_be_registered_again_with_another_model():
    with pytest.raises(ConfigError, match="already registered"):
        register_physics(PhysicsEntry("valve", lambda: resolve_physics("slider")))


@pytest.mark.parametrize("name", ["valve", "slider", "arm"])
def test_a_document_round_trips_through_json_exactly(name):
    system = resolve_physics(name)
    again = system_from_document(json.loads(json.dumps(system_to_document(system))))
    rng = np.random.default_rng(0)
    x, u = rng.uniform(0.1, 1.0, system.n_x), rng.uniform(0.1, 1.0, len(system.inputs))
    p = system.parameter_values()
    assert np.array_equal(np.asarray(system.ode(x, u, p)), np.asarray(again.ode(x, u, p)))
    assert np.array_equal(np.asarray(system.output(x, p)), np.asarray(again.output(x, p)))
    assert (again.states, again.inputs, again.outputs, again.parameters) == (
        system.states, system.inputs, system.outputs, system.parameters)
    assert (again.Ts, again.n_sub, again.name) == (system.Ts, system.n_sub, system.name)


def test_a_damaged_document_is_refused_in_one_error():
    doc = system_to_document(resolve_physics("slider"))
    with pytest.raises(CheckpointError, match="not a physics model document"):
        system_from_document({**doc, "format": "other"})
    with pytest.raises(CheckpointError, match="damaged"):
        system_from_document({**doc, "ode": "garbage"})


def test_free_parameters_must_name_parameters():
    import dataclasses

    with pytest.raises(ShapeError, match="not among its parameters"):
        dataclasses.replace(resolve_physics("slider"), free_parameters=("m", "mass"))
