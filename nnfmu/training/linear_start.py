"""Start a network on its linear path (``ModelConfig.linear_order > 0``) at the identified linear baseline.

:func:`start_linear_path` gives each holder of a linear path in a fresh model (a
:class:`~nnfmu.models.linear_path.LinearPathStepModel`, or a model that holds its path itself, as :mod:`nnfmu.ss`'s;
one network or an ensemble's members) the linear model's matrices in its normalised units
(:func:`path_arrays`), with every linear state scaled to unit size over the training data; the correction
starts at zero, so the fresh model simulates exactly the linear model.
"""

from __future__ import annotations

import numpy as np

from nnfmu.data import Dataset, Trajectories
from nnfmu.errors import ConfigError
from nnfmu.models.base import StepModel
from nnfmu.models.linear_path import LinearPathStepModel


def linear_state_scale(linear, train: Trajectories) -> np.ndarray:
    """Per linear state, its RMS over the free runs of ``linear`` on the training trajectories (n_z,)."""
    from nnfmu.linear.statespace import free_run

    sums, count = np.zeros(linear.n_x), 0
    for u, y in zip(train.u, train.y):
        x0 = linear.initial_state(y[0], u[0])
        xs, _ = free_run(linear.system, x0[None], np.asarray(u, dtype=float)[None])
        sums += np.sum(xs[0] ** 2, axis=0)
        count += len(u)
    rms = np.sqrt(sums / max(count, 1))
    ok = np.isfinite(rms) & (rms > 1e-12 * max(float(np.max(rms, initial=0.0)), 1e-300))
    return np.where(ok, rms, 1.0)


def start_linear_path(model: StepModel, dataset: Dataset, linear=None):
    """Set the linear path of ``model`` (or of each ensemble member) from ``linear``; returns the linear model.

    ``linear`` None: identify one of ``model.config.linear_order`` states on ``dataset`` (its train split, with
    its valid split guarding the refinement).
    """
    order = model.config.linear_order
    if linear is None:
        from nnfmu.linear import LinearConfig, identify_linear

        linear = identify_linear(dataset, LinearConfig(order=order))
    if linear.n_x != order:
        raise ConfigError(f"the linear model has {linear.n_x} states but linear_order is {order}; "
                          f"set linear_order={linear.n_x}")
    names = [[c.name for c in chans] for chans in (linear.inputs, linear.outputs)]
    if names != [dataset.input_names, dataset.output_names]:
        raise ConfigError(f"the linear model was identified on inputs {names[0]} and outputs {names[1]}, the dataset "
                          f"has {dataset.input_names} and {dataset.output_names}; identify it on this dataset")
    if linear.init != "estimate":
        raise ConfigError(f"a linear path starts from the 'estimate' initial-state rule, got {linear.init!r}; "
                          "identify the linear model with init='estimate'")
    scale = linear_state_scale(linear, dataset.train)
    for path in path_holders(model):
        path.set_path(path_arrays(linear, path, scale))
    return linear


def path_holders(model: StepModel) -> list[StepModel]:
    """The modules of ``model`` that hold a linear path: they name their arrays in ``PATH_ARRAYS`` and take them
    in ``set_path`` (:class:`LinearPathStepModel`, and models whose record says ``linear_path="own"``)."""
    return [m for m in model.modules() if isinstance(m, StepModel) and hasattr(m, "PATH_ARRAYS")
            and callable(getattr(m, "set_path", None))]


def path_arrays(linear, path: LinearPathStepModel, state_scale: np.ndarray) -> dict:
    """The linear model in ``path``'s normalised units, its states divided by ``state_scale``; zero corrections.

    With ``u = s_u un + m_u``, ``y = s_y yn + m_y`` and ``x = D z``: ``A_n = D^-1 A D``, ``B_n = D^-1 B s_u``,
    ``b_n = D^-1 (B m_u + b)``, ``C_n = s_y^-1 C D``, ``d_n = (d - m_y) / s_y``, and the ``estimate`` rule
    ``z0 = D^-1 (K_y (s_y yn0 + m_y - d) + K_u (s_u un0 + m_u) + k_0)``.
    """
    from nnfmu.linear.statespace import init_gains

    sys, D = linear.system, np.asarray(state_scale, dtype=float)
    su, mu, sy, my = (getattr(path, k).detach().double().cpu().numpy() for k in ("u_std", "u_mean", "y_std", "y_mean"))
    K_y, K_u, k_0 = init_gains(sys, linear.y_scale)
    return {"lin_A": sys.A * D[None, :] / D[:, None], "lin_B": sys.B * su[None, :] / D[:, None],
            "lin_b": (sys.B @ mu + sys.b) / D, "lin_C": sys.C * D[None, :] / sy[:, None], "lin_d": (sys.d - my) / sy,
            "lin_Ky": K_y * sy[None, :] / D[:, None], "lin_Ku": K_u * su[None, :] / D[:, None],
            "lin_k0": (K_y @ (my - sys.d) + K_u @ mu + k_0) / D,
            "lin_G": np.zeros((sys.n_x, len(my))), "alpha": np.zeros(len(my))}
