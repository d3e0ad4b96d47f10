"""The physics registry and the physics document: every model by one name, stored without Python code."""

from __future__ import annotations

import json

import numpy as np
import pytest

from nnfmu.errors import CheckpointError, ConfigError, ShapeError
from nnfmu.physics import (PhysicsEntry, physics_names, register_physics, resolve_physics, system_from_document,
                           system_to_document)


def test_the_built_in_models_are_registered():
    assert {"valve", "arm", "slider"} <= set(physics_names())


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
