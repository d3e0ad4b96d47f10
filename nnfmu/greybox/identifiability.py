"""Which of a fit's parameters the data determine: correlations, weak directions and flags with a fix.

All from the Gauss-Newton information of the free parameters, ``F = J_theta^T J_theta`` less what the windows'
initial states explain (the Schur complement, :func:`parameter_information`), at the optimum. The covariance is
``sigma^2 F^-1`` (:mod:`nnfmu.greybox.fit`).

- **Correlation** of every pair: ``C_ij / sqrt(C_ii C_jj)``. Near +-1, the data see only a combination of the two.
- **Weak directions**: the eigenvectors of ``F`` in *relative* parameters ``theta_j / ref_j`` (``ref_j = |theta_j|``,
  or the parameter's typical magnitude where the estimate is near 0). The direction ``v`` (unit length) with
  eigenvalue ``lambda`` is determined to ``+-sqrt(sigma^2 / lambda)``: moving every parameter by ``t v_j`` of its
  value worsens the fit by one standard deviation only at ``t`` = that figure. A near-zero eigenvalue is a
  combination the data cannot see; its largest components name the parameters involved.
- **Flags**, each a line that names the parameters and the fix, with the fit's own options: every parameter
  whose standard error exceeds :data:`RELATIVE_LIMIT` of its value. Flagged parameters correlated beyond
  :data:`GROUP_CORRELATION` are one flag, "cannot be told apart" (fix one, or tie them in the model); one alone
  is "not determined" (fix it, or give data that excite it).

A correlation alone is not a flag. Measured on the two tanks of docs/own-physics.md (upper tank unmeasured; 16
records of 400 samples, 1 % noise): the well-posed fit of ``a1, a2, k_p`` has ``a2`` and ``k_p`` correlated at
0.9998, yet each is determined to 0.3 %; freeing the upper tank's cross-section ``A1`` beside ``a1`` (redundant:
a larger tank with a wider outlet looks the same from the lower tank) gives ``A1 +- 42 %``, ``a1 +- 21 %``,
correlated at 1.000 (on 6 of the records: 490 % and 240 %). :data:`RELATIVE_LIMIT` lies between, below the
50 % that would have missed them. On the robot (docs/own-physics.md) every joint's viscous and Coulomb
friction correlate beyond 0.995 with standard errors from 26 % to 15,000 %: six pairs.
"""

from __future__ import annotations

import numpy as np

__all__ = ["RELATIVE_LIMIT", "GROUP_CORRELATION", "STRONG_CORRELATION", "NULL_RTOL", "parameter_information",
           "covariance", "identifiability_report", "describe"]

#: A parameter (or a direction) is flagged when its standard error exceeds this fraction of its value: its 95 %
#: interval spans more than +-40 % of it.
RELATIVE_LIMIT = 0.2
#: ``describe`` lists the pairs correlated above this when there are too many parameters for the matrix.
STRONG_CORRELATION = 0.9
#: An eigenvalue of the scaled information below this fraction of the largest is a direction the data do not see.
NULL_RTOL = 1e-12
#: Flagged parameters correlated beyond this are one flag: "cannot be told apart" (fix one, or tie them).
GROUP_CORRELATION = 0.95


def parameter_information(dt: np.ndarray, dx: np.ndarray) -> np.ndarray:
    """The free parameters' Gauss-Newton information, the windows' initial states eliminated: (n_f, n_f).

    ``dt``: ``dr/dtheta`` (n_w, rows, n_f), ``dx``: ``dr/dx0_w`` (n_w, rows, n_x), in the scaled unknowns
    (:meth:`nnfmu.greybox.problem.Problem.blocks`). The Schur complement of the states' blocks in ``J^T J``.
    """
    information = np.einsum("wri,wrj->ij", dt, dt)
    for a, b in zip(dt, dx):
        coupling = a.T @ b
        information -= coupling @ np.linalg.pinv(b.T @ b) @ coupling.T
    return 0.5 * (information + information.T)


def covariance(information: np.ndarray, sigma2: float) -> tuple[np.ndarray, np.ndarray]:
    """``(covariance, null)``: ``sigma2 F^-1`` (n_f, n_f), and which parameters a null direction of ``F`` touches.

    Eigenvalues below :data:`NULL_RTOL` of the largest are raised to it, so the covariance stays finite and a
    redundant pair correlates at +-1; ``null`` (n_f,) bool marks the parameters with a component of at least
    1e-6 in such a direction, whose standard error is infinite.
    """
    w, V = np.linalg.eigh(information)
    floor = NULL_RTOL * max(float(w.max(initial=0.0)), np.finfo(float).tiny)
    cov = sigma2 * (V / np.maximum(w, floor)) @ V.T
    null = (np.abs(V[:, w <= floor]) >= 1e-6).any(axis=1)
    return cov, null


def _references(theta: np.ndarray, typical: np.ndarray) -> np.ndarray:
    """What "its value" means for a relative error: ``|theta|``, or the typical magnitude where theta is near 0."""
    return np.where(np.abs(theta) > 1e-3 * typical, np.abs(theta), typical)


def identifiability_report(names, theta, typical, information, sigma2) -> dict:
    """The identifiability section of a fit's report (JSON-safe, module docstring).

    Parameters
    ----------
    names : sequence of str, (n_f,)
    theta : ndarray (n_f,)
        The estimates, in the parameters' units.
    typical : ndarray (n_f,)
        Each parameter's typical magnitude, the scale of the solver's unknowns (``theta = typical z``).
    information : ndarray (n_f, n_f)
        :func:`parameter_information` in those scaled unknowns.
    sigma2 : float
        The residuals' variance (normalised units).
    """
    names, theta, typical = list(names), np.asarray(theta, float), np.asarray(typical, float)
    cov, null = covariance(information, sigma2)
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(invalid="ignore", over="ignore"):  # a parameter the data never see: its row is NaN (undefined)
        corr = cov / np.outer(np.maximum(sd, 1e-300), np.maximum(sd, 1e-300))
    np.fill_diagonal(corr, 1.0)
    ref = _references(theta, typical)
    relative = np.where(null, np.inf, sd * typical / ref)
    d = ref / typical  # z_j = (ref_j / typical_j) rho_j: the information in relative parameters is D F D
    w, V = np.linalg.eigh(d[:, None] * information * d[None, :])
    floor = NULL_RTOL * max(float(w.max(initial=0.0)), np.finfo(float).tiny)
    directions = []
    for k in range(len(w)):
        v = V[:, k] * np.sign(V[np.argmax(np.abs(V[:, k])), k])  # largest component positive
        spread = float(np.sqrt(sigma2 / w[k])) if w[k] > floor else float("inf")
        directions.append({"relative_std_error": spread,
                           "components": {n: float(c) for n, c in zip(names, v) if abs(c) >= 0.01}})
    report = {"limits": {"relative_std_error": RELATIVE_LIMIT},
              "parameters": names, "correlation": corr.round(6).tolist(),
              "relative_std_error": dict(zip(names, map(float, relative))),
              "weak_directions": directions}
    report["flags"] = _flags(names, theta, corr, relative)
    return report


def _flags(names, theta, corr, relative) -> list[dict]:
    """``[{"kind", "parameters", "message"}]``: the parameters whose standard error exceeds :data:`RELATIVE_LIMIT`
    of their value, grouped where two of them correlate beyond :data:`GROUP_CORRELATION`, least determined first."""
    uncertain = [i for i, r in enumerate(relative) if r > RELATIVE_LIMIT]
    groups, left = [], set(uncertain)
    while left:  # connected components of "strongly correlated" among the uncertain ones
        group, todo = [], [min(left)]
        left.discard(todo[0])
        while todo:
            i = todo.pop()
            group.append(i)
            near = [j for j in left if abs(corr[i, j]) >= GROUP_CORRELATION]
            left.difference_update(near)
            todo += near
        groups.append(sorted(group, key=lambda k: -relative[k]))
    flags = []
    for group in sorted(groups, key=lambda g: -relative[g[0]]):
        first = names[group[0]]
        fix = f"--fixed {first} --start {first}={theta[group[0]]:.6g}"
        if len(group) == 1:
            message = (f"{first} is not determined by the data (standard error {_percent(relative[group[0]])} of "
                       f"its value): fix it ({fix}) or give data that excite it")
            flags.append({"kind": "undetermined", "parameters": [first], "message": message})
            continue
        c = max((corr[a, b] for a in group for b in group if a < b), key=abs)
        errors = ", ".join(_percent(relative[k]) for k in group)
        message = (f"{_and([names[k] for k in group])} cannot be told apart (correlation {c:+.3f}, standard errors "
                   f"{errors} of their values): fix one ({fix}) or tie them in the model")
        flags.append({"kind": "collinear", "parameters": [names[k] for k in group], "message": message})
    return flags


def _and(names: list[str]) -> str:
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]


def _percent(x: float | None) -> str:
    """``+-58.6 %``, ``+-1.5e+04 %``, ``+-inf`` (also for None: an infinite figure read back from JSON)."""
    return "+-inf" if x is None or not np.isfinite(x) else f"+-{100 * x:.3g} %"


def describe(section: dict, *, most_pairs: int = 10) -> list[str]:
    """Lines for a person: the correlations (the matrix up to 6 parameters, else the strongest pairs), the
    weakest direction, and one line per flag (each starting ``"identifiability: "``). ``section``: as
    :func:`identifiability_report` returns it, or read back from a fit file."""
    names, corr = section["parameters"], np.asarray(section["correlation"], dtype=float)
    lines = []
    if 1 < len(names) <= 6:
        width, label = max(8, *map(len, names)), max(11, *map(len, names))
        lines.append(f"{'correlation':<{label}} " + " ".join(f"{n:>{width}}" for n in names[:-1]))
        for i, n in enumerate(names[1:], start=1):
            lines.append(f"{n:<{label}} " + " ".join(f"{corr[i, j]:>+{width}.3f}" for j in range(i)))
    elif len(names) > 6:
        pairs = sorted(((abs(corr[i, j]), i, j) for i in range(len(names)) for j in range(i)), reverse=True)
        strong = [(i, j) for c, i, j in pairs if c >= STRONG_CORRELATION][:most_pairs]
        lines.append("strongest correlations: " + (", ".join(f"{names[i]}~{names[j]} {corr[i, j]:+.3f}"
                                                            for i, j in strong) or f"none above {STRONG_CORRELATION}"))
    weakest = section["weak_directions"][0] if section["weak_directions"] else None
    if weakest is not None and len(names) > 1:
        parts = " ".join(f"{c:+.2f} {n}" for n, c in sorted(weakest["components"].items(), key=lambda t: -abs(t[1]))
                         if abs(c) >= 0.1)
        lines.append(f"weakest direction (relative changes): {parts}, determined to "
                     f"{_percent(weakest['relative_std_error'])}")
    lines += [f"identifiability: {flag['message']}" for flag in section["flags"]]
    return lines
