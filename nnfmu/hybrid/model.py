"""``HybridStepModel``: a CasADi physics model plus a neural correction, behind the one step interface.

The physics is written once, in CasADi (:mod:`nnfmu.physics`); torch evaluates it
through :func:`nnfmu.hybrid.casadi_to_torch` (compiled C or the SX translation, both
with CasADi's own reverse-mode gradients). With ``correction="derivative"`` (default)::

    delta(x, u) = scatter_corrected(state_scale / correction_time * N([x / state_scale, un]))
    xdot        = ode(x, u, p) + delta(x, u)                   # inside every RK4 stage
    x_{k+1}     = rk4_step(xdot, x_k, u_k, p, Ts, n_sub)       # nnfmu.physics.rk4_step, in torch
    y_{k+1}     = output(x_{k+1}, p)

and with ``correction="step"``: ``x_{k+1} = RK4_physics(x_k, u_k, p) + Ts * delta(x_k, u_k)``.

Why the derivative is the default: a missing force or flow *is* a term of the ODE, so the
correction acts where the physics is wrong, is integrated by the same RK4 as the physics
(it cannot destabilise the discretisation more than the physics' own terms) and does not
depend on Ts or n_sub. The step residual is cheaper (one network call per sample instead of
``4 n_sub``, and the physics step is one compiled call) but is tied to the sample time.

``N`` is an MLP whose last layer starts at zero, so an untrained hybrid *is* the physics.
It sees the state scaled by ``state_scales`` and the normalised input. Only derivatives of
``corrected_states`` are corrected (the valve: pressure and plunger velocity; the arm: the
joint accelerations), not kinematic identities such as ``d/dt s = sdot``.

The state ``x`` is the physics state in physical units (valve: ``[z1, z1dot, z2, z2dot, p,
s, sdot]``; arm: ``[q1..q6 (rad), qd1..qd6 (rad/s)]``); ``init(y0, u0)`` is the physics'
``init_state``. Trainable physical parameters are ``p = p_given * exp(gain * theta)`` with
``theta`` (``physics_log_scale``) starting at 0. The physics runs in float64 whatever the
model's dtype; train hybrids in float64 (the CLI does).

Hybrids train in parallel mode only: teacher forcing would have to write measured outputs
into a state that holds more than the outputs, so series-parallel raises ConfigError.
"""

from __future__ import annotations

import functools
import math
import warnings
from typing import Mapping, NamedTuple

import torch
from torch import nn
from torch.nn import functional as F

from nnfmu.errors import ConfigError, ShapeError
from nnfmu.hybrid.compiled_torch import casadi_to_torch
from nnfmu.hybrid.config import HybridConfig
from nnfmu.hybrid.fused import fused_step, weight_vector
from nnfmu.hybrid.initial_state import estimate_state
from nnfmu.hybrid.parameters import document_system, hide_state_inputs, physics_system
from nnfmu.models.base import StepModel
from nnfmu.models.activation import activation_module
from nnfmu.physics import PhysicsSystem, rk4_step
from nnfmu.physics.rk4 import physics_step
from nnfmu.system import Variable


class _Plan(NamedTuple):
    """What :meth:`HybridStepModel.delta` needs, fetched once per rollout (the RK4 stages' hot loop)."""

    w_x: torch.Tensor
    w_u: torch.Tensor
    b: torch.Tensor
    rest: list
    state_scale: torch.Tensor
    scatter: torch.Tensor
    fused: object = None                # the whole step as one compiled call (nnfmu.hybrid.fused), or None
    weights: torch.Tensor | None = None  # its input ``w``: the correction's weights, flattened


class PhysicsBridge:
    """Torch callables of one physics system: ``ode``, ``output``, ``init_state`` and (step mode) ``rk4``.

    Shared by every model and copy of a model with the same physics, backend and discretisation.
    """

    def __init__(self, system: PhysicsSystem, backend: str, Ts: float, n_sub: int, with_rk4: bool):
        self.system, self.backend = system, backend
        self.ode = casadi_to_torch(system.ode, backend=backend)
        self.output = casadi_to_torch(system.output, backend=backend)
        self.init_state = casadi_to_torch(system.init_state, backend=backend)
        self.rk4 = casadi_to_torch(physics_step(system, Ts, n_sub), backend=backend) if with_rk4 else None

    def __deepcopy__(self, memo) -> "PhysicsBridge":
        return self


@functools.lru_cache(maxsize=None)
def physics_bridge(physics: tuple[str, str], backend: str, Ts: float, n_sub: int, with_rk4: bool) -> PhysicsBridge:
    """The bridge of the physics that ``physics`` (:meth:`HybridConfig.physics_key`) identifies."""
    kind, value = physics
    system = document_system(value) if kind == "document" else physics_system(value)
    return PhysicsBridge(system, backend, Ts, n_sub, with_rk4)


def physics_meta(system: PhysicsSystem) -> dict:
    """Meta of a hybrid made without a dataset: the physics' name, Ts and channels."""
    def channels(variables) -> list[dict]:
        return [{"name": v.name, "unit": v.unit} for v in variables]

    return {"name": f"{system.name}_hybrid", "Ts": system.Ts, "inputs": channels(system.inputs),
            "outputs": channels(system.outputs)}


class HybridStepModel(StepModel):
    """Physics ODE plus neural correction; see the module docstring.

    Attributes
    ----------
    physics : PhysicsSystem
        The (nominal) CasADi physics; its parameter vector comes from :meth:`physics_parameters`.
    Ts : float
        Sample time in seconds (the dataset's).
    n_sub : int
        RK4 sub-steps per sample.
    correction : nn.Sequential
        The MLP ``N``; its last Linear starts at zero.
    physics_log_scale : nn.Parameter (n_train,)
        ``theta`` of the trained physical parameters (``config.train_physics``).
    """

    takes_feedback_noise = False  # its state is the physics state: no fed-back output to disturb

    def __init__(self, config: HybridConfig, meta: Mapping | None = None):
        if not isinstance(config, HybridConfig):
            raise ShapeError(f"expected a HybridConfig, got {type(config).__name__}")
        system = config.system()
        super().__init__(config, physics_meta(system) if meta is None else meta)
        self._check_units(system)
        self.Ts = float(self.meta["Ts"])
        self.n_sub = config.n_sub or max(1, math.ceil(system.n_sub * self.Ts / system.Ts - 1e-9))
        self._bridge = physics_bridge(config.physics_key(), config.physics_backend, self.Ts, self.n_sub,
                                      config.correction == "step")
        names = [v.name for v in system.parameters]
        states = [v.name for v in system.states]
        # float64 constants outside the state_dict (rebuilt from the config): .to(float32) must not round them
        self._p_given = torch.tensor(config.parameter_values(), dtype=torch.float64)
        self._trained = torch.tensor([names.index(n) for n in config.train_physics], dtype=torch.long)
        self._p_min, self._p_max = _trained_bounds(system, config.train_physics)
        self._state_scale = torch.tensor(system.state_scales or (1.0,) * system.n_x, dtype=torch.float64)
        self._corrected = torch.tensor([states.index(n) for n in config.corrected_states], dtype=torch.long)
        scale = self._state_scale[self._corrected] / config.correction_time
        self._scatter = torch.zeros(system.n_x, len(self._corrected), dtype=torch.float64)
        self._scatter[self._corrected, torch.arange(len(self._corrected))] = scale
        self.physics_log_scale = nn.Parameter(torch.zeros(len(config.train_physics)))
        self.correction = _correction_mlp(config, system.n_x, len(config.corrected_states))
        hide_state_inputs(self.correction[0], [i for i, n in enumerate(states) if n not in config.correction_inputs])
        self.check_sizes()

    def _check_units(self, system: PhysicsSystem) -> None:
        """Refuse data whose channels' units differ from the physics' (a subclass may generate its physics)."""
        _check_units(self.meta, system)

    def _apply(self, fn, recurse=True):
        """``.to(device)`` moves the float64 constants too (their dtype stays float64, see ``__init__``)."""
        super()._apply(fn, recurse)
        device = self.u_mean.device
        for name in ("_p_given", "_trained", "_p_min", "_p_max", "_state_scale", "_corrected", "_scatter"):
            value = getattr(self, name)
            setattr(self, name, None if value is None else value.to(device))
        return self

    # ---- physics ----------------------------------------------------------------------------
    @property
    def physics(self) -> PhysicsSystem:
        return self._bridge.system

    @property
    def n_x(self) -> int:
        return self.physics.n_x

    def physics_parameters(self) -> torch.Tensor:
        """The parameter vector ``p`` (n_p,) in float64: given values, trained entries times ``exp(gain * theta)``.

        A trained entry stays within its parameter's ``min`` / ``max`` (clipped there) where it has them.
        """
        if not len(self._trained):
            return self._p_given
        theta = self.physics_log_scale.double() * self.config.train_physics_gain
        factor = torch.ones_like(self._p_given).index_put((self._trained,), torch.exp(theta))
        p = self._p_given * factor
        return p if self._p_min is None else torch.clamp(p, self._p_min, self._p_max)

    def physics_parameter_values(self) -> dict[str, float]:
        """Current physical parameters by name (the trained values where trained)."""
        values = self.physics_parameters().detach().tolist()
        return {v.name: value for v, value in zip(self.physics.parameters, values)}

    def physics_variables(self) -> tuple[Variable, ...]:
        """The physics parameters as Variables whose ``start`` is the current value (FMU parameters)."""
        values = self.physics_parameters().detach().tolist()
        return tuple(Variable(v.name, v.unit, v.description, value)
                     for v, value in zip(self.physics.parameters, values))

    # ---- the correction ---------------------------------------------------------------------
    def _plan(self, dtype: torch.dtype, fused_batch: int = 0) -> "_Plan":
        """The correction's weights and constants for one rollout (views of the parameters, no copies).

        With ``fused_batch`` (the batch size; 0: none), also the whole step as one compiled call where it applies
        (:mod:`nnfmu.hybrid.fused`)
        and its input ``w``, the weights concatenated into one vector (a copy, differentiable).
        """
        layers = list(self.correction)
        first, n_x = layers[0], self.n_x
        rest = [m for m in layers[1:] if not (type(m) is nn.Dropout and not (self.training and m.p > 0))]
        step = fused_step(self, fused_batch) if fused_batch else None
        return _Plan(first.weight[:, :n_x], first.weight[:, n_x:], first.bias, rest,
                     self._state_scale.to(dtype), self._scatter.to(dtype), step,
                     None if step is None else weight_vector(self))

    def delta(self, x: torch.Tensor, input_term: torch.Tensor, plan: "_Plan") -> torch.Tensor:
        """Correction of the state derivative (B, n_x), zero outside ``corrected_states``.

        ``x`` (B, n_x) physical state; ``input_term = W1_u un + b1`` (B, hidden), the input's
        share of the first layer, which is constant over a sample's RK4 stages. The network is
        ``N = MLP(W1_x (x / state_scale) + input_term)`` and ``delta = S N``, with ``S`` (n_x, n_corr)
        holding ``state_scale_i / correction_time`` at the corrected states (one nonzero per row,
        so the product is exact).
        """
        v = F.linear(_as(x / plan.state_scale, plan.w_x), plan.w_x) + input_term
        for module in plan.rest:
            v = F.linear(v, module.weight, module.bias) if type(module) is nn.Linear else module(v)
        return F.linear(_as(v, x), plan.scatter)

    def _advance(self, x, u, un, p, plan) -> tuple[torch.Tensor, torch.Tensor]:
        """One sample in physical units: ``(x_next, y_next)``."""
        if plan.fused is not None:
            x_next, y_next = plan.fused(x, u, un, p, plan.weights)
            return _as(x_next, x), _as(y_next, x)
        c = F.linear(_as(un, plan.w_u), plan.w_u, plan.b)
        if self._bridge.rk4 is not None:
            x_next = _as(self._bridge.rk4(x, u, p)[0], x) + self.Ts * self.delta(x, c, plan)
        else:
            def rhs(x_, u_, p_):
                return _as(self._bridge.ode(x_, u_, p_)[0], x_) + self.delta(x_, c, plan)

            x_next = rk4_step(rhs, x, u, p, Ts=self.Ts, n_sub=self.n_sub)
        return x_next, _as(self._bridge.output(x_next, p)[0], x)

    def _denormalise_u(self, un: torch.Tensor) -> torch.Tensor:
        return un * self.u_std + self.u_mean

    # ---- StepModel core (normalised in, physical state) --------------------------------------
    def init_norm(self, yn0: torch.Tensor, un0: torch.Tensor) -> torch.Tensor:
        p = self.physics_parameters()
        return self._bridge.init_state(self.denormalise_y(yn0), self._denormalise_u(un0), p)[0].to(yn0.dtype)

    def step_norm(self, x: torch.Tensor, un: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        x_next, y_next = self._advance(x, self._denormalise_u(un), un, self.physics_parameters(), self._plan(x.dtype))
        return x_next, self.normalise_y(y_next)

    def init_window_norm(self, yn_win: torch.Tensor, un_win: torch.Tensor) -> torch.Tensor:
        """The state at the window's newest sample (B, n_x): with ``init_window = N > 1``, its FMU's estimator over
        the window (B, N, n_y), (B, N, n_u) (:mod:`nnfmu.hybrid.initial_state`), else the init rule."""
        if self.config.init_window == 1:
            return self.init_norm(yn_win[:, -1], un_win[:, -1])
        return estimate_state(self, yn_win, un_win)

    def free_run_norm(self, un: torch.Tensor, yn0: torch.Tensor, x0: torch.Tensor | None = None) -> torch.Tensor:
        """Free run: the same operations as :meth:`step_norm`, with ``p`` and ``u`` computed once; from ``x0``
        (B, n_x; default the init rule at ``yn0``)."""
        out = self._free_run_eager(un, yn0, x0)
        self._check_finite(out)
        return out

    def _free_run_eager(self, un: torch.Tensor, yn0: torch.Tensor, x0: torch.Tensor | None = None) -> torch.Tensor:
        """:meth:`free_run_norm` without the check (what :mod:`nnfmu.hybrid.graphed` records on a GPU)."""
        p, u, plan = self.physics_parameters(), self._denormalise_u(un), self._plan(yn0.dtype, fused_batch=yn0.shape[0])
        if x0 is None:
            x0 = self._bridge.init_state(self.denormalise_y(yn0), u[:, 0], p)[0]
        x = x0.to(yn0.dtype)
        ys = [yn0]
        for k in range(un.shape[1] - 1):
            x, y = self._advance(x, u[:, k], un[:, k], p, plan)
            ys.append(self.normalise_y(y))
        return torch.stack(ys, dim=1)

    def _check_finite(self, out: torch.Tensor) -> None:
        """In training, warn that the simulation blew up if ``out`` is not finite (the trainer then stops)."""
        if self.training and not bool(torch.isfinite(out).all()):
            _warn_blow_up(self)

    def inject_y(self, x: torch.Tensor, yn: torch.Tensor) -> torch.Tensor:
        raise _series_parallel_error()

    def teacher_forced_norm(self, un: torch.Tensor, yn_meas: torch.Tensor) -> torch.Tensor:
        raise _series_parallel_error()


def _warn_blow_up(model: "HybridStepModel") -> None:
    """Say that the simulation, not the data, went non-finite (the trainer then stops and keeps the best weights)."""
    values = ", ".join(f"{k} = {v:.4g}" for k, v in model.physics_parameter_values().items())
    warnings.warn(f"the {model.physics.name} hybrid's simulation became non-finite in training: its ODE blew up "
                  f"(physical parameters {values}); check the model and its parameters, or lower the learning rate",
                  RuntimeWarning, stacklevel=4)


def _trained_bounds(system: PhysicsSystem, trained) -> tuple[torch.Tensor | None, torch.Tensor | None]:
    """Float64 ``(min, max)`` vectors (n_p,) of the trained parameters' bounds (+-inf elsewhere); None if there are none."""
    lower = [v.min if v.name in trained and v.min is not None else -math.inf for v in system.parameters]
    upper = [v.max if v.name in trained and v.max is not None else math.inf for v in system.parameters]
    if all(math.isinf(b) for b in lower + upper):
        return None, None
    return torch.tensor(lower, dtype=torch.float64), torch.tensor(upper, dtype=torch.float64)


def _as(t: torch.Tensor, like: torch.Tensor) -> torch.Tensor:
    return t if t.dtype == like.dtype else t.to(like.dtype)


def _series_parallel_error() -> ConfigError:
    return ConfigError("a hybrid model trains in parallel mode only (strategy='parallel'): its state is the full "
                       "physics state, which measured outputs cannot overwrite; use strategy='parallel'")


def _check_units(meta: dict, system: PhysicsSystem) -> None:
    for key, variables in (("inputs", system.inputs), ("outputs", system.outputs)):
        for chan, var in zip(meta[key], variables):
            unit = chan.get("unit", "")
            if unit and unit != var.unit:
                raise ConfigError(f"{key[:-1]} {chan.get('name')!r} is in {unit!r} but the {system.name} physics "
                                  f"expects {var.name} in {var.unit!r}; convert the data to the physics' units")


def _correction_mlp(config: HybridConfig, n_x: int, n_out: int) -> nn.Sequential:
    modules: list[nn.Module] = []
    n_in = n_x + config.n_u
    for _ in range(config.layers):
        modules += [nn.Linear(n_in, config.hidden), activation_module(config.activation), nn.Dropout(config.dropout)]
        n_in = config.hidden
    last = nn.Linear(n_in, n_out)
    nn.init.zeros_(last.weight)
    nn.init.zeros_(last.bias)
    return nn.Sequential(*modules, last)
