"""Issue 34, item 1: which estimator of the initial state goes into the FMU, measured.

On data generated from a physics model (the two tanks of examples/two_tanks.py, the upper level not
measured; the viscous slider of examples/slider_viscous.py, its velocity not measured), with and without
measurement noise, the state at t0 is estimated from the init window of the N samples up to t0 by

- ``rule``: the model's init rule from the sample at t0 alone (what the FMU did without a window);
- ``lm K``: the unrolled Levenberg-Marquardt fit of the window's start state, K steps (the FMU's,
  :mod:`nnfmu.physics.initial_state`);
- ``ekf``: an extended Kalman filter over the window, from the init rule at its oldest sample
  (``P0 = diag(state scales)^2``, ``Q = (1e-3 scale)^2`` per sample, ``R = max(noise, 1e-4)^2 std(y)^2``),

at every 40th sample of the test records (true states from the noise-free run of the same inputs), and
prints the median and the 90th percentile of each state's error relative to its scale, the RMSE of the
free run over the 200 samples after t0 against the noise-free outputs (relative to std(y)), and the
process CPU time per estimate (CasADi's virtual machine). Not part of the test run.

    python benchmarks/initial_state.py                 # both models, windows 10 20 50, noise 0 and 0.01
    python benchmarks/initial_state.py --windows 20 --noise 0.01
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import casadi as ca
import numpy as np

from nnfmu.physics import generate_model_dataset, resolve_physics, rk4_function
from nnfmu.physics.initial_state import estimating_model

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
MODELS = {"two_tanks": f"{EXAMPLES / 'two_tanks.py'}:two_tanks",
          "slider": f"{EXAMPLES / 'slider_viscous.py'}:slider_viscous"}
HORIZON, EVERY = 200, 40


def simulate_states(system, x0, u) -> np.ndarray:
    """States of the RK4 free run from ``x0`` (n_x,) under ``u`` (n, n_u): (n + 1, n_x)."""
    step = rk4_function(system.ode, Ts=system.Ts, n_sub=system.n_sub)
    p = np.repeat(system.parameter_values()[:, None], len(u), axis=1)
    return np.vstack([np.asarray(x0, float)[None], np.asarray(step.mapaccum("sim", len(u))(x0, u.T, p)).T])


def ekf_function(system):
    """``(x, P, u, y_next, p, Q, R) -> (x_next, P_next)``: one predict and update step of the EKF."""
    model = system.model(expose_parameters=True)
    n_x, n_y = model.n_x, system.outputs.__len__()
    x, P = ca.SX.sym("x", n_x), ca.SX.sym("P", n_x, n_x)
    u, y, p = ca.SX.sym("u", len(system.inputs)), ca.SX.sym("y", n_y), ca.SX.sym("p", len(system.parameters))
    Q, R = ca.SX.sym("Q", n_x, n_x), ca.SX.sym("R", n_y, n_y)
    x_pred, _ = model.step(x, u, p)
    F = ca.jacobian(x_pred, x)
    P_pred = F @ P @ F.T + Q
    xs = ca.SX.sym("xs", n_x)
    y_pred = system.output(x_pred, p)
    H = ca.substitute(ca.jacobian(system.output(xs, p), xs), xs, x_pred)
    S = H @ P_pred @ H.T + R
    K = ca.mtimes(P_pred @ H.T, ca.inv(S))
    x_new = x_pred + K @ (y - y_pred)
    P_new = (ca.SX.eye(n_x) - K @ H) @ P_pred
    return ca.Function("ekf", [x, P, u, y, p, Q, R], [x_new, 0.5 * (P_new + P_new.T)])


def run_ekf(system, ekf, y_win, u_win, p, noise, y_std):
    scale = np.asarray(system.state_scales or np.ones(system.n_x))
    x = np.asarray(system.init_state(y_win[0], u_win[0], p)).ravel()
    P, Q = np.diag(scale ** 2), np.diag((1e-3 * scale) ** 2)
    R = np.diag((max(noise, 1e-4) * y_std) ** 2)
    for j in range(len(u_win)):
        x, P = ekf(x, P, u_win[j], y_win[j + 1], p, Q, R)
    return np.asarray(x).ravel()


def cases(system, clean, noisy, window):
    """(u, y_noisy, y_clean, x_true, k) at every EVERY-th t0 of the test records."""
    for u, y, y0 in zip(noisy.test.u, noisy.test.y, clean.test.y):
        x = simulate_states(system, np.asarray(system.init_state(y0[0], u[0], system.parameter_values())).ravel(),
                            u[:-1])
        for k in range(window - 1, len(u) - HORIZON, EVERY):
            yield u, y, y0, x, k


def measure(name, window, noise, iterations):
    system = resolve_physics(MODELS[name])
    clean, noisy = (generate_model_dataset(system, size="small", noise=n, seed=1) for n in (0.0, noise))
    y_std = np.concatenate(clean.train.y).std(axis=0)
    p = system.parameter_values()
    plain = system.model(expose_parameters=True)
    lms = {K: estimating_model(system, init_window=window, y_scale=y_std, iterations=K) for K in iterations}
    ekf = ekf_function(system)
    scale = np.asarray(system.state_scales or np.ones(system.n_x))
    rows = {}

    def record(method, x_hat, x_true, u, y_clean, k, seconds):
        sim = simulate_states(system, x_hat, u[k:k + HORIZON - 1])
        y_hat = np.vstack([np.asarray(system.output(s, p)).ravel() for s in sim])
        err = np.sqrt(np.mean(((y_hat - y_clean[k:k + HORIZON]) / y_std) ** 2))
        rows.setdefault(method, []).append((np.abs(x_hat - x_true[k]) / scale, err, seconds))

    for u, y, y_clean, x, k in cases(system, clean, noisy, window):
        y_past, u_past = y[k - window + 1:k], u[k - window + 1:k]
        t = time.process_time()
        x_rule = np.asarray(plain.init(y[k], u[k], p)).ravel()
        record("rule", x_rule, x, u, y_clean, k, time.process_time() - t)
        for K, model in lms.items():
            t = time.process_time()
            x_lm = np.asarray(model.init(y[k], u[k], p, y_past.ravel(), u_past.ravel())).ravel()
            record(f"lm {K}", x_lm, x, u, y_clean, k, time.process_time() - t)
        t = time.process_time()
        x_ekf = run_ekf(system, ekf, y[k - window + 1:k + 1], u[k - window + 1:k], p, noise, y_std)
        record("ekf", x_ekf, x, u, y_clean, k, time.process_time() - t)
    states = [v.name for v in system.states]
    print(f"\n{name}, window {window}, noise {noise:g}: {len(rows['rule'])} estimates; state errors / scale "
          f"(median, 90 %), free-run RMSE / std(y) over {HORIZON} samples (median, 90 %), ms per estimate")
    for method, values in rows.items():
        errs = np.array([v[0] for v in values])
        runs = np.array([v[1] for v in values])
        cells = "  ".join(f"{s} {np.median(errs[:, i]):.2e} {np.quantile(errs[:, i], 0.9):.2e}"
                          for i, s in enumerate(states))
        ms = 1e3 * np.mean([v[2] for v in values])
        print(f"  {method:<6} {cells}  run {np.median(runs):.2e} {np.quantile(runs, 0.9):.2e}  {ms:.2f} ms")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", nargs="+", default=list(MODELS), choices=list(MODELS))
    parser.add_argument("--windows", nargs="+", type=int, default=[10, 20, 50])
    parser.add_argument("--noise", nargs="+", type=float, default=[0.0, 0.01])
    parser.add_argument("--iterations", nargs="+", type=int, default=[5, 10, 20])
    args = parser.parse_args()
    for name in args.models:
        for noise in args.noise:
            for window in args.windows:
                measure(name, window, noise, args.iterations)


if __name__ == "__main__":
    main()
