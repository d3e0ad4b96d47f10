"""A physics model of the user's own: ModelBuilder, model files (path.py:NAME), JSON documents, generated data.

The model files are written to a temporary folder outside the repository, as a user's would be. Each bad
file ends in one error of nnfmu's hierarchy that names the file and the fix.
"""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import numpy as np
import pytest

from nnfmu.errors import CheckpointError, ConfigError, DataFileError, ShapeError
from nnfmu.physics import ModelBuilder, PhysicsSystem, resolve_physics, system_to_document
from nnfmu.physics.generate_model import generate_model_dataset
from nnfmu.physics.model_file import models_in_file, split_spec

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"

#: A damped oscillator: the smallest model with a parameter of each kind, an input range and an init rule.
OSCILLATOR = '''
import casadi as ca
from nnfmu.physics import ModelBuilder


def oscillator(k=4.0):
    m = ModelBuilder("oscillator", Ts=0.05, n_sub=2, settle_time=2.0)
    pos = m.state("pos", "m", "position")
    vel = m.state("vel", "m/s", "velocity", scale=2.0)
    F = m.input("F", "N", "force", min=-1.0, max=1.0)
    stiffness = m.parameter("k", k, "N/m", "spring", min=0.1, max=100.0)
    damping = m.parameter("c", 0.5, "N.s/m", "damper", min=0.0, max=10.0, free=False)
    m.ode(pos=vel, vel=F - stiffness * pos - damping * vel)
    y0 = m.output("pos", "m", "measured position", pos)
    m.init(vel=0.1 * y0)
    return m.build()


def helper(x):  # takes an argument: never called to look for models
    raise RuntimeError("not a model")
'''


def write(folder: Path, text: str, name: str = "model.py") -> Path:
    path = folder / name
    path.write_text(textwrap.dedent(text), encoding="utf-8")
    return path


def test_builder_gives_variables_bounds_free_parameters_and_the_init_rule(tmp_path):
    system = resolve_physics(f"{write(tmp_path, OSCILLATOR)}:oscillator")
    assert isinstance(system, PhysicsSystem) and (system.Ts, system.n_sub) == (0.05, 2)
    assert [(v.name, v.min, v.max) for v in system.inputs] == [("F", -1.0, 1.0)]
    assert [(v.name, v.start, v.min, v.max) for v in system.parameters] == [("k", 4.0, 0.1, 100.0),
                                                                           ("c", 0.5, 0.0, 10.0)]
    assert system.free_parameters == ("k",) and system.state_scales == (1.0, 2.0)
    p = system.parameter_values()
    np.testing.assert_array_equal(np.asarray(system.init_state(0.3, 0.0, p)).ravel(), [0.3, 0.03])
    np.testing.assert_allclose(np.asarray(system.ode([1.0, 2.0], 0.5, p)).ravel(), [2.0, 0.5 - 4.0 - 1.0])
    assert system.source["function"] == "oscillator" and Path(system.source["file"]).parent == tmp_path


def test_a_file_with_one_model_needs_no_name_and_info_lists_every_model(tmp_path):
    path = write(tmp_path, OSCILLATOR)
    assert resolve_physics(str(path)).name == "oscillator"
    assert list(models_in_file(path)) == ["oscillator"]
    two = write(tmp_path, OSCILLATOR + "\n\ndef stiff():\n    return oscillator(k=50.0)\n", "two.py")
    assert list(models_in_file(two)) == ["oscillator", "stiff"]
    with pytest.raises(ConfigError, match="defines oscillator, stiff; name one as .*two.py:NAME"):
        resolve_physics(str(two))
    assert resolve_physics(f"{two}:stiff").parameter_values()[0] == 50.0


def test_split_spec_takes_the_last_colon_after_dot_py():
    assert split_spec("C:/models/tanks.py:two_tanks") == (Path("C:/models/tanks.py"), "two_tanks")
    assert split_spec("models/tanks.py") == (Path("models/tanks.py"), None)


def test_the_examples_are_models_and_the_json_document_is_the_same_model(tmp_path):
    tanks = resolve_physics(str(EXAMPLES / "two_tanks.py") + ":two_tanks")
    assert tanks.free_parameters == ("a1", "a2", "k_p") and [v.name for v in tanks.outputs] == ["h2"]
    p = tanks.parameter_values()
    h1, h2 = np.asarray(tanks.init_state(0.2, 5.0, p)).ravel()
    assert h2 == 0.2 and h1 == pytest.approx(0.2 * (6e-5 / 5e-5) ** 2)  # at rest: equal flows
    np.testing.assert_allclose(np.asarray(tanks.ode([h1, h2], 0.0, p)).ravel()[1], 0.0, atol=1e-7)
    assert resolve_physics(str(EXAMPLES / "slider_viscous.py")).free_parameters is None  # m and d: all free
    document = tmp_path / "tanks.json"
    document.write_text(json.dumps(system_to_document(tanks)))
    fit = tmp_path / "fit.json"
    fit.write_text(json.dumps({"format": "nnfmu-greybox-fit/1", "physics": system_to_document(tanks), "fit": {}}))
    x, u = np.array([0.3, 0.1]), np.array([7.0])
    for spec in (document, str(fit)):
        again = resolve_physics(spec)
        assert np.array_equal(np.asarray(again.ode(x, u, p)), np.asarray(tanks.ode(x, u, p)))
        assert again.free_parameters == tanks.free_parameters and again.parameters == tanks.parameters
    (tmp_path / "other.json").write_text("{\"format\": \"something else\"}")
    with pytest.raises(CheckpointError, match="other.json: not a physics model document"):
        resolve_physics(str(tmp_path / "other.json"))


BAD_FILES = {
    "raises on load": ("import casadi\nx = 1 / 0\n", ConfigError, r"model.py:2: loading it raised ZeroDivisionError"),
    "syntax": ("def broken(:\n", ConfigError, r"model.py:1: SyntaxError"),
    "function raises": ("def m():\n    raise KeyError('h3')\n", ConfigError, r"model.py:2: m\(\) raised KeyError"),
    "no model": ("def m():\n    return 3\n", ConfigError, r"m\(\) returned int, expected a model"),
    "ODE too long": (OSCILLATOR.replace("m.ode(pos=vel, vel=F - stiffness * pos - damping * vel)",
                                        "m.ode(ca.vertcat(vel, F, pos))"),
                     ShapeError, r"the ODE gives 3x1 derivatives for 2 states \(pos, vel\)"),
    "ODE misses a state": (OSCILLATOR.replace(", vel=F - stiffness * pos - damping * vel", ""),
                           ShapeError, "the ODE has no derivative for vel"),
    "output not scalar": (OSCILLATOR.replace('m.output("pos", "m", "measured position", pos)',
                                             'm.output("pos", "m", "measured position", ca.vertcat(pos, vel))'),
                          ShapeError, "output 'pos' is 2x1, expected a scalar"),
    "output uses an input": (OSCILLATOR.replace('"measured position", pos)', '"measured position", pos + F)'),
                             ShapeError, r"the output uses symbols it cannot see \(\[F\]\)"),
    "NaN at nominal": (OSCILLATOR.replace("vel=F - stiffness", "vel=ca.log(-stiffness) + F - stiffness"),
                       ConfigError, "ode is NaN or Inf for vel at u = .0.0., y0 = .0.0. and the nominal"),
    "bounds exclude nominal": (OSCILLATOR.replace("min=0.1, max=100.0", "min=5.0, max=100.0"),
                               ConfigError, r"parameter 'k' has nominal value 4 outside its bounds \[5, 100\]"),
}


@pytest.mark.parametrize("case", BAD_FILES)
def test_a_bad_model_file_is_one_error_naming_the_file(tmp_path, case):
    text, error, message = BAD_FILES[case]
    path = write(tmp_path, text)
    name = "m" if "def m()" in text else "oscillator" if "oscillator" in text else "broken"
    with pytest.raises(error, match=message) as caught:
        resolve_physics(f"{path}:{name}")
    assert str(path) in str(caught.value) and "\n" not in str(caught.value)


def test_a_missing_file_or_name_is_one_error(tmp_path):
    with pytest.raises(DataFileError, match="nowhere.py not found"):
        resolve_physics(str(tmp_path / "nowhere.py") + ":m")
    with pytest.raises(ConfigError, match=r"does not define tanks\(\); it defines oscillator"):
        resolve_physics(f"{write(tmp_path, OSCILLATOR)}:tanks")
    with pytest.raises(ConfigError, match="defines no function that returns a model"):
        resolve_physics(str(write(tmp_path, "X = 1\n", "empty.py")))


def test_builder_refuses_reused_names_and_a_state_in_the_init_rule():
    m = ModelBuilder("toy", Ts=0.1)
    x = m.state("x")
    m.state("y")  # a state may share an output's name, never another state's
    with pytest.raises(ShapeError, match="state 'x' reuses a name"):
        m.state("x")
    m.output("x", "", "", x)
    with pytest.raises(ShapeError, match="output 'x' reuses a name"):
        m.output("x", "", "", x)
    m.ode(x=-x, y=x)
    m.init(y=x)
    with pytest.raises(ShapeError, match=r"init_state uses symbols it cannot see \(\[x\]\)"):
        m.build()
    with pytest.raises(ConfigError, match="Ts must be a positive number"):
        ModelBuilder("toy", Ts=0.0)


def test_generated_data_stay_in_the_input_ranges_are_seeded_and_noisy_on_request(tmp_path):
    system = resolve_physics(f"{write(tmp_path, OSCILLATOR)}:oscillator")
    clean = generate_model_dataset(system, size="small", seed=3)
    assert clean.train.n_traj == 16 and clean.test.n_traj == 2 and clean.Ts == 0.05
    u = np.concatenate(clean.train.u)
    assert u.min() >= -1.0 and u.max() <= 1.0 and np.ptp(u) > 1.5  # the whole range, never beyond
    first = clean.train
    np.testing.assert_array_equal(first.y[0], system.model().simulate(first.u[0], first.y[0][0]))
    noisy = generate_model_dataset(system.source["file"] + ":oscillator", size="small", seed=3, noise=0.05)
    np.testing.assert_array_equal(noisy.train.u[0], first.u[0])
    residual = np.concatenate(noisy.train.y) - np.concatenate(first.y)
    assert residual.std() == pytest.approx(0.05 * np.concatenate(first.y).std(), rel=0.05)
    assert noisy.source["noise"] == 0.05 and noisy.source["model_source"]["function"] == "oscillator"
    open_range = ModelBuilder("open", Ts=0.1)
    s = open_range.state("s")
    f = open_range.input("f")
    open_range.ode(s=f - s)
    open_range.output("s", "", "", s)
    with pytest.raises(ConfigError, match=r"input\(s\) f have no range"):
        generate_model_dataset(open_range.build())



def test_a_model_without_parameters_has_no_p_port_and_one_without_inputs_is_not_generated():
    m = ModelBuilder("decay", Ts=0.1)
    x = m.state("x")
    f = m.input("f", min=0.0, max=1.0)
    m.ode(x=f - x)
    m.output("y", "", "", x)
    model = m.build().model()
    assert model.init.name_in() == ["y0", "u0"] and model.step.name_in() == ["x", "u"]
    assert model.continuous.ode.name_in() == ["x", "u"] and model.spec.parameters == ()
    free = ModelBuilder("free", Ts=0.1)
    s = free.state("s")
    free.ode(s=-s)
    free.output("s", "", "", s, start=1.0)
    with pytest.raises(ConfigError, match="free has no inputs"):
        generate_model_dataset(free.build())


def test_an_inputs_start_defaults_inside_its_range_and_is_checked_there():
    """Issue 37, item 7: an input with min=5, max=10 passed info and generate, but physics-fmu refused its start 0."""
    import casadi as ca

    from nnfmu.export.model_description import check_spec

    def tank(**start):
        m = ModelBuilder("tank", Ts=0.1)
        h = m.state("h", "m")
        q = m.input("q", "m3/s", min=5, max=10, **start)
        w = m.input("w", "m3/s", min=-1, max=3)
        m.output("level", "m", "level", h)
        m.ode(h=q + w - ca.sqrt(h * h + 1))
        return m.build()

    system = tank()
    assert [v.start for v in system.inputs] == [7.5, 0.0]  # the range's middle where it excludes 0, else 0
    check_spec(system.model().spec)  # what physics-fmu checks before writing the FMU
    assert tank(start=6.0).inputs[0].start == 6.0
    with pytest.raises(ConfigError, match="input 'q' has start value 2 outside its bounds \\[5, 10\\]"):
        tank(start=2.0)
