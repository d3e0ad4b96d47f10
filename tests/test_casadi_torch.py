"""sx_to_torch: a CasADi SX Function evaluated in torch equals CasADi, in values and in gradients.

Values are compared with CasADi's own evaluation and gradients with CasADi's
``jacobian()`` Function, in float64 to 1e-12, on random points away from kinks,
for a function exercising every supported operation and for the real physics
(valve ODE, valve RK4 step and free run, arm ODE). At kinks and across
``if_else`` the default "casadi" gradient mode reproduces CasADi's conventions
exactly. Shapes, dtypes and errors: test_casadi_torch_api.py.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
import torch

from nnfmu.hybrid import GRADIENT_MODES, SUPPORTED_OPS, TorchFunction, sx_to_torch
from nnfmu.hybrid._sx_source import OP_NAMES
from physics_sim import simulate_states

RTOL = 1e-12
BATCH = 32


def _all_ops_function() -> ca.Function:
    """One output entry per operation; inputs a, b in (0.1, 0.9) and c, d in (-2, 2) keep every op defined."""
    x = ca.SX.sym("x", 4)
    a, b, c, d = (x[i] for i in range(4))
    branch = ca.if_else(c < d, ca.sin(c) * d, ca.exp(d) / b)  # both branches occur in a random batch
    entries = [
        a + c, a - c, a * c, c / b, -c, a**c, a**2.7, ca.sqrt(a), c**2, 2 * c, 1 / c,
        ca.exp(c), ca.log(a), ca.log1p(a), ca.expm1(c), ca.sin(c), ca.cos(c), ca.tan(a),
        ca.asin(a), ca.acos(b), ca.atan(c), ca.atan2(c, d), ca.sinh(c), ca.cosh(c), ca.tanh(c),
        ca.asinh(c), ca.acosh(1 + a), ca.atanh(a - 0.5), ca.erf(c),
        ca.fabs(c), ca.sign(c), ca.fmin(c, d), ca.fmax(c, d), ca.floor(3 * c), ca.ceil(3 * c),
        ca.fmod(c, b), ca.hypot(c, d), ca.copysign(a, c),
        c < d, c <= d, ca.floor(3 * a) == ca.floor(3 * b), ca.floor(3 * a) != ca.floor(3 * b),
        ca.logic_not(c < d), ca.logic_and(c < d, a < b), ca.logic_or(c < d, a < b),
        branch, branch * ca.if_else(a < b, c, 0.5) + 3.25,
        ca.sin(a * c) * ca.exp(-(d**2)) / (1 + b),  # a chain, so gradients pass several ops
    ]
    return ca.Function("all_ops", [x[:2], x[2:]], [ca.vertcat(*entries), a * d], ["ab", "cd"], ["y", "z"])


def _random_all_ops_inputs(rng) -> list[np.ndarray]:
    return [rng.uniform(0.1, 0.9, (BATCH, 2)), rng.uniform(-2.0, 2.0, (BATCH, 2))]


def _valve_inputs(rng, system) -> list[np.ndarray]:
    """States around the operating range (plunger also slightly inside the end stops), voltages, parameters +-10 %."""
    low = [0.0, -0.5, 0.0, -0.5, 1.2e5, -2e-6, -0.5]
    high = [1.2e-4, 0.5, 1.2e-4, 0.5, 6.8e5, 1.002e-3, 0.5]
    x = rng.uniform(low, high, (BATCH, 7))
    u = rng.uniform(0.0, 250.0, (BATCH, 2))
    p = system.parameter_values() * rng.uniform(0.9, 1.1, (BATCH, system.parameter_values().size))
    return [x, u, p]


def _casadi_values(fn: ca.Function, inputs: list[np.ndarray]) -> list[np.ndarray]:
    """Outputs of ``fn`` on each row, evaluated by CasADi: one (B, numel_out) array per port."""
    mapped = fn.map(inputs[0].shape[0])
    outputs = mapped.call([a.T for a in inputs])
    return [np.array(o).T for o in outputs]


def _casadi_jacobians(fn: ca.Function, inputs: list[np.ndarray]) -> dict:
    """``{(out, in): (B, numel_out, numel_in)}`` from CasADi's ``jacobian()`` Function, row by row."""
    jac = fn.jacobian()
    result = {}
    for row in range(inputs[0].shape[0]):
        args = {n: a[row] for n, a in zip(fn.name_in(), inputs)}
        args.update({f"out_{n}": np.zeros(fn.numel_out(j)) for j, n in enumerate(fn.name_out())})
        blocks = jac.call(args)
        for j, out in enumerate(fn.name_out()):
            for i, name in enumerate(fn.name_in()):
                block = np.array(ca.densify(blocks[f"jac_{out}_{name}"]))
                result.setdefault((j, i), np.zeros((len(inputs[0]), fn.numel_out(j), fn.numel_in(i))))[row] = block
    return result


def _torch_jacobians(tf: TorchFunction, inputs: list[np.ndarray]) -> dict:
    """Per-row Jacobians by reverse mode: one backward pass per output entry (rows are independent)."""
    tensors = [torch.tensor(a, requires_grad=True) for a in inputs]
    outputs = tf(*tensors)
    result = {}
    for j, out in enumerate(outputs):
        for k in range(out.shape[-1]):
            grads = torch.autograd.grad(out[:, k].sum(), tensors, retain_graph=True, allow_unused=True)
            for i, g in enumerate(grads):
                block = result.setdefault((j, i), np.zeros((len(inputs[0]), out.shape[-1], tensors[i].shape[-1])))
                block[:, k, :] = 0.0 if g is None else g.numpy()
    return result


def _assert_values_close(actual: np.ndarray, expected: np.ndarray, what: str) -> None:
    """(B, n) arrays agree to RTOL relative, with a floor of RTOL times the entry's largest value over the batch."""
    floor = RTOL * np.max(np.abs(expected), axis=0, keepdims=True)
    np.testing.assert_array_less(np.abs(actual - expected), RTOL * np.abs(expected) + floor + 1e-300, err_msg=what)


def _assert_jacobians_close(actual: np.ndarray, expected: np.ndarray, input_scale: np.ndarray, what: str) -> None:
    """(B, n_out, n_in) Jacobians agree to RTOL relative, with a floor for entries that are small through cancellation.

    The floor of entry (k, j) is RTOL times the largest change of output k caused by moving any
    input j' by its scale s_j', converted back to a move of input j: ``RTOL * max_j' |J_kj'| s_j' / s_j``.
    It is what rounding allows in a derivative made of terms of that size; a block of mixed units
    (Pa beside metres) cannot hide an error behind its largest entry.
    """
    s = np.where(input_scale > 0, input_scale, 1.0)
    row_size = np.max(np.abs(expected) * s, axis=2, keepdims=True)
    floor = RTOL * row_size / s
    np.testing.assert_array_less(np.abs(actual - expected), RTOL * np.abs(expected) + floor + 1e-300, err_msg=what)


def _check_values_and_gradients(fn: ca.Function, inputs: list[np.ndarray], gradients: str) -> None:
    tf = sx_to_torch(fn, gradients=gradients)
    with torch.no_grad():
        values = tf(*(torch.tensor(a) for a in inputs))
    for j, (got, want) in enumerate(zip(values, _casadi_values(fn, inputs))):
        assert got.dtype == torch.float64 and got.shape == want.shape
        _assert_values_close(got.numpy(), want, f"{fn.name()} output {fn.name_out(j)}")
    expected = _casadi_jacobians(fn, inputs)
    for (j, i), got in _torch_jacobians(tf, inputs).items():
        scale = np.max(np.abs(inputs[i]), axis=0)
        _assert_jacobians_close(got, expected[(j, i)], scale, f"{fn.name()} d {fn.name_out(j)} / d {fn.name_in(i)}")


def test_every_supported_operation_is_exercised():
    fn = _all_ops_function()
    used = {OP_NAMES[fn.instruction_id(k)] for k in range(fn.n_instructions())}
    assert SUPPORTED_OPS - used == {"OP_PRINTME"}  # it prints at each CasADi evaluation: tested on its own


@pytest.mark.parametrize("gradients", GRADIENT_MODES)
def test_all_operations_match_casadi(gradients):
    rng = np.random.default_rng(0)
    inputs = _random_all_ops_inputs(rng)
    c, d = inputs[1][:, 0], inputs[1][:, 1]
    assert 0 < np.sum(c < d) < BATCH, "both if_else branches must be taken somewhere in the batch"
    _check_values_and_gradients(_all_ops_function(), inputs, gradients)


def test_valve_ode_matches_casadi():
    """Default gradients only: plain autograd gives NaN here, from sqrt(fmax(., 0)) in an if_else branch not taken."""
    from nnfmu.physics import valve_system

    system = valve_system()
    _check_values_and_gradients(system.ode, _valve_inputs(np.random.default_rng(1), system), "casadi")


def test_valve_rk4_step_matches_casadi():
    """The discretised step (4 RK4 sub-steps, ~16 ODE evaluations): what a hybrid trains through."""
    from nnfmu.physics import valve_system

    system = valve_system()
    inputs = _valve_inputs(np.random.default_rng(2), system)
    _check_values_and_gradients(system.model().step, [a[:8] for a in inputs], "casadi")


def test_arm_ode_matches_casadi():
    """The robot's ~4k-instruction ODE (RNEA, mass matrix, symbolic solve, friction, counterbalance)."""
    from nnfmu.physics import arm_system

    system = arm_system()
    rng = np.random.default_rng(11)
    n = 6  # rows: the Jacobian loop costs one backward pass per output entry
    q = rng.uniform(-1.0, 1.0, (n, 6)) + np.array([0.0, -1.2, 1.0, 0.0, 0.0, 0.0])
    inputs = [np.hstack([q, rng.uniform(-0.5, 0.5, (n, 6))]), rng.uniform(-20.0, 20.0, (n, 6)),
              system.parameter_values() * rng.uniform(0.9, 1.1, (n, len(system.parameters)))]
    _check_values_and_gradients(system.ode, inputs, "casadi")


def test_valve_free_run_matches_casadi_simulation():
    """60 steps of the translated RK4 step, fed its own state, stay on CasADi's free run (tests/physics_sim.py)."""
    from nnfmu.physics import valve_system

    system = valve_system()
    step = sx_to_torch(system.model().step)
    u = np.random.default_rng(3).uniform(0.0, 250.0, (60, 2))
    x0 = np.array([20e-6, 0.0, 10e-6, 0.0, 3.0e5, 0.5e-3, 0.0])
    expected = simulate_states(system, x0, u)
    x, p = torch.tensor(x0), torch.tensor(system.parameter_values())
    states = []
    with torch.no_grad():
        for k in range(len(u)):
            x, _ = step(x, torch.tensor(u[k]), p)
            states.append(x.numpy())
    _assert_values_close(np.array(states), expected[1:], "valve free run")


def _kink_function(*, masked_nan_branches: bool) -> ca.Function:
    x = ca.SX.sym("x", 2)
    a, b = x[0], x[1]
    entries = [
        ca.fmin(a, b), ca.fmax(a, 0), ca.fabs(a), ca.sign(a), ca.floor(a),
        ca.if_else(a <= 0, b**2, 3 * b),  # on the switching boundary
    ]
    if masked_nan_branches:
        entries += [ca.if_else(a < 1, a, ca.sqrt(a - 1)), ca.if_else(a > -1, a * b, ca.log(a))]
    return ca.Function("kinks", [x], [ca.vertcat(*entries)], ["x"], ["y"])


@pytest.mark.parametrize("gradients", GRADIENT_MODES)
def test_gradients_follow_casadi_at_kinks(gradients):
    """Both modes split fmin/fmax ties evenly like CasADi; only "casadi" also stays finite when
    the if_else branch not taken is NaN (plain autograd multiplies its zero cotangent by inf)."""
    fn, point = _kink_function(masked_nan_branches=gradients == "casadi"), np.zeros((1, 2))
    got = _torch_jacobians(sx_to_torch(fn, gradients=gradients), [point])[(0, 0)][0]
    expected = _casadi_jacobians(fn, [point])[(0, 0)][0]
    np.testing.assert_array_equal(got, expected)
    assert np.all(np.isfinite(got))
    np.testing.assert_array_equal(got[:2], [[0.5, 0.5], [0.5, 0.0]])


@pytest.mark.parametrize("gradients", GRADIENT_MODES)
def test_gradcheck_and_gradgradcheck(gradients):
    x, p = ca.SX.sym("x", 3), ca.SX.sym("p", 2)
    y = ca.vertcat(
        ca.sin(x[0]) * p[0] + x[1] * ca.exp(-x[2] * p[1]),
        ca.if_else(x[0] < x[1], x[2] ** 3, ca.tanh(x[2] * p[0])),
        ca.atan2(x[1], x[2]) / (1 + p[1] ** 2),
    )
    tf = sx_to_torch(ca.Function("small", [x, p], [y], ["x", "p"], ["y"]), gradients=gradients)
    generator = torch.Generator().manual_seed(0)
    xs = torch.randn(6, 3, dtype=torch.float64, generator=generator, requires_grad=True)
    ps = torch.randn(2, dtype=torch.float64, generator=generator, requires_grad=True)  # broadcast over the batch
    assert torch.autograd.gradcheck(tf, (xs, ps))
    assert torch.autograd.gradgradcheck(tf, (xs, ps))


def test_only_inputs_that_require_grad_get_gradients():
    from nnfmu.physics import valve_system

    system = valve_system()
    x, u, p = (torch.tensor(a) for a in _valve_inputs(np.random.default_rng(6), system))
    x_all, u_all, p_all = (t.clone().requires_grad_() for t in (x, u, p))
    sx_to_torch(system.ode)(x_all, u_all, p_all)[0].sum().backward()
    x_only = x.clone().requires_grad_()
    sx_to_torch(system.ode)(x_only, u, p)[0].sum().backward()
    assert u.grad is None and p.grad is None
    torch.testing.assert_close(x_only.grad, x_all.grad, rtol=0.0, atol=0.0)
