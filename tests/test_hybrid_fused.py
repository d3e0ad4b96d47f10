"""The hybrid's whole step as one compiled call equals the stage-by-stage path: values and gradients, float64."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from nnfmu.hybrid import HybridConfig
from nnfmu.hybrid.fused import fused_step
from nnfmu.models import build_model
from nnfmu.training.compiled_rollout import ENV_SWITCH

pytestmark = pytest.mark.usefixtures("one_thread")

VALVE = {"physics": "valve", "physics_params": {"k_s": 1.3 * 25e3, "C_max": 0.7 * 6e-10, "d_c": 0.0}}


def _hybrid(data, options: dict):
    """A float64 valve hybrid for ``data`` with a small correction network."""
    config = HybridConfig(n_u=data.n_u, n_y=data.n_y, hidden=6, train_physics=options.pop("train", ()), **options)
    model = build_model(config, data.meta(), norm=data.norm_stats("train")).double()
    generator = torch.Generator().manual_seed(0)
    with torch.no_grad():  # a nonzero correction and moved parameters: every term of the step counts
        for prm in model.correction.parameters():
            prm.copy_(0.3 * torch.randn(prm.shape, generator=generator, dtype=torch.float64))
        model.physics_log_scale.copy_(0.02 * torch.randn(model.physics_log_scale.shape, generator=generator))
    return model


def _rollout_and_gradients(model, u, y, monkeypatch, fused: bool):
    monkeypatch.setenv(ENV_SWITCH, "1" if fused else "0")
    un, yn0 = model.normalise_u(torch.tensor(u)), model.normalise_y(torch.tensor(y[:, 0]))
    ys = model.rollout_normalised(un, yn0)
    weights = torch.linspace(0.5, 1.5, ys.numel(), dtype=torch.float64).reshape(ys.shape)
    grads = torch.autograd.grad((ys * weights).sum(), list(model.parameters()), allow_unused=True)
    return ys.detach(), [None if g is None else g.detach() for g in grads]


@pytest.mark.parametrize("looped", [False, True], ids=["unrolled", "looped"])
@pytest.mark.parametrize("options", [
    {**VALVE, "train": ("k_s", "C_max")},
    {**VALVE, "correction": "step", "activation": "relu", "layers": 1},
], ids=["derivative", "step"])
def test_the_fused_step_equals_the_stage_by_stage_path(valve_small, options, looped, monkeypatch):
    """Every RK4 sub-step (the valve has 4) with the network, the physics' output and the trained parameters;
    ``looped``: the step of physics too large to unroll (the arm's), a C loop over one SX sub-step."""
    from nnfmu.hybrid import fused

    u, y = np.stack([a[:40] for a in valve_small.train.u[:3]]), np.stack([a[:40] for a in valve_small.train.y[:3]])
    model = _hybrid(valve_small, dict(options)).train()
    if looped:
        monkeypatch.setattr(fused, "MAX_ODE_INSTRUCTIONS", 4 * model.n_sub * model.physics.ode.n_instructions() - 1)
        assert not fused.unrolled(model) and fused.step_function(model).is_a("MXFunction")
    assert fused_step(model, 3) is not None
    got, got_grads = _rollout_and_gradients(model, u, y, monkeypatch, fused=True)
    want, want_grads = _rollout_and_gradients(model, u, y, monkeypatch, fused=False)
    assert torch.allclose(got, want, rtol=0, atol=1e-12 * float(want.abs().max()))
    for a, b in zip(got_grads, want_grads):
        assert (a is None) == (b is None)
        if b is not None:
            assert b.abs().max() > 0 and torch.allclose(a, b, rtol=0, atol=1e-12 * float(b.abs().max()))


def test_active_dropout_keeps_the_stage_by_stage_path(valve_small):
    model = _hybrid(valve_small, {**VALVE, "dropout": 0.2})
    assert fused_step(model.train(), 3) is None and fused_step(model.eval(), 3) is not None
    sx = _hybrid(valve_small, {**VALVE, "physics_backend": "sx"})
    assert fused_step(sx, 3) is None


def test_physics_too_large_to_unroll_train_large_batches_stage_by_stage(valve_small, monkeypatch):
    """The looped step costs the same per trajectory at any batch; the per-stage path is faster on large batches
    with gradients, and much slower on one trajectory (the arm's validation run)."""
    from nnfmu.hybrid import fused
    from nnfmu.physics import arm_system

    assert 4 * 50 * arm_system().ode.n_instructions() > fused.MAX_ODE_INSTRUCTIONS  # the arm: 50 sub-steps
    model = _hybrid(valve_small, dict(VALVE))
    monkeypatch.setattr(fused, "MAX_ODE_INSTRUCTIONS", 4 * model.n_sub * model.physics.ode.n_instructions() - 1)
    large = fused.LOOPED_MAX_BATCH + 1
    assert fused_step(model, large) is None and fused_step(model, fused.LOOPED_MAX_BATCH) is not None
    with torch.no_grad():
        assert fused_step(model, large) is not None


def test_a_large_fused_step_compiles_at_o1():
    """A user's model with the default network gives megabytes of straight-line C, which GCC takes minutes to
    optimise at -O3 (two tanks: 153 CPU-s against 18 s at -O1, training equally fast): large sources get -O1."""
    from nnfmu.hybrid.compiled_torch import LARGE_SOURCE, _flags

    large, small = _flags("x" * (LARGE_SOURCE + 1)), _flags("x" * 1000)
    assert "-O1" in large and not any(f in large for f in ("-O2", "-O3"))
    assert "-O3" in small and "-ffp-contract=off" in large  # the same floating-point rules at either level
