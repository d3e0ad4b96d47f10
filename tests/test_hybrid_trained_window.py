"""A hybrid that trains with its FMU's estimator: ``nnfmu train --arch hybrid --init-window N`` (issue 34, item 1).

Every training window, validation run and score starts from the state the FMU's estimator fits over the ``N``
samples up to ``y0`` (:mod:`nnfmu.hybrid.initial_state`), with the current weights. On noise-free data of the
true two-tank model (the upper tank unmeasured), training windows cut inside the records start right with it and
wrong without it. The estimate in torch equals the exported CasADi model's to 1e-9, ``nnfmu export`` gives the
FMU the window without being told, and the FMU scores what training reported.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from nnfmu.cli import main
from nnfmu.cosim import FmuSimulator, inspect_fmu
from nnfmu.data import save_dataset
from nnfmu.export import casadi_model
from nnfmu.hybrid import HybridConfig
from nnfmu.models import build_model, load_checkpoint, load_model
from nnfmu.physics import generate_model_dataset

pytestmark = pytest.mark.usefixtures("one_thread")

MODEL = f"{Path(__file__).resolve().parents[1] / 'examples' / 'two_tanks.py'}:two_tanks"
N = 12


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    """(folder, dataset) of the true two tanks, noise-free, the small size."""
    ds = generate_model_dataset(MODEL, size="small", noise=0.0)
    return save_dataset(ds, tmp_path_factory.mktemp("tanks") / "data"), ds


def _hybrid(ds, window: int, seed: int = 0):
    model = build_model(HybridConfig(n_u=1, n_y=1, physics=MODEL, hidden=6, physics_backend="sx",
                                     init_window=window), ds.meta(), norm=ds.norm_stats("train")).double()
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for p in model.correction.parameters():
            p.copy_(0.05 * torch.randn(p.shape, generator=g, dtype=torch.float64))
    return model


def test_the_estimate_in_training_is_the_exported_models_to_1e9(clean):
    _, ds = clean
    model = _hybrid(ds, N)
    exported = casadi_model(model)
    assert exported.spec.init_window == N
    p = [v.start for v in exported.spec.parameters]
    for i, k in ((0, N - 1), (0, 300), (1, 150)):
        u, y = ds.test.u[i], ds.test.y[i]
        past = dict(y_past=y[k - N + 1:k], u_past=u[k - N + 1:k])
        with torch.no_grad():
            x_torch = model.init(*(torch.tensor(a)[None] for a in (y[k], u[k], past["y_past"], past["u_past"])))
        x_casadi = np.asarray(exported.init(y[k], u[k], p, past["y_past"].ravel(), past["u_past"].ravel())).ravel()
        scale = np.asarray(model.physics.state_scales)
        np.testing.assert_allclose(x_torch[0].numpy() / scale, x_casadi / scale, rtol=0, atol=1e-9)
        with torch.no_grad():
            run = model.simulate(u[k:], y[k], **past)
        expected = exported.simulate(u[k:], y[k], **past)
        np.testing.assert_allclose(run / np.abs(expected).max(), expected / np.abs(expected).max(), rtol=0, atol=1e-9)


def test_a_neural_ode_with_an_init_window_runs_as_its_exported_model(clean):
    """The neural ODE is a hybrid on generated physics: its unmeasured states are estimated the same way."""
    from nnfmu.node.config import NodeConfig

    _, ds = clean
    model = build_model(NodeConfig(n_u=1, n_y=1, hidden=6, n_states=2, physics_backend="sx", init_window=N),
                        ds.meta(), norm=ds.norm_stats("train")).double()
    g = torch.Generator().manual_seed(0)
    with torch.no_grad():
        for p in model.correction.parameters():
            p.copy_(0.3 * torch.randn(p.shape, generator=g, dtype=torch.float64))
    exported = casadi_model(model)
    assert exported.spec.init_window == N
    u, y, k = ds.test.u[0], ds.test.y[0], 100
    past = dict(y_past=y[k - N + 1:k], u_past=u[k - N + 1:k])
    with torch.no_grad():
        run = model.simulate(u[k:], y[k], **past)
    expected = exported.simulate(u[k:], y[k], **past)
    np.testing.assert_allclose(run / np.abs(expected).max(), expected / np.abs(expected).max(), rtol=0, atol=1e-9)
    assert not np.allclose(run, model.simulate(u[k:], y[k]), rtol=1e-6)  # the window matters


def _first_loss(data, out: Path, window: int) -> float:
    """The training loss of one epoch, at a learning rate too small to move the weights from the true physics."""
    assert main(["train", "--data", str(data), "--arch", "hybrid", "--physics", MODEL, "--physics-backend", "sx",
                 "--init-window", str(window), "--truncate", "40", "--epochs", "1", "--lr", "1e-12",
                 "--train-physics", "none", "-o", str(out)]) == 0
    return load_checkpoint(out)["history"][-1]["train_loss"]


def test_training_windows_start_from_the_estimated_unmeasured_level(clean, tmp_path, capsys):
    data, _ = clean
    with_window = _first_loss(data, tmp_path / "window.pt", N)
    from_y0 = _first_loss(data, tmp_path / "rule.pt", 1)
    capsys.readouterr()
    # the true physics from the estimated state runs as the data (noise-free); from the init rule's guess of the
    # upper tank (at rest) every window inside a record starts wrong
    assert with_window < 1e-9 < 1e-4 < from_y0


def test_export_gives_the_fmu_its_training_window_and_it_scores_what_training_said(clean, tmp_path, capsys):
    data, ds = clean
    ckpt, fmu, scores = tmp_path / "h.pt", tmp_path / "h.fmu", tmp_path / "scores.json"
    assert main(["train", "--data", str(data), "--arch", "hybrid", "--physics", MODEL, "--physics-backend", "sx",
                 "--init-window", str(N), "--epochs", "2", "--hidden", "6", "-o", str(ckpt)]) == 0
    assert f"starts from its estimator over a record's first {N} samples" in capsys.readouterr().out
    reported = load_checkpoint(ckpt)["summary"]["test_nrmse_window"]
    assert main(["export", str(ckpt), "--init-window", "5", "-o", str(fmu)]) == 2
    assert "trained from the state its estimator fits over 12 samples" in capsys.readouterr().err
    assert not fmu.exists()
    assert main(["export", str(ckpt), "-o", str(fmu)]) == 0
    assert inspect_fmu(fmu).init_window == N
    assert main(["evaluate", str(fmu), "--data", str(data), "--init-window", str(N), "--json", str(scores)]) == 0
    assert json.loads(scores.read_text())["models"][0]["nrmse"] == pytest.approx(reported, rel=1e-9)
    network = load_model(ckpt).double()
    u, y = ds.test.u[0], ds.test.y[0]
    k = 200
    with torch.no_grad():
        expected = network.simulate(u[k:], y[k], y_past=y[k - N + 1:k], u_past=u[k - N + 1:k])
    with FmuSimulator(fmu, ds.input_names, ds.output_names, ds.Ts) as sim:
        got = sim.simulate(u[k:], y[k], y[k - N + 1:k], u[k - N + 1:k])
    np.testing.assert_allclose(got / np.abs(expected).max(), expected / np.abs(expected).max(), rtol=0, atol=1e-9)
    capsys.readouterr()
