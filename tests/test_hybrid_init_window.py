"""A hybrid's FMU with an init window: ``nnfmu export HYBRID.pt --init-window N``.

The estimator fits the start state of the hybrid's own step (physics plus correction) over the window; the FMU
equals the CasADi model to 1e-9 in float64, and ``nnfmu evaluate --init-window N`` scores it. A network's
checkpoint with ``--init-window`` is one line and status 2 (its own init window is learned in training).
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
from nnfmu.models import build_model, load_model
from nnfmu.models.checkpoint import save_checkpoint
from nnfmu.physics import generate_model_dataset
from nnfmu.physics.initial_state import with_init_window

pytestmark = pytest.mark.usefixtures("one_thread")

MODEL = f"{Path(__file__).resolve().parents[1] / 'examples' / 'two_tanks.py'}:two_tanks"
N = 15


@pytest.fixture(scope="module")
def hybrid(tmp_path_factory):
    """(dataset folder, checkpoint) of a two-tank hybrid whose correction has small random weights."""
    folder = tmp_path_factory.mktemp("hybrid")
    ds = generate_model_dataset(MODEL, size="small", noise=0.0)
    model = build_model(HybridConfig(n_u=1, n_y=1, physics=MODEL, hidden=6, physics_backend="sx"), ds.meta(),
                        norm=ds.norm_stats("train")).double()
    g = torch.Generator().manual_seed(0)
    with torch.no_grad():
        for p in model.correction.parameters():
            p.copy_(0.05 * torch.randn(p.shape, generator=g, dtype=torch.float64))
    return save_dataset(ds, folder / "data"), save_checkpoint(folder / "hybrid.pt", model), ds


def test_the_hybrid_fmu_with_a_window_equals_its_casadi_model(hybrid, tmp_path, capsys):
    data, ckpt, ds = hybrid
    fmu, scores = tmp_path / "h.fmu", tmp_path / "scores.json"
    assert main(["export", str(ckpt), "--init-window", str(N), "-o", str(fmu)]) == 0
    assert inspect_fmu(fmu).init_window == N
    network = load_model(ckpt).double()
    model = with_init_window(casadi_model(network), N, y_scale=network.y_std.numpy(),
                             x_scale=network.physics.state_scales)
    u, y = ds.test.u[0], ds.test.y[0]
    k = 100
    expected = model.simulate(u[k:], y[k], y_past=y[k - N + 1:k], u_past=u[k - N + 1:k])
    with FmuSimulator(fmu, ds.input_names, ds.output_names, ds.Ts) as sim:
        got = sim.simulate(u[k:], y[k], y[k - N + 1:k], u[k - N + 1:k])
    scale = np.abs(expected).max()
    np.testing.assert_allclose(got / scale, expected / scale, rtol=0, atol=1e-9)
    assert not np.allclose(got, model.simulate(u[k:], y[k]), rtol=1e-6)  # the window matters
    assert main(["evaluate", str(fmu), "--data", str(data), "--init-window", str(N), "--json", str(scores)]) == 0
    assert json.loads(scores.read_text())["protocol"]["init_window"] == N
    capsys.readouterr()


def test_a_network_checkpoint_refuses_an_init_window(hybrid, tmp_path, capsys):
    _, _, ds = hybrid
    from nnfmu.models import ModelConfig

    net = build_model(ModelConfig(arch="gru", n_u=1, n_y=1, hidden=4), ds.meta(), norm=ds.norm_stats("train"))
    ckpt = save_checkpoint(tmp_path / "gru.pt", net)
    assert main(["export", str(ckpt), "--init-window", "5", "-o", str(tmp_path / "g.fmu")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "nnfmu train --init-window 5" in err
    assert not (tmp_path / "g.fmu").exists()
