"""sx_to_torch as an API: batch shapes, names, dtypes, matrix and sparse ports, pickling, and clear errors.

The numerical equivalence with CasADi (values and gradients, every operation, the
physics models) is tested in test_casadi_torch.py.
"""

from __future__ import annotations

import pickle

import casadi as ca
import numpy as np
import pytest
import torch

from nnfmu.errors import ConfigError, ExportError, ShapeError
from nnfmu.hybrid import sx_to_torch

RTOL = 1e-12


def _small_function() -> ca.Function:
    x, p = ca.SX.sym("x", 3), ca.SX.sym("p", 2)
    y = ca.vertcat(x[0] * p[0], ca.sin(x[1] + p[1]))
    return ca.Function("small", [x, p], [y, x[2] ** 2], ["x", "p"], ["y", "z"])


def test_batch_shapes_broadcast_and_names():
    tf = sx_to_torch(_small_function())
    x = torch.tensor(np.random.default_rng(4).normal(size=(2, 5, 3)))
    p = torch.tensor([1.5, -0.5], dtype=torch.float64)
    y, z = tf(x, p)
    assert y.shape == (2, 5, 2) and z.shape == (2, 5, 1)
    y_row, z_row = tf(x[1, 3], p)  # no batch dimension at all
    assert y_row.shape == (2,) and torch.equal(y_row, y[1, 3]) and torch.equal(z_row, z[1, 3])
    y_named, _ = tf(p=p, x=x)
    assert torch.equal(y_named, y)
    assert tf.name_in == ("x", "p") and tf.name_out == ("y", "z") and tf.numel_in == (3, 2)


def test_broadcast_parameter_gradient_sums_over_the_batch():
    tf = sx_to_torch(_small_function())
    x = torch.tensor(np.random.default_rng(5).normal(size=(4, 3)))
    p = torch.tensor([1.5, -0.5], dtype=torch.float64, requires_grad=True)
    tf(x, p)[0].sum().backward()
    per_row = []
    for row in x:
        q = p.detach().clone().requires_grad_()
        tf(row, q)[0].sum().backward()
        per_row.append(q.grad)
    torch.testing.assert_close(p.grad, torch.stack(per_row).sum(0), rtol=RTOL, atol=0.0)


def test_output_dtype_follows_the_inputs():
    tf = sx_to_torch(_small_function())
    x = torch.tensor(np.random.default_rng(7).normal(size=(4, 3)))
    p = torch.tensor([1.1, -0.7], dtype=torch.float64)
    y64, _ = tf(x, p)
    y32, _ = tf(x.float(), p.float())
    assert y32.dtype == torch.float32
    torch.testing.assert_close(y32, y64.float(), rtol=1e-6, atol=1e-6)
    y_int, _ = tf(torch.ones(4, 3, dtype=torch.int64), p.float())
    assert y_int.dtype == torch.float32  # integers take the floating inputs' dtype
    y_lists, _ = tf(x.tolist(), [1.1, -0.7])  # Python numbers: float64, no digit lost
    assert y_lists.dtype == torch.float64 and torch.equal(y_lists, y64)


def test_matrix_sparse_and_constant_outputs_are_dense_column_major():
    A, v = ca.SX.sym("A", 2, 2), ca.SX.sym("v", 2)
    jac = ca.jacobian(ca.vertcat(ca.sin(v[0]), v[1] * A[0, 1]), v)  # structural zero at (0, 1)
    constant = ca.sparsify(ca.SX(ca.DM([[1.5, 0.0], [0.0, -2.0]])))  # constants, zeros off the diagonal
    fn = ca.Function("ports", [A, v], [A.T @ v, jac, constant, ca.SX(2, 1)], ["A", "v"], ["Atv", "jac", "c", "zero"])
    rng = np.random.default_rng(8)
    a_rows, v_rows = rng.normal(size=(3, 4)), rng.normal(size=(3, 2))
    outputs = sx_to_torch(fn)(torch.tensor(a_rows), torch.tensor(v_rows))
    for row in range(3):
        expected = fn(a_rows[row].reshape(2, 2, order="F"), v_rows[row])
        for got, want in zip(outputs, expected):
            np.testing.assert_allclose(got[row].numpy(), np.array(ca.densify(want)).ravel(order="F"), rtol=RTOL, atol=0)


def test_mx_function_is_expanded_to_sx():
    m = ca.MX.sym("m", 3)
    fn = ca.Function("mx", [m], [ca.sin(m) * ca.sumsqr(m)], ["m"], ["y"])
    rows = np.random.default_rng(9).normal(size=(4, 3))
    (got,) = sx_to_torch(fn)(torch.tensor(rows))
    expected = np.array([np.array(fn(row)).ravel() for row in rows])
    np.testing.assert_allclose(got.numpy(), expected, rtol=RTOL, atol=0)


def test_printme_passes_its_value_through():
    x = ca.SX.sym("x")
    fn = ca.Function("printing", [x], [ca.sin(x).printme(0) * 2], ["x"], ["y"])
    (got,) = sx_to_torch(fn)(torch.tensor([[0.3], [0.7]], dtype=torch.float64))
    torch.testing.assert_close(got, 2 * torch.sin(torch.tensor([[0.3], [0.7]], dtype=torch.float64)), rtol=RTOL, atol=0)


def test_pickled_function_evaluates_the_same():
    tf = sx_to_torch(_small_function())
    x, p = torch.tensor(np.random.default_rng(10).normal(size=(4, 3))), torch.tensor([1.5, -0.5], dtype=torch.float64)
    clone = pickle.loads(pickle.dumps(tf))
    for got, want in zip(clone(x, p), tf(x, p)):
        assert torch.equal(got, want)


def _function_calling_another():
    x = ca.SX.sym("x")
    inner = ca.Function("inner", [x], [ca.sin(x)], {"never_inline": True})
    return ca.Function("outer", [x], [inner(x) * 2])


def _function_with_free_variable():
    x, q = ca.SX.sym("x"), ca.SX.sym("q")
    return ca.Function("free", [x], [x * q], {"allow_free": True})


def _mx_function_with_linear_solver():
    A, b = ca.MX.sym("A", 2, 2), ca.MX.sym("b", 2)
    return ca.Function("linsol", [A, b], [ca.solve(A, b, "qr")])


def _erfinv_function():
    x = ca.SX.sym("x")
    return ca.Function("inverse_erf", [x], [ca.erfinv(x)])


@pytest.mark.parametrize(
    "build, match",
    [
        (_erfinv_function, "OP_ERFINV.*approximation"),
        (_function_calling_another, "OP_CALL.*never_inline"),
        (_function_with_free_variable, r"free variables \['q'\]"),
        (_mx_function_with_linear_solver, "cannot be expanded to SX"),
        (lambda: "not a function", "expected a casadi.Function, got str"),
    ],
)
def test_untranslatable_functions_raise_export_error(build, match):
    with pytest.raises(ExportError, match=match):
        sx_to_torch(build())


@pytest.mark.parametrize(
    "args, kwargs, match",
    [
        ((torch.zeros(4, 2), torch.zeros(2)), {}, r"input 'x' has shape \(4, 2\), expected \(\.\.\., 3\)"),
        ((torch.zeros(4, 3),), {}, r"expected 2 inputs \['x', 'p'\], got 1"),
        ((torch.zeros(4, 3), torch.zeros(5, 2)), {}, "do not broadcast"),
        ((), {"x": torch.zeros(3), "q": torch.zeros(2)}, r"unknown names \['q'\]"),
        ((), {"x": torch.zeros(3)}, r"missing input\(s\) \['p'\]"),
    ],
)
def test_bad_calls_raise_shape_errors(args, kwargs, match):
    with pytest.raises(ShapeError, match=match):
        sx_to_torch(_small_function())(*args, **kwargs)


def test_unknown_gradient_mode_lists_the_valid_ones():
    with pytest.raises(ConfigError, match="valid modes are: casadi, autograd"):
        sx_to_torch(_small_function(), gradients="numeric")
