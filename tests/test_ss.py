"""The subspace-encoder state-space network (``--arch ss``, nnfmu.ss): it starts as the linear model, exactly,
in torch, CasADi and the FMU; trained, its FMU (with its init window) equals torch; it is offered like any
architecture, by its record alone."""

from __future__ import annotations

import re

import numpy as np
import pytest
import torch

from nnfmu.cli import main
from nnfmu.errors import ConfigError, ShapeError
from nnfmu.export import build_fmu, casadi_model
from nnfmu.models import ModelConfig, architectures, build_model, load_model
from nnfmu.training import TrainConfig, dataset_meta, train
from nnfmu.training.linear_start import start_linear_path
from tests.test_linear_path import data, linear, rel  # noqa: F401 (the fixtures: the same system as the path's)

pytestmark = pytest.mark.usefixtures("one_thread")


def ss_model(data, linear, **options):
    config = ModelConfig.from_dict({"arch": "ss", "n_u": data.n_u, "n_y": data.n_y, "hidden": 8,
                                    "linear_order": linear.n_x, **options})
    model = build_model(config, dataset_meta(data, "ss"), norm=data.norm_stats("train")).double()
    start_linear_path(model, data, linear)
    return model


def fmu_run(path, data, u, y0, **past):
    from nnfmu.cosim import FmuSimulator

    with FmuSimulator(path, data.input_names, data.output_names, data.Ts) as sim:
        return sim.simulate(u, y0, **past)


def test_with_its_correction_at_zero_the_ss_network_and_its_fmu_are_the_linear_model(data, linear, tmp_path):
    """Issue 38's check: f, h and the encoder at zero reproduce the linear model's free run to 1e-9, in torch
    and in the FMU (fmpy), also with extra latent states beside the path's."""
    for states in (None, linear.n_x + 2):
        model = ss_model(data, linear, states=states, init_window=4)
        for u, y in zip(data.test.u, data.test.y):
            assert rel(model.simulate(u, y[0]), linear.simulate(u, y[0])) < 1e-9
    fmu = build_fmu(casadi_model(model, name="ss_on_linear"), tmp_path / "ss.fmu")
    u, y = data.test.u[0], data.test.y[0]
    assert rel(fmu_run(fmu, data, u, y[0]), linear.simulate(u, y[0])) < 1e-9


def test_a_trained_ss_network_exports_exactly_with_its_init_window(data, linear, tmp_path):
    """Trained (f, h and the encoder moved off zero), in float64: the checkpoint, CasADi and the FMU given the
    measured window agree with torch to 1e-9, and the window changes the free run (the encoder is used)."""
    result = train(data, ModelConfig.from_dict({"arch": "ss", "n_u": 2, "n_y": 2, "hidden": 8, "init_window": 5,
                                                "linear_order": linear.n_x}),
                   TrainConfig(epochs=3, batch_size=2, truncate=40, dtype="float64", patience=0),
                   out=tmp_path / "ss.pt", linear=linear)
    model = load_model(tmp_path / "ss.pt").double()
    assert any(float(p.detach().abs().max()) > 0 for p in model.encoder[-1].parameters())  # the encoder learned
    u, y = data.test.u[0][4:], data.test.y[0][4:]
    past = {"y_past": data.test.y[0][:4], "u_past": data.test.u[0][:4]}
    want = model.simulate(u, y[0], **past)
    assert rel(want, model.simulate(u, y[0])) > 1e-6  # the window is not ignored
    assert rel(casadi_model(model).simulate(u, y[0], **past), want) < 1e-9
    fmu = build_fmu(casadi_model(model, name="ss_trained"), tmp_path / "ss.fmu")
    assert rel(fmu_run(fmu, data, u, y[0], **past), want) < 1e-9
    assert result.best_valid_nrmse <= result.history[0]["valid_nrmse"]  # never worse than its linear start


def test_the_ss_network_is_offered_by_its_record(capsys):
    """`--arch ss` and its option in `nnfmu train --help`, a place in the --max-minutes search, parallel only."""
    record = architectures.architecture("ss")
    assert "ss" in architectures.search_order() and record.linear_path == "own"
    with pytest.raises(SystemExit):
        main(["train", "--help"])
    text = capsys.readouterr().out
    assert re.search(r"\bss\b", text) and "--ss-states" in text
    assert record.strategies == ("parallel",)


def test_ss_config_rules():
    with pytest.raises(ShapeError, match="linear path's 3 states"):
        ModelConfig.from_dict({"arch": "ss", "n_u": 1, "n_y": 1, "linear_order": 3, "states": 2})
    with pytest.raises(ConfigError, match="increment"):
        ModelConfig.from_dict({"arch": "ss", "n_u": 1, "n_y": 1, "increment": True})
    config = ModelConfig.from_dict({"arch": "ss", "n_u": 1, "n_y": 2})
    assert config.n_states == 4 and config.replace(linear_order=7).n_states == 7  # the path's order once it has one
    model = build_model(config)
    with torch.no_grad():  # without a path: SUBNET's own form, random f and h, a state that moves
        x = model.init_norm(torch.zeros(1, 2), torch.ones(1, 1))
        assert float(model.step_norm(x, torch.ones(1, 1))[0].abs().max()) > 0
