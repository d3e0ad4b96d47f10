"""An architecture from outside nnfmu plugs in through its public record alone (issue 22, docs/design.md,
"Adding an architecture").

The toy (tests/plugins/toy_arch: a leaky recurrent cell on nnfmu's base classes) is registered by its own
module, loaded through ``NNFMU_PLUGINS``, trained both ways, exported to an FMU that fmpy scores as the
torch model scores it, and offered by ``nnfmu train --arch`` (with its own option) and ``nnfmu tune --arch``.
"""

from __future__ import annotations

import ast
import os
import re
import subprocess
import sys
import types
from pathlib import Path

import dataclasses

import numpy as np
import pytest

from nnfmu.errors import ConfigError
from nnfmu.models import architectures

PLUGINS = Path(__file__).parent / "plugins"
pytestmark = pytest.mark.usefixtures("one_thread")


@pytest.fixture(scope="module")
def toy():
    """The toy's record, loaded as a user loads it (NNFMU_PLUGINS); the registry is restored afterwards."""
    architectures.records()  # every installed architecture registered, so that restoring the records keeps them
    records, env, path = dict(architectures._RECORDS), os.environ.get("NNFMU_PLUGINS"), list(sys.path)
    os.environ["NNFMU_PLUGINS"] = "toy_arch"
    sys.path.insert(0, str(PLUGINS))
    try:
        yield architectures.architecture("toy")  # unknown yet: the lookup loads the plugins
    finally:
        sys.modules.pop("design_example", None)
        architectures._RECORDS.clear()
        architectures._RECORDS.update(records)
        architectures._loaded.discard("toy_arch")
        sys.path[:] = path
        for name in [m for m in sys.modules if m == "toy_arch" or m.startswith("toy_arch.")]:
            del sys.modules[name]
        if env is None:
            os.environ.pop("NNFMU_PLUGINS")
        else:
            os.environ["NNFMU_PLUGINS"] = env


@pytest.fixture(scope="module")
def data():
    """A small nonlinear plant: y+ = 0.8 y + 0.3 tanh(u) (4 records of 80 samples to train, 2 to test)."""
    from nnfmu.data import from_arrays

    rng = np.random.default_rng(0)
    u = rng.standard_normal((6, 80, 1)).cumsum(axis=1) * 0.3
    y = np.zeros((6, 80, 1))
    for k in range(79):
        y[:, k + 1] = 0.8 * y[:, k] + 0.3 * np.tanh(u[:, k])
    return from_arrays(Ts=0.1, u_train=u[:4], y_train=y[:4], u_test=u[4:], y_test=y[4:])


def test_the_toy_trains_both_ways_exports_and_scores_in_fmpy(toy, data, tmp_path):
    from nnfmu.cosim import evaluate
    from nnfmu.export import casadi_model
    from nnfmu.export.fmu import build_fmu
    from nnfmu.models import ModelConfig, load_model
    from nnfmu.training import TrainConfig, train

    config = ModelConfig.from_dict({"arch": "toy", "n_u": 1, "n_y": 1, "hidden": 6, "leak": 0.3})
    assert type(config).__name__ == "ToyConfig"  # a stored config finds the plugin's class through the record
    scores = {}
    for strategy in ("series-parallel", "parallel"):
        result = train(data, config, TrainConfig(strategy=strategy, epochs=3, batch_size=2, seed=0),
                       out=tmp_path / f"{strategy}.pt", device="cpu")
        assert type(result.model).__name__ == "ToyStepModel" and len(result.history) == 4
        scores[strategy] = result.test.mean
    model = load_model(tmp_path / "parallel.pt")
    fmu = build_fmu(casadi_model(model), tmp_path / "toy.fmu")  # casadi_model checks the export against torch
    got = evaluate([fmu], data)[0]
    u, y = data.test.u[0], data.test.y[0]
    from nnfmu.cosim import FmuSimulator

    with FmuSimulator(fmu, data.input_names, data.output_names, data.Ts) as sim:
        fmpy_run = sim.simulate(u, y[0])
    torch_run = model.simulate(u, y[0])
    assert np.ptp(torch_run) > 0
    assert float(np.max(np.abs(fmpy_run - torch_run)) / np.max(np.abs(torch_run))) < 1e-9
    assert got.result.mean == pytest.approx(scores["parallel"], rel=1e-6)


def test_nnfmu_train_and_tune_offer_the_toy(toy, data, tmp_path, capsys):
    from nnfmu.cli import main
    from nnfmu.data import save_dataset
    from nnfmu.models import load_model

    env = {**os.environ, "NNFMU_PLUGINS": "toy_arch",
           "PYTHONPATH": os.pathsep.join([str(PLUGINS), os.environ.get("PYTHONPATH", "")])}
    helps = {command: " ".join(subprocess.run([sys.executable, "-m", "nnfmu", command, "--help"], env=env,
                                              capture_output=True, text=True, check=True).stdout.split())
             for command in ("train", "tune")}
    for command, text in helps.items():
        choices = text.partition("--arch ARCH the architecture")[2].partition(": ")[2].partition(" (")[0]
        assert "toy" in choices.split(", "), (command, choices)
    assert "--arch toy: a leaky one-layer recurrent toy (a plugin): --toy-leak A" in helps["train"]
    folder = tmp_path / "data"
    save_dataset(data, folder)
    argv = ["train", "--data", str(folder), "--arch", "toy", "--toy-leak", "0.5", "--hidden", "4", "--epochs", "1",
            "--linear-path", "off", "--quiet", "--out", str(tmp_path / "toy.pt")]
    assert main(argv) == 0, capsys.readouterr().err
    assert load_model(tmp_path / "toy.pt").config.leak == 0.5
    assert main(["train", "--data", str(folder), "--arch", "gru", "--toy-leak", "0.5", "--out", "x.pt"]) == 2
    assert "--toy-leak only apply to --arch toy" in capsys.readouterr().err


def test_a_plugin_that_cannot_be_imported_is_one_warning_not_a_broken_command_line(tmp_path):
    env = {**os.environ, "NNFMU_PLUGINS": "no_such_plugin"}
    run = subprocess.run([sys.executable, "-m", "nnfmu", "train", "--data", str(tmp_path), "--arch", "no_such_plugin",
                          "-o", str(tmp_path / "x.pt")], env=env, capture_output=True, text=True)
    assert run.returncode == 2 and "Traceback" not in run.stderr
    assert "cannot import the architecture plugin 'no_such_plugin'" in run.stderr
    assert "invalid choice: 'no_such_plugin'" in run.stderr and not (tmp_path / "x.pt").exists()


def test_the_toy_touches_no_underscored_name_of_nnfmu():
    """The public base is enough: the toy overrides, calls and imports no ``_name`` of nnfmu (its own helpers may)."""
    for path in (PLUGINS / "toy_arch").glob("*.py"):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        own = {n.name for n in tree.body if isinstance(n, ast.FunctionDef)}
        private = [f"{path.name}:{n.lineno} {name}" for n in ast.walk(tree)
                   for name in ([n.attr] if isinstance(n, ast.Attribute) else
                                [n.name] if isinstance(n, ast.FunctionDef) else
                                [a.name for a in n.names] if isinstance(n, ast.ImportFrom) else [])
                   if name.startswith("_") and not name.startswith("__") and name not in own]
        assert private == []
        assert "super().__post_init__()" in path.read_text() or path.name != "model.py"


def test_every_records_references_resolve(toy):
    """Each class and function a record names, lazily or not, exists: a rename fails here, not at a user's."""
    checked = 0
    for record in architectures.records():
        architectures.check_references(record)
        checked += len(record.references())
    assert checked >= 6 * 5 + 4  # config, model, step, init (and the networks' rollout cell) of each
    broken = dataclasses.replace(toy, casadi_step="toy_arch.casadi_step:renamed_step")
    with pytest.raises(ConfigError, match="'toy'.*casadi_step 'toy_arch.casadi_step:renamed_step' does not resolve"):
        architectures.check_references(broken)


def test_the_toy_is_in_the_max_minutes_search_space(toy):
    from nnfmu.models import ModelConfig
    from nnfmu.study import time_space
    from nnfmu.training import TrainConfig

    config = ModelConfig(arch="gru", n_u=1, n_y=1)
    searched = time_space.axes(config, TrainConfig(), given=set(), longest=100)["arch"]
    assert searched[0] == "gru" and "toy" in searched
    assert searched.index("toy") == len(searched) - 1  # its search_rank, 7, is the last


def _design_example() -> str:
    """The Python block of docs/design.md's "Adding an architecture"."""
    page = (Path(__file__).parents[1] / "docs" / "design.md").read_text(encoding="utf-8")
    section = page.partition("## Adding an architecture")[2].partition("\n## ")[0]
    return re.findall(r"```python\n(.*?)```", section, flags=re.DOTALL)[0]


def test_the_design_pages_example_architecture_trains_exports_and_is_offered(data, tmp_path, capsys):
    from nnfmu.cli import main
    from nnfmu.export import to_casadi
    from nnfmu.models import ModelConfig, build_model
    from nnfmu.training import TrainConfig, train

    architectures.records()
    records = dict(architectures._RECORDS)
    try:
        module = sys.modules["design_example"] = types.ModuleType("design_example")
        exec(compile(_design_example(), "design.md", "exec", dont_inherit=True), module.__dict__)  # noqa: S102
        config = ModelConfig(arch="affine", n_u=1, n_y=1)
        assert type(config).__name__ == "AffineConfig" and config.window == 1
        result = train(data, config, TrainConfig(epochs=6, batch_size=2, seed=0), out=tmp_path / "a.pt", device="cpu")
        losses = [h["train_loss"] for h in result.history if h["train_loss"] is not None]
        assert losses[-1] < losses[0] and np.isfinite(result.test.mean)  # it trains
        to_casadi(result.model.double())  # checks CasADi against torch (relative 1e-9)
        for increment in (False, True):
            to_casadi(build_model(config.replace(increment=increment)).double())
        with pytest.raises(SystemExit):
            main(["train", "--help"])
        assert "affine" in capsys.readouterr().out
        assert "affine" in architectures.search_order()
    finally:
        sys.modules.pop("design_example", None)
        architectures._RECORDS.clear()
        architectures._RECORDS.update(records)


def test_the_installed_entry_points_are_those_of_pyproject():
    """The built-in architectures are found through the entry points, so the installed metadata must list each one
    that pyproject.toml declares (after a change there: pip install -e . again)."""
    import tomllib
    from importlib.metadata import entry_points

    declared = tomllib.loads((Path(__file__).parents[1] / "pyproject.toml").read_text())["project"]["entry-points"]
    installed = {ep.name: ep.value for ep in entry_points(group=architectures.ENTRY_POINT_GROUP)}
    assert installed == dict(declared[architectures.ENTRY_POINT_GROUP]), "reinstall nnfmu: pip install -e ."
