"""Start a network on its linear path (``ModelConfig.linear_order > 0``) at the identified linear baseline.

:func:`start_linear_path` gives each :class:`~nnfmu.models.linear_path.LinearPathStepModel` in a fresh model
(one network or an ensemble's members) the linear model's matrices in its normalised units, with every linear
state scaled to unit size over the training data; the correction starts at zero, so the fresh model
simulates exactly the linear model.
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
    scale = linear_state_scale(linear, dataset.train)
    paths = [m for m in model.modules() if isinstance(m, LinearPathStepModel)]
    for path in paths:
        path.set_linear(linear, state_scale=scale)
    return linear
