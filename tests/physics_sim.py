"""The tests' reference free run of a physics model: its states under RK4, in CasADi's virtual machine."""

from __future__ import annotations

import numpy as np

from nnfmu.physics import PhysicsSystem, rk4_function


def simulate_states(system: PhysicsSystem, x0, u, *, p=None, n_sub: int | None = None) -> np.ndarray:
    """States of an RK4 free run: ``x0`` (n_x,), ``u`` (N, n_u) -> x (N + 1, n_x), x[0] = x0.

    ``p``: the parameter vector (default nominal); ``n_sub``: RK4 sub-steps per sample (default the model's).
    """
    u = np.atleast_2d(np.asarray(u, dtype=float))
    assert u.shape[1] == len(system.inputs), u.shape
    p = system.parameter_values() if p is None else np.asarray(p, dtype=float)
    n_sub = system.n_sub if n_sub is None else n_sub
    step = rk4_function(system.ode, Ts=system.Ts, n_sub=n_sub, name=f"{system.name}_rk4")
    xs = step.mapaccum("sim", u.shape[0])(np.asarray(x0, float), u.T, np.repeat(p[:, None], len(u), 1))
    return np.vstack([np.asarray(x0, float)[None, :], np.asarray(xs).T])
