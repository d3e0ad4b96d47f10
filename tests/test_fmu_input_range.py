"""The valid input range: stored with the model, declared as min/max, guarded by doStep, counted by evaluate."""

from __future__ import annotations

import json

import fmpy
import numpy as np
import pytest
from fmpy.validation import validate_fmu
from fmu_cases import MODELS, FMICallException, Instance, built_fmu, excitation

from nnfmu.cli import main as nnfmu_main
from nnfmu.data import Channel, from_arrays, save_dataset
from nnfmu.valid_range import RANGE_MARGIN, count_outside, training_range

VERSIONS = [2, 3]


def declared_ranges(fmu) -> dict:
    md = fmpy.read_model_description(str(fmu))
    return {v.name: (float(v.min), float(v.max)) for v in md.modelVariables if v.causality == "input"}


def test_training_range_is_widened_by_the_documented_margin():
    u = [np.array([[0.0, 5.0], [2.0, 5.0]]), np.array([[10.0, 5.0]])]
    assert RANGE_MARGIN == 0.1
    assert training_range(u) == [(-1.0, 11.0), (5.0, 5.0)]  # a constant input: valid at that value only


def test_count_outside_counts_samples_and_inputs():
    u = [np.array([[0.0, 1.0], [5.0, 1.0], [5.0, 9.0]]), np.array([[-1.0, 0.0]])]
    counted = count_outside(u, ["a", "b"], {"a": (0.0, 4.0), "b": (None, 2.0)})
    assert (counted.samples, counted.total, counted.per_input) == (3, 4, {"a": 3, "b": 1})
    assert counted.describe() == "3 of 4 samples (a 3, b 1)"


def test_a_trained_network_stores_its_training_range(valve_small):
    from nnfmu.training import dataset_meta

    meta = dataset_meta(valve_small, "gru")
    assert meta["input_range"] == training_range(valve_small.train.u)
    lo, hi = np.array(meta["input_range"]).T
    u = np.concatenate(valve_small.train.u)
    np.testing.assert_allclose(hi - lo, 1.2 * (u.max(0) - u.min(0)))


@pytest.mark.parametrize("version", VERSIONS)
def test_network_fmu_declares_the_stored_range(version):
    fmu = built_fmu("valve_gru", version)  # its checkpoint meta holds input_range [[0, 10], [0, 10]]
    assert declared_ranges(fmu) == {"u1": (0.0, 10.0), "u2": (0.0, 10.0)}
    assert validate_fmu(str(fmu)) == []


@pytest.mark.parametrize("version", VERSIONS)
def test_out_of_range_input_warns_once_per_excursion_and_still_computes(version):
    model = MODELS["nonlinear"]  # inputs u1, u2 valid in [-3, 3] V
    u = 0.5 * excitation(model, 12)
    u[3:6, 0] = 7.5  # first excursion of u1: three samples
    u[8, 0] = -4.0  # second excursion
    inst = Instance(built_fmu("nonlinear", version)).initialize()
    statuses, outputs = [], []
    for row in u[:-1]:
        inst.set({"u1": row[0], "u2": row[1]})
        statuses.append(inst.step(model.spec.Ts))
        outputs.append(inst.get(["s", "q"]))
    assert statuses == [0, 0, 0, 1, 1, 1, 0, 0, 1, 0, 0]  # fmi2Warning / fmi3Warning while outside
    warnings = inst.warnings()
    assert len(warnings) == 2, warnings
    assert "input u1 = 7.5 V at t = 0.006" in warnings[0] and "valid range [-3, 3] V" in warnings[0]
    assert "input u1 = -4 V" in warnings[1]
    np.testing.assert_allclose(outputs, model.simulate(u, [0.0, 1.0])[1:], rtol=1e-12, atol=1e-15)
    inst.close()


@pytest.mark.parametrize("version", VERSIONS)
def test_input_range_error_parameter_turns_the_guard_into_an_error(version):
    model = MODELS["nonlinear"]
    inst = Instance(built_fmu("nonlinear", version))
    inst.set_int("input_range_error", True)
    inst.initialize()
    inst.run(model, np.zeros((2, 2)))
    before = inst.get(["s", "q", "time"])
    inst.set({"u2": -3.5})
    with pytest.raises(FMICallException):
        inst.step(model.spec.Ts)
    assert "input u2 = -3.5 V at t = 0.004 s is outside its valid range [-3, 3] V; the step was not taken" \
        in inst.errors()[-1]
    np.testing.assert_array_equal(inst.get(["s", "q", "time"]), before)
    inst.close()


def test_an_input_without_a_range_is_unbounded():
    md = fmpy.read_model_description(str(built_fmu("blowup", 2)))
    (u,) = [v for v in md.modelVariables if v.causality == "input"]
    assert u.min is None and u.max is None


@pytest.fixture(scope="module")
def oscillator_data(tmp_path_factory):
    """The oscillator's own trajectories, inputs in about [-2, 2] N; the test inputs peak at 3 N."""
    model, rng = MODELS["linear"], np.random.default_rng(1)
    train = [np.clip(rng.normal(size=(150, 1)), -2, 2) for _ in range(3)]
    test = [np.sin(np.arange(200)[:, None] * 0.05) * 3.0]
    ys = [model.simulate(u, [0.1, 0.0]) for u in train + test]
    ds = from_arrays(Ts=0.01, u_train=train, y_train=ys[:3], u_test=test, y_test=ys[3:],
                     input_names=[Channel("force", "N")], output_names=[Channel("pos", "m"), Channel("vel", "m/s")])
    return save_dataset(ds, tmp_path_factory.mktemp("osc") / "data"), ds


def test_linear_fmu_declares_its_training_range_and_evaluate_counts_excursions(oscillator_data, tmp_path, capsys):
    folder, ds = oscillator_data
    fmu, report = tmp_path / "lin.fmu", tmp_path / "scores.json"
    assert nnfmu_main(["linear", "--data", str(folder), "--order", "2", "--no-refine", "-o", str(fmu)]) == 0
    lo, hi = training_range(ds.train.u)[0]
    assert declared_ranges(fmu) == {"force": (lo, hi)}
    assert nnfmu_main(["evaluate", "--data", str(folder), str(fmu), "--json", str(report)]) == 0
    test_u = ds.test.u[0][:, 0]
    outside = int(((test_u < lo) | (test_u > hi)).sum())
    assert 20 < outside < 200
    assert f"inputs outside the valid range of lin: {outside} of 200 samples (force {outside})" \
        in capsys.readouterr().out
    assert json.loads(report.read_text())["models"][0]["inputs_out_of_range"]["samples"] == outside
