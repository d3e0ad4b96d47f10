"""The quasi-Newton refinement: its adjoint gradient is the exact gradient, and it refines as Gauss-Newton does.

The gradient of the free-run cost by the adjoint pass (nnfmu/linear/adjoint.py) must equal
``J^T r`` from the forward sensitivities that the Gauss-Newton refinement accumulates
(nnfmu/linear/refine.py), in float64, for every initial-state rule.
"""

from __future__ import annotations

import numpy as np
import pytest

from nnfmu.linear import StateSpace, refine
from nnfmu.linear.adjoint import OutputError
from nnfmu.linear.refine import _Problem


def _system(seed: int, n: int = 3, n_u: int = 2, n_y: int = 2) -> StateSpace:
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n, n))
    A *= 0.8 / np.max(np.abs(np.linalg.eigvals(A)))
    return StateSpace(A, rng.normal(size=(n, n_u)), 0.1 * rng.normal(size=n), rng.normal(size=(n_y, n)),
                      0.1 * rng.normal(size=n_y))


def _data(truth: StateSpace, seed: int, lengths=(40, 70, 55)):
    """Normalised trajectories of ``truth`` from random initial states, with output noise."""
    rng = np.random.default_rng(seed)
    us, ys = [], []
    for n_steps in lengths:
        u = rng.normal(size=(n_steps, truth.B.shape[1]))
        x, y = rng.normal(size=truth.n_x), np.empty((n_steps, truth.C.shape[0]))
        for k in range(n_steps):
            y[k] = truth.C @ x + truth.d + 0.05 * rng.normal(size=len(truth.d))
            x = truth.A @ x + truth.B @ u[k] + truth.b
        us.append(u)
        ys.append(y)
    return us, ys


def _perturbed(sys: StateSpace, seed: int) -> StateSpace:
    rng = np.random.default_rng(seed)
    return StateSpace(sys.A + 0.05 * rng.normal(size=sys.A.shape), sys.B + 0.1 * rng.normal(size=sys.B.shape),
                      sys.b, sys.C + 0.1 * rng.normal(size=sys.C.shape), sys.d)


@pytest.mark.parametrize("init, x0, rtol", [("zero-offset", "rule", 1e-10), ("estimate", "fit", 1e-9),
                                            ("estimate", "rule", 1e-6)])  # the last: J's x0 part by differences
def test_adjoint_gradient_equals_the_forward_sensitivity_gradient(init, x0, rtol):
    truth = _system(0)
    us, ys = _data(truth, 1)
    problem = _Problem(_perturbed(truth, 2), us, ys, init, x0, 0.9999)
    beta = 0.01 * np.random.default_rng(3).normal(size=problem.n_dir)
    sys = problem.system(beta)
    wanted = problem._gram(sys, beta)[:-1, -1]  # J^T r
    error = OutputError(problem.u, problem.y, problem.mask, init)
    run = error.run(sys, problem._fitted_x0(sys) if x0 == "fit" else problem._rule_x0(sys))
    g = error.gradient(sys, run, rule_x0=x0 == "rule")
    full = np.concatenate([g["A"].ravel(), g["B"].ravel(), g["C"].ravel()] + ([g["b"]] if init == "estimate" else []))
    got = problem.basis.T @ full
    assert np.abs(wanted).max() > 1e-3
    np.testing.assert_allclose(got, wanted, rtol=0, atol=rtol * np.abs(wanted).max())


@pytest.mark.parametrize("init", ["estimate", "zero-offset"])
def test_quasi_newton_reaches_the_gauss_newton_minimum(init):
    truth = _system(4)
    us, ys = _data(truth, 5, lengths=(80, 120, 100, 90))
    start = _perturbed(truth, 6)
    options = dict(init=init, x0="rule", max_radius=0.9999)
    reached = {m: refine(start, us, ys, method=m, max_evaluations=n, **options)
               for m, n in (("quasi-newton", 400), ("gauss-newton", 60))}
    qn, gn = reached["quasi-newton"], reached["gauss-newton"]
    assert qn.cost_after < 0.2 * qn.cost_before
    assert qn.cost_after == pytest.approx(gn.cost_after, rel=1e-4)
    assert qn.system.spectral_radius < 0.9999


def test_an_unknown_method_is_refused_with_the_valid_ones():
    from nnfmu.errors import ConfigError
    from nnfmu.linear import LinearConfig

    with pytest.raises(ConfigError, match="quasi-newton, gauss-newton"):
        LinearConfig(refine_method="newton")
