"""The physics in torch: compiled C (and the SX translation) equal CasADi in values and gradients, 1e-12.

Both backends of :func:`nnfmu.hybrid.casadi_to_torch` are compared with CasADi's own
evaluation and with its ``jacobian()`` Function, in float64, on the real physics (valve
ODE, valve RK4 step, arm ODE) with a parameter vector shared by the batch, as a hybrid
model calls them. The compiled backend's API (broadcasting, dtypes, errors) is tested here
too; the SX translation's own API is tested in test_casadi_torch_api.py.
"""

from __future__ import annotations

import copy

import casadi as ca
import numpy as np
import pytest
import torch

from nnfmu.errors import ConfigError, ExportError, ShapeError
from nnfmu.hybrid import BACKENDS, CompiledFunction, TorchFunction, casadi_to_torch, compiled_to_torch, physics_system
from nnfmu.hybrid.model import physics_step

RTOL = 1e-12


def _valve_point(rng, n: int) -> list[np.ndarray]:
    """States over the operating range (plunger also inside the end stops), voltages, one parameter vector."""
    system = physics_system("valve")
    x = rng.uniform([0.0, -0.5, 0.0, -0.5, 1.2e5, -2e-6, -0.5], [1.2e-4, 0.5, 1.2e-4, 0.5, 6.8e5, 1.002e-3, 0.5],
                    (n, 7))
    return [x, rng.uniform(0.0, 250.0, (n, 2)), system.parameter_values() * rng.uniform(0.8, 1.2, 29)]


def _arm_point(rng, n: int) -> list[np.ndarray]:
    system = physics_system("arm")
    q = rng.uniform(-1.0, 1.0, (n, 6)) + np.array([0.0, -1.2, 1.0, 0.0, 0.0, 0.0])
    x = np.hstack([q, rng.uniform(-0.5, 0.5, (n, 6))])
    return [x, rng.uniform(-20.0, 20.0, (n, 6)), system.parameter_values() * rng.uniform(0.9, 1.1, 109)]


def _casadi_rows(fn: ca.Function, inputs: list[np.ndarray]):
    """Per row: CasADi's outputs and the Jacobian blocks d out_0 / d in_i (dense)."""
    jac = fn.jacobian()
    values, blocks = [], []
    for r in range(len(inputs[0])):
        args = [a[r] if a.ndim == 2 else a for a in inputs]
        values.append(np.asarray(fn(*args)).ravel())
        out = jac(*args, np.zeros(fn.numel_out(0)))
        blocks.append([np.asarray(ca.densify(out[i])) for i in range(fn.n_in())])
    return np.array(values), blocks


def _check(fn: ca.Function, inputs: list[np.ndarray], backend: str) -> None:
    tf = casadi_to_torch(fn, backend=backend)
    tensors = [torch.tensor(a, requires_grad=True) for a in inputs]
    (out,) = tf(*tensors)
    want, blocks = _casadi_rows(fn, inputs)
    scale = np.maximum(np.abs(want).max(0), 1e-300)
    np.testing.assert_array_less(np.abs(out.detach().numpy() - want), RTOL * (np.abs(want) + scale))
    # reverse mode, one output entry at a time; the shared parameter vector gets the sum over the rows
    for k in range(out.shape[1]):
        grads = torch.autograd.grad(out[:, k].sum(), tensors, retain_graph=True)
        for i, g in enumerate(grads):
            expected = np.array([b[i][k] for b in blocks])
            if inputs[i].ndim == 1:
                expected = expected.sum(0)
            input_scale = np.maximum(np.abs(inputs[i]).reshape(-1, inputs[i].shape[-1]).max(0), 1e-30)
            floor = RTOL * np.max(np.abs(expected) * input_scale, axis=-1, keepdims=True) / input_scale
            np.testing.assert_array_less(np.abs(g.numpy() - expected), RTOL * np.abs(expected) + floor + 1e-300,
                                         err_msg=f"{fn.name()} d xdot[{k}] / d {fn.name_in(i)}")


@pytest.mark.parametrize("backend", BACKENDS)
def test_valve_ode_values_and_gradients_equal_casadi(backend):
    _check(physics_system("valve").ode, _valve_point(np.random.default_rng(0), 12), backend)


def test_valve_rk4_step_values_and_gradients_equal_casadi():
    """The discretised step with its 16 ODE evaluations: what the 'step' correction trains through."""
    system = physics_system("valve")
    _check(physics_step(system, system.Ts, system.n_sub), _valve_point(np.random.default_rng(1), 6), "compiled")


def test_arm_ode_values_and_gradients_equal_casadi():
    _check(physics_system("arm").ode, _arm_point(np.random.default_rng(2), 4), "compiled")


def test_gradcheck_with_a_shared_parameter_vector():
    """torch's finite-difference check of the compiled reverse mode, on a smooth function."""
    x, p = ca.SX.sym("x", 3), ca.SX.sym("p", 2)
    y = ca.vertcat(ca.sin(x[0]) * p[0] + x[1] * ca.exp(-x[2] * p[1]), ca.atan2(x[1], x[2]) / (1 + p[1] ** 2))
    cf = compiled_to_torch(ca.Function("smooth", [x, p], [y], ["x", "p"], ["y"]))
    generator = torch.Generator().manual_seed(0)
    xs = torch.randn(5, 3, dtype=torch.float64, generator=generator, requires_grad=True)
    ps = torch.randn(2, dtype=torch.float64, generator=generator, requires_grad=True)
    assert torch.autograd.gradcheck(cf, (xs, ps))


def test_batch_shapes_dtypes_names_and_copies():
    cf = compiled_to_torch(physics_system("valve").ode)
    x, u, p = (torch.tensor(a) for a in _valve_point(np.random.default_rng(3), 6))
    (rows,) = cf(x.reshape(2, 3, 7), u.reshape(2, 3, 2), p)
    (single,) = cf(x[4], u[4], p)
    (named,) = cf(p=p, u=u, x=x)
    assert rows.shape == (2, 3, 7) and single.shape == (7,)
    assert torch.equal(rows.reshape(6, 7), named) and torch.equal(single, named[4])
    (grid,) = cf(x[:2].reshape(2, 1, 7), u[:3], p)  # full broadcasting: states x inputs
    assert grid.shape == (2, 3, 7) and torch.equal(grid[1, 2], cf(x[1], u[2], p)[0])
    (low,) = cf(x.float(), u.float(), p.float())
    assert low.dtype == torch.float32  # computed in float64 (C), returned in the inputs' dtype
    assert copy.deepcopy(cf) is cf and cf.name_in == ("x", "u", "p") and cf.numel_out == (7,)


def test_clear_errors():
    cf = compiled_to_torch(physics_system("valve").ode)
    x, u, p = (torch.tensor(a) for a in _valve_point(np.random.default_rng(4), 3))
    with pytest.raises(ShapeError, match=r"input 'u' has shape \(3, 3\), expected \(\.\.\., 2\)"):
        cf(x, torch.zeros(3, 3, dtype=torch.float64), p)
    with pytest.raises(ShapeError, match="do not broadcast"):
        cf(x, u[:2], p)
    with pytest.raises(ShapeError, match="expected 3 inputs"):
        cf(x, u)
    with pytest.raises(ConfigError, match="unknown physics backend 'cuda'; choose one of compiled, sx"):
        casadi_to_torch(physics_system("valve").ode, backend="cuda")
    a = ca.SX.sym("a", ca.Sparsity.lower(2))
    sparse = ca.Function("sparse", [a], [ca.sum1(ca.sum2(a))])
    with pytest.raises(ExportError, match="sparse"):
        CompiledFunction(sparse)


def test_without_a_c_compiler_the_sx_translation_takes_over(monkeypatch):
    """Like nnfmu.physics.compile_function: a warning, then slower code with the same values."""
    x, p = ca.SX.sym("x", 2), ca.SX.sym("p", 1)
    fn = ca.Function("no_cc", [x, p], [ca.sin(x) * p], ["x", "p"], ["y"])  # a new Function: nothing cached
    monkeypatch.setenv("CC", "/nonexistent/cc")
    with pytest.warns(RuntimeWarning, match="no_cc runs as the SX translation.*no C compiler found"):
        tf = casadi_to_torch(fn, backend="compiled")
    assert isinstance(tf, TorchFunction)
    (y,) = tf(torch.tensor([[0.5, 1.0]], dtype=torch.float64), torch.tensor([2.0], dtype=torch.float64))
    np.testing.assert_allclose(y.numpy()[0], np.asarray(fn([0.5, 1.0], 2.0)).ravel(), rtol=1e-15)

