"""A hybrid's initial state from its init window, in training and scoring: the estimator its FMU runs.

With ``HybridConfig.init_window = N > 1`` a hybrid starts every free run (each training window, the validation
runs, the scores) from the state that its FMU's estimator (:mod:`nnfmu.physics.initial_state`) computes from the
``N`` samples that end at ``y0``: Levenberg-Marquardt on the state at the window's oldest sample, through the
hybrid's own step (physics plus correction, with the current weights and physical parameters), each output's
error divided by its training standard deviation, each state by the physics' state scale. These are the
algorithm, constants and scales that ``nnfmu export`` compiles into the FMU, so training, validation and the
FMU start from the same state (tests/test_hybrid_trained_window.py: to 1e-9).

The estimator is one CasADi Function per model structure, whose parameter vector holds the physical
parameters and then the correction's weights (:func:`nnfmu.hybrid.fused.step_function`), mapped over the
windows of a batch and evaluated in CasADi's virtual machine in float64. Its result enters the free run as a
fixed start: the loss reaches the weights through the run from it, not through the estimate. A window whose
estimate is not finite starts from the physics' init rule at ``(y0, u0)``, as in the FMU.

Cost: ``iterations`` Gauss-Newton steps of ``N - 1`` model steps with their ``n_x`` forward sensitivities, for
every window of every batch: about 50 ms per window on the two tanks with a 32-wide correction and ``N = 20``
(AMD EPYC), so that training on windows of 50 samples cut inside the records took 15 times the CPU time of
training from the init rule (benchmarks/hybrid_init_window.py).
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import torch

from nnfmu.hybrid.fused import step_function, structure_key, weight_vector
from nnfmu.physics.initial_state import FINITE_LIMIT, ITERATIONS, lm_estimator

_ESTIMATORS: dict[tuple, ca.Function] = {}


def _key(model) -> tuple:
    """What the estimator's graph depends on besides the weights and the physical parameters."""
    def values(t: torch.Tensor) -> tuple:
        return tuple(t.detach().double().reshape(-1).tolist())

    return (structure_key(model), model.config.init_window, values(model.u_mean), values(model.u_std),
            values(model.y_std))


def estimator(model) -> ca.Function:
    """``estimate(y_win[n_y, N], u_win[n_u, N - 1], q) -> (x_end, x_start, cost)`` of ``model`` (a
    HybridStepModel with ``init_window = N > 1``), ``q = [p; w]``: its physical parameters, then its correction's
    weights as :func:`~nnfmu.hybrid.fused.weight_vector` flattens them."""
    key = _key(model)
    if key not in _ESTIMATORS:
        _ESTIMATORS[key] = _build(model)
    return _ESTIMATORS[key]


def _build(model) -> ca.Function:
    system, config = model.physics, model.config
    base = step_function(model)  # step(x, u, un, p, w)
    n_p, n_w = len(system.parameters), base.size1_in(4)
    x, u, q = ca.MX.sym("x", model.n_x), ca.MX.sym("u", config.n_u), ca.MX.sym("q", n_p + n_w)
    p, w = q[:n_p], q[n_p:]
    mean = ca.DM(model.u_mean.detach().double().tolist())
    std = ca.DM(model.u_std.detach().double().tolist())
    x_next, y_next = base(x, u, (u - mean) / std, p, w)  # the input normalised as the exported model does
    step = ca.Function("hybrid_step", [x, u, q], [x_next, y_next], ["x", "u", "p"], ["x_next", "y_next"])
    y0 = ca.MX.sym("y0", config.n_y)
    init = ca.Function("init", [y0, u, q], [system.init_state(y0, u, p)], ["y0", "u0", "p"], ["x0"])
    return lm_estimator(init, step, config.init_window, y_scale=model.y_std.detach().double().numpy(),
                        x_scale=system.state_scales or None, iterations=ITERATIONS)


def estimate_state(model, yn_win: torch.Tensor, un_win: torch.Tensor) -> torch.Tensor:
    """The estimated state at each window's newest sample, (B, n_x) in physical units, in ``yn_win``'s dtype.

    ``yn_win`` (B, N, n_y) and ``un_win`` (B, N, n_u): the window in normalised units, oldest first, ``y0`` and
    ``u0`` last (``u0`` is not used: the inputs act between samples). No gradient flows through the result.
    """
    batch, n = yn_win.shape[0], yn_win.shape[1]
    with torch.no_grad():
        y = model.denormalise_y(yn_win).double().cpu().numpy()
        u = model._denormalise_u(un_win[:, :-1]).double().cpu().numpy()
        q = torch.cat([model.physics_parameters().double(), weight_vector(model).double()]).cpu().numpy()
        fallback = model.init_norm(yn_win[:, -1], un_win[:, -1])
    mapped = estimator(model).map("estimate_batch", "serial", batch, [2], [])
    x_end, _, cost = mapped(y.transpose(2, 0, 1).reshape(y.shape[2], batch * n),
                            u.transpose(2, 0, 1).reshape(u.shape[2], batch * (n - 1)), q)
    x_end, cost = np.asarray(x_end).T, np.asarray(cost).ravel()
    x0 = torch.as_tensor(x_end, dtype=yn_win.dtype, device=yn_win.device)
    # finite as the FMU tests it (a sum of magnitudes, which NaN fails), else the init rule
    finite = (np.abs(x_end).sum(axis=1) <= FINITE_LIMIT) & (np.abs(cost) <= FINITE_LIMIT)
    finite = torch.as_tensor(finite, device=yn_win.device)
    return torch.where(finite[:, None], x0, fallback.detach())
