"""``NodeConfig`` (``arch="node"``): a hybrid whose physics is a generated zero ODE, and that physics.

The neural ODE is the degenerate hybrid (:mod:`nnfmu.node`): :func:`node_physics` writes, with
:class:`~nnfmu.physics.ModelBuilder`, a model of ``n_states`` states ``x1..xN`` (output-normalised, scale 1)
whose ODE is zero, whose outputs are ``y_i = y_mean_i + y_std_i * x_i`` (``i < n_y``) and whose initial state
is ``x_i = (y0_i - y_mean_i) / y_std_i``, the latent states 0. ``y_mean`` and ``y_std`` are parameters of that
physics (fixed, never trained): :class:`~nnfmu.node.model.NodeStepModel` supplies them from its output
normalisation, so the exported FMU shows them as parameters with the data's values and units.

Why ``y = x[:n_y]`` and not a learned ``y = C x``: for any ``C`` of full row rank a change of latent
coordinates ``z = T x`` whose first rows are ``C`` gives ``y = z[:n_y]`` with the same input/output
behaviour, so the identity output loses no generality for a linear output map; it makes the initial
state exact from the first measured output (no init network, no pseudo-inverse), and it keeps the output
free of trained parameters (the Model Exchange FMU's outputs are states, scaled).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca

from nnfmu.errors import ConfigError, ShapeError
from nnfmu.hybrid.config import HybridConfig
from nnfmu.node import NODE_ARCH
from nnfmu.physics import ModelBuilder, PhysicsSystem

__all__ = ["NodeConfig", "default_states", "node_physics"]


def default_states(n_y: int) -> int:
    """``max(2 n_y, 4)``: position and velocity per output (a mechanical system), at least 4."""
    return max(2 * n_y, 4)


def node_physics(n_x: int, n_u: int, n_y: int) -> PhysicsSystem:
    """The zero ODE over ``n_x`` states: inputs ``u1..``, outputs ``y1..``, parameters ``y<i>_mean``, ``y<i>_std``.

    Its time unit is one sample (``Ts = 1``): the model's RK4 runs at the data's sample time, and the
    correction's scale comes from :attr:`NodeConfig.time_scale`.
    """
    m = ModelBuilder(NODE_ARCH, Ts=1.0, n_sub=1,
                     description=f"no physics (xdot = 0 over {n_x} states, y = y_mean + y_std x[:{n_y}])",
                     source={"model": "nnfmu.node.config:node_physics", "n_states": n_x})
    x = [m.state(f"x{i + 1}", "", "output-normalised output" if i < n_y else "latent state") for i in range(n_x)]
    for j in range(n_u):
        m.input(f"u{j + 1}", "", f"input {j + 1}")
    mean = [m.parameter(f"y{i + 1}_mean", 0.0, "", f"offset of output {i + 1}", free=False) for i in range(n_y)]
    std = [m.parameter(f"y{i + 1}_std", 1.0, "", f"scale of output {i + 1}", min=0.0, free=False)
           for i in range(n_y)]
    m.ode(ca.SX.zeros(n_x, 1))
    measured = [m.output(f"y{i + 1}", "", f"output {i + 1}", mean[i] + std[i] * x[i]) for i in range(n_y)]
    m.init(**{f"x{i + 1}": (measured[i] - mean[i]) / std[i] for i in range(n_y)})
    return m.build()


@dataclass(frozen=True, kw_only=True)
class NodeConfig(HybridConfig):
    """A neural ODE: the hybrid fields with the physics generated from the sizes.

    Attributes
    ----------
    n_states : int or None
        States of the ODE, ``>= n_y`` (None: :func:`default_states`).
    time_scale : float
        Sample times: ``xdot = N(x, u) / (time_scale * Ts)`` with ``N`` the MLP (``hidden``, ``layers``,
        ``activation``, ``dropout``), so a unit network output moves a state by one output standard
        deviation in ``time_scale`` samples. Stored as the hybrid's ``correction_time`` too (in samples here).
    n_sub : int
        RK4 sub-steps per sample (default 1).
    physics, physics_document, physics_params, train_physics, corrected_states, correction_time
        Set from the above (:func:`node_physics`; nothing trained but the network; every state corrected);
        the values a checkpoint holds are replaced, so they cannot disagree with the sizes.
    """

    arch: str = NODE_ARCH
    physics: str = NODE_ARCH
    n_states: int | None = None
    time_scale: float = 10.0
    n_sub: int | None = 1

    def __post_init__(self) -> None:
        if self.arch != NODE_ARCH:
            raise ConfigError(f"NodeConfig has arch {NODE_ARCH!r}, got {self.arch!r}")
        for name in ("n_u", "n_y"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise ShapeError(f"NodeConfig.{name} must be a positive integer, got {value!r}")
        n_x = default_states(self.n_y) if self.n_states is None else self.n_states
        if not isinstance(n_x, int) or isinstance(n_x, bool) or n_x < self.n_y:
            raise ShapeError(f"a neural ODE needs at least one state per output ({self.n_y}), got n_states = "
                             f"{n_x!r}; give --states {self.n_y} or more")
        if isinstance(self.time_scale, bool) or not (isinstance(self.time_scale, (int, float))
                                                     and 0 < self.time_scale < math.inf):
            raise ConfigError(f"time_scale must be a positive number of sample times, got {self.time_scale!r}")
        if self.correction != "derivative":
            raise ConfigError(f"a neural ODE's network is its derivative (correction='derivative'), got "
                              f"{self.correction!r}; leave correction out")
        if dict(self.physics_params):
            raise ConfigError("a neural ODE has no physical parameters to set; leave physics_params out")
        if self.n_sub is None:
            object.__setattr__(self, "n_sub", 1)
        for name, value in (("n_states", n_x), ("time_scale", float(self.time_scale)),
                            ("physics", node_physics(n_x, self.n_u, self.n_y)), ("physics_document", None),
                            ("train_physics", ()), ("corrected_states", None),
                            ("correction_time", float(self.time_scale))):
            object.__setattr__(self, name, value)
        super().__post_init__()
