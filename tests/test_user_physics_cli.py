"""A user's model file outside the repository through ``nnfmu physics-fmu``, ``generate`` and ``info``.

The FMU of examples/two_tanks.py (copied to a temporary folder) validates, simulates as co-simulation (equal to
the CasADi model) and as Model Exchange (CVode, equal to a fine RK4), its directional derivatives equal
central finite differences to 1e-6 relative, and it still simulates after the model file is deleted. Bad
files end in one line and status 2, with nothing written.
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fmpy.validation import validate_fmu
from test_fmu_model_exchange import MeInstance

from nnfmu.cli import main as nnfmu_main
from nnfmu.data import load_dataset
from nnfmu.physics import resolve_physics

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "two_tanks.py"
N = 300  # samples of 1 s


@pytest.fixture(scope="module")
def tanks(tmp_path_factory):
    """(model file, FMU) of a copy of the two-tank example in a folder outside the repository."""
    folder = tmp_path_factory.mktemp("user")
    model_file = folder / "my_tanks.py"
    shutil.copy(EXAMPLE, model_file)
    fmu = folder / "tanks.fmu"
    assert nnfmu_main(["physics-fmu", f"{model_file}:two_tanks", "-o", str(fmu)]) == 0
    return model_file, fmu


def _pump(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Pump voltages held for 40 s (n, 1) and fmpy's input signal with a step (an event) at each change."""
    u = np.repeat(np.random.default_rng(0).uniform(0.0, 10.0, n // 40 + 1), 40)[:n, None]
    t = np.arange(n, dtype=float)
    rows = [(t[k], u[k - 1, 0]) for k in range(1, n) if u[k, 0] != u[k - 1, 0]] + list(zip(t, u[:, 0]))
    rows.sort(key=lambda row: row[0])
    return u, np.array(rows, dtype=[("time", float), ("u", float)])


def _simulate(fmu: Path, fmi_type: str, signal, **options) -> np.ndarray:
    result = fmpy.simulate_fmu(str(fmu), fmi_type=fmi_type, stop_time=N - 1.0, output_interval=1.0, input=signal,
                               start_values={"h2_start": 0.05}, **options)
    rows = [np.flatnonzero(np.abs(result["time"] - k) < 1e-6)[-1] for k in range(N)]
    return result["h2"][rows]


def test_the_fmu_of_a_user_model_simulates_both_ways_and_without_its_file(tanks, tmp_path):
    model_file, fmu = tanks
    assert validate_fmu(str(fmu)) == []
    md = fmpy.read_model_description(str(fmu))
    assert md.modelExchange is not None and [d.variable.name for d in md.derivatives] == ["der(x.h1)", "der(x.h2)"]
    assert {v.name: (float(v.min), float(v.max)) for v in md.modelVariables if v.causality == "input"} == \
        {"u": (0.0, 10.0)}
    model = resolve_physics(f"{model_file}:two_tanks")
    u, signal = _pump(N)
    cs = _simulate(fmu, "CoSimulation", signal)
    expected = model.model().simulate(u, [0.05])[:, 0]
    assert np.ptp(expected) > 0.05, "the pump must move the level"
    np.testing.assert_allclose(cs, expected, rtol=0, atol=1e-12)
    me = _simulate(fmu, "ModelExchange", signal, solver="CVode", relative_tolerance=1e-10)
    fine = model.model(n_sub=32).simulate(u, [0.05])[:, 0]
    assert np.max(np.abs(me - fine)) < 1e-3 * np.ptp(fine)  # CVode and a fine RK4 solve the same ODE
    moved = tmp_path / "elsewhere.fmu"
    shutil.copy(fmu, moved)
    model_file.unlink()  # the FMU is standalone C: the model file is not needed any more
    np.testing.assert_array_equal(_simulate(moved, "CoSimulation", signal), cs)
    assert np.max(np.abs(_simulate(moved, "ModelExchange", signal, solver="CVode") - fine)) < 1e-2 * np.ptp(fine)


def test_directional_derivatives_of_a_user_model_equal_finite_differences(tanks):
    me = MeInstance(tanks[1], {"h2_start": 0.2})
    me.set({"u": 6.0})
    x = np.array([0.31, 0.17])
    me.set_states(x)
    unknowns, knowns = ["der(x.h1)", "der(x.h2)", "h2"], ["x.h1", "x.h2", "u"]
    jacobian = me.jacobian(unknowns, knowns)
    fd = me.finite_differences(unknowns, {"u": 6.0}, floor=1e-5)
    assert np.count_nonzero(jacobian) == 5  # h1' on h1 and u, h2' on h1 and h2, y = h2
    np.testing.assert_array_less(np.abs(jacobian - fd) / np.abs(jacobian).max(axis=1, keepdims=True), 1e-6)
    me.fmu.terminate()
    me.fmu.freeInstance()


def test_generate_and_info_take_a_user_model(tmp_path, capsys):
    model_file = tmp_path / "tanks.py"
    shutil.copy(EXAMPLE, model_file)
    out = tmp_path / "data"
    assert nnfmu_main(["generate", str(model_file), "-o", str(out), "--size", "small", "--noise", "0.01"]) == 0
    ds = load_dataset(out)
    assert [(c.name, c.unit) for c in ds.inputs] == [("u", "V")] and [c.name for c in ds.outputs] == ["h2"]
    assert ds.train.n_traj == 16 and ds.source["noise"] == 0.01 and ds.Ts == 1.0
    capsys.readouterr()
    assert nnfmu_main(["info", str(model_file)]) == 0
    text = capsys.readouterr().out
    assert f"{model_file}:two_tanks: two_tanks" in text and "a1 [m2]  nominal 5e-05  bounds 1e-06 .. 0.001" in text
    assert "A1 [m2]  nominal 0.0154  fixed" in text and "u [V]  range 0.0 .. 10.0" in text
    assert nnfmu_main(["info", "slider"]) == 0 and "F_s [N]  nominal 2.5" in capsys.readouterr().out


def test_generate_keeps_the_built_in_generators_and_adds_noise_on_request(tmp_path):
    from nnfmu.physics import generate_dataset

    assert nnfmu_main(["generate", "slider", "-o", str(tmp_path / "s"), "--size", "small", "--noise", "0.1"]) == 0
    noisy, clean = load_dataset(tmp_path / "s"), generate_dataset("slider", size="small")
    np.testing.assert_array_equal(noisy.train.u[0], clean.train.u[0])
    residual = np.concatenate(noisy.train.y) - np.concatenate(clean.train.y)
    assert residual.std() == pytest.approx(0.1 * np.concatenate(clean.train.y).std(), rel=0.05)


@pytest.mark.parametrize("command", ["physics-fmu", "generate"])
@pytest.mark.parametrize("text, spec, message", [
    (None, "missing.py:m", "missing.py not found"),
    ("import casadi\n1 / 0\n", "model.py:m", "model.py:2: loading it raised ZeroDivisionError"),
    ("def other():\n    return 1\n", "model.py:m", r"does not define m\(\)"),
    ("from nnfmu.physics import ModelBuilder\n\ndef m():\n    b = ModelBuilder('m', Ts=1.0)\n    x = b.state('x')\n"
     "    b.ode(x=1 / (x - x))\n    b.output('y', '', '', x)\n    return b.build()\n", "model.py:m", "NaN or Inf"),
])
def test_a_bad_model_file_is_one_line_and_status_2_with_nothing_written(tmp_path, capsys, command, text, spec,
                                                                       message):
    if text is not None:
        (tmp_path / "model.py").write_text(text)
    out = tmp_path / "out"
    assert nnfmu_main([command, str(tmp_path / spec), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"nnfmu {command}: error: ")
    assert re.search(message, err)
    assert sorted(p.name for p in tmp_path.iterdir()) == (["model.py"] if text else [])
