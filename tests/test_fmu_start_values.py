"""Start values: every FMU declares neutral ones inside its valid range (docs/fmu.md, "Start values").

Trained models (networks, hybrids, the linear baseline) start at the training means; the physics
models at rest. Before, every ``<y>_start`` was 0 (0 Pa absolute for the valve's pressure) and every
input started at the minimum of its range.
"""

from __future__ import annotations

import fmpy
import numpy as np
import pytest
from fmpy.validation import validate_fmu
from fmu_cases import built_fmu

from nnfmu.cli import main as nnfmu_main
from nnfmu.data import Channel, from_arrays, save_dataset
from nnfmu.errors import ShapeError
from nnfmu.system import Variable
from nnfmu.valid_range import stored_input_variables, with_starts

VERSIONS = [2, 3]


def starts(fmu) -> dict:
    """name -> (start, min, max) of every input and every ``<y>_start`` parameter."""
    md = fmpy.read_model_description(str(fmu))
    return {v.name: (float(v.start), None if v.min is None else float(v.min), None if v.max is None else float(v.max))
            for v in md.modelVariables if v.causality == "input" or v.name.endswith("_start")}


def test_stored_inputs_start_at_the_training_mean_clipped_into_the_range():
    meta = {"inputs": [{"name": "a"}, {"name": "b"}], "input_range": [[0.0, 10.0], [2.0, 3.0]]}
    a, b = stored_input_variables(meta, np.array([4.0, 7.0]), np.ones(2))
    assert (a.start, b.start) == (4.0, 3.0)  # b's mean lies outside its range: the nearest bound
    with pytest.raises(ShapeError, match="2 finite start values"):
        with_starts([Variable("y"), Variable("z")], [1.0, float("nan")])


@pytest.mark.parametrize("version", VERSIONS)
def test_network_fmu_starts_at_the_training_means(version):
    fmu = built_fmu("valve_gru", version)  # u_mean 5 V in [0, 10] V; y_mean 5e-4 m and 3e5 Pa
    found = starts(fmu)
    assert found["u1"] == found["u2"] == (5.0, 0.0, 10.0)
    assert found["s_start"][0] == pytest.approx(5e-4) and found["p_start"][0] == 3e5  # not 0 Pa absolute
    assert validate_fmu(str(fmu)) == []


@pytest.fixture(scope="module")
def offset_data(tmp_path_factory):
    """A first-order plant around an operating point: input 40 .. 60, output near 1000."""
    rng = np.random.default_rng(4)
    us = [50.0 + 10.0 * np.repeat(rng.uniform(-1, 1, (20, 1)), 15, axis=0) for _ in range(4)]
    ys = []
    for u in us:
        y = np.empty((len(u), 1))
        y[0] = 1000.0
        for k in range(len(u) - 1):
            y[k + 1] = 0.9 * y[k] + 0.1 * (1000.0 + 2.0 * (u[k] - 50.0))
        ys.append(y)
    ds = from_arrays(Ts=0.1, u_train=us[:3], y_train=ys[:3], u_test=us[3:], y_test=ys[3:],
                     input_names=[Channel("flow", "l/min")], output_names=[Channel("level", "mm")])
    return save_dataset(ds, tmp_path_factory.mktemp("offset") / "data"), ds


def test_linear_fmu_starts_at_the_training_means(offset_data, tmp_path):
    folder, ds = offset_data
    fmu = tmp_path / "lin.fmu"
    assert nnfmu_main(["linear", "--data", str(folder), "--order", "1", "--no-refine", "--quiet", "-o", str(fmu)]) == 0
    found = starts(fmu)
    u_mean, y_mean = np.concatenate(ds.train.u).mean(), np.concatenate(ds.train.y).mean()
    start, lo, hi = found["flow"]
    assert start == pytest.approx(u_mean) and lo < start < hi
    assert found["level_start"][0] == pytest.approx(y_mean)  # was 0 mm
    assert validate_fmu(str(fmu)) == []


def test_physics_valve_fmu_starts_at_rest_at_ambient_pressure(tmp_path):
    fmu = tmp_path / "valve.fmu"
    assert nnfmu_main(["physics-fmu", "valve", "-o", str(fmu)]) == 0
    found = starts(fmu)
    assert found["p_start"][0] == 1.013e5 and found["s_start"][0] == 0.0  # was 0 Pa absolute
    assert found["u1"] == (0.0, 0.0, 250.0)  # unpowered pilots: the valve at rest
    assert validate_fmu(str(fmu)) == []
