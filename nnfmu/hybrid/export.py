"""A trained hybrid as CasADi ``(init, step)`` Functions: the same SX physics, the network as MX constants.

::

    init(y0, u0, p) -> x0 = physics.init_state(y0, u0, p)
    step(x, u, p)   -> (x_next, y_next)
        derivative:  x_next = rk4_step(lambda x, u, p: physics.ode(x, u, p) + delta(x, u), x, u, p, Ts, n_sub)
        step:        x_next = physics_step(physics)(x, u, p) + Ts * delta(x, u)   (the same RK4 as a Function)
        y_next = physics.output(x_next, p)

``delta`` is the correction network written with the dense-constant MX layers of
:mod:`nnfmu.export.casadi_layers`, in the torch model's order of operations. The physical
parameters ``p`` are a port, so :func:`hybrid_casadi_model` exposes them as tunable FMU
parameters whose start values are the trained ones. :func:`nnfmu.export.to_casadi` and
:func:`nnfmu.export.casadi_model` call these for a :class:`~nnfmu.hybrid.HybridStepModel`.
"""

from __future__ import annotations

import copy

import casadi as ca
import numpy as np
import torch
from torch import nn

from nnfmu.errors import ExportError
from nnfmu.export import casadi_layers as nets
from nnfmu.hybrid.model import HybridStepModel, physics_step
from nnfmu.identifiers import to_c_identifier
from nnfmu.physics import rk4_step
from nnfmu.physics.initial_state import with_init_window
from nnfmu.system import CasadiModel, ContinuousDynamics, SystemSpec, Variable
from nnfmu.valid_range import stored_input_variables, with_starts

_VERIFY_RTOL = 1e-9


def _delta_function(model: HybridStepModel) -> ca.Function:
    """``delta(x, u) -> xdot_correction`` as an MX Function with the weights as constants."""
    c, n_x = model.config, model.n_x
    x, u = ca.MX.sym("x", n_x), ca.MX.sym("u", c.n_u)
    layers = list(model.correction)
    first = layers[0]
    if not isinstance(first, nn.Linear):
        raise nets.unsupported("correction.0", first)
    w = first.weight.detach()
    un = (u - nets.dm(model.u_mean)) / nets.dm(model.u_std)
    input_term = ca.mtimes(nets.dm(w[:, n_x:]), un) + nets.dm(first.bias)
    v = ca.mtimes(nets.dm(w[:, :n_x]), x / nets.dm(model._state_scale)) + input_term
    for i, module in enumerate(layers[1:], start=1):
        v = nets.module_expr(module, v, f"correction.{i}")
    delta = ca.mtimes(nets.dm(model._scatter), v)
    return ca.Function("delta", [x, u], [delta], ["x", "u"], ["xdot_correction"])


def hybrid_to_casadi(model: HybridStepModel, *, verify: bool = True) -> tuple[ca.Function, ca.Function]:
    """CasADi ``init(y0, u0, p) -> x0`` and ``step(x, u, p) -> (x_next, y_next)`` of a hybrid model.

    Parameters
    ----------
    model : HybridStepModel
    verify : bool
        Compare ``init`` and two steps with the torch model (relative 1e-9 per entry,
        against the entry's magnitude or its state scale).

    Raises
    ------
    ExportError
        For a layer the builders do not know or a failed verification.
    """
    if not isinstance(model, HybridStepModel):
        raise ExportError(f"expected a HybridStepModel, got {type(model).__name__}")
    system, c = model.physics, model.config
    delta = _delta_function(model)
    x, u = ca.MX.sym("x", model.n_x), ca.MX.sym("u", c.n_u)
    p, y0 = ca.MX.sym("p", len(system.parameters)), ca.MX.sym("y0", c.n_y)
    if c.correction == "step":
        x_next = physics_step(system, model.Ts, model.n_sub)(x, u, p) + model.Ts * delta(x, u)
    else:
        x_next = rk4_step(lambda x_, u_, p_: system.ode(x_, u_, p_) + delta(x_, u), x, u, p,
                          Ts=model.Ts, n_sub=model.n_sub)
    init = ca.Function("init", [y0, u, p], [system.init_state(y0, u, p)], ["y0", "u0", "p"], ["x0"])
    step = ca.Function("step", [x, u, p], [x_next, system.output(x_next, p)], ["x", "u", "p"],
                       ["x_next", "y_next"])
    if verify:
        verify_hybrid_export(model, init, step)
    return init, step


def verify_hybrid_export(model: HybridStepModel, init: ca.Function, step: ca.Function, seed: int = 0) -> None:
    """Raise ExportError unless ``init`` and two steps from the mean output match the torch model."""
    ref = copy.deepcopy(model).double().eval()
    rng = np.random.default_rng(seed)
    y0 = ref.y_mean.numpy().copy()
    us = ref.u_mean.numpy() + 0.5 * ref.u_std.numpy() * rng.standard_normal((2, model.config.n_u))
    p = ref.physics_parameters().detach().numpy()
    scale = ref._state_scale.numpy()
    with torch.no_grad():
        # the init rule (an init window's estimator is verified with the model it is built on)
        x_t = ref.init_norm(ref.normalise_y(torch.from_numpy(y0)[None]), ref.normalise_u(torch.from_numpy(us[0])[None]))
        x_c = np.asarray(init(y0, us[0], p)).ravel()
        pairs = [("x0", x_c, x_t[0].numpy(), scale)]
        for k, u_k in enumerate(us):
            x_t, y_t = ref.step(x_t, torch.from_numpy(u_k)[None])
            x_c, y_c = (np.asarray(a).ravel() for a in step(x_c, u_k, p))
            pairs += [(f"x_{k + 1}", x_c, x_t[0].numpy(), scale), (f"y_{k + 1}", y_c, y_t[0].numpy(), None)]
    for what, got, want, floor in pairs:
        denominator = np.abs(want) if floor is None else np.maximum(np.abs(want), floor)
        err = float(np.max(np.abs(got - want) / np.maximum(denominator, 1e-300)))
        if not err <= _VERIFY_RTOL:
            raise ExportError(f"the exported hybrid's {what} differs from the torch model by {err:.3g} (relative, "
                              f"expected <= {_VERIFY_RTOL:g}); the model computes something the export does not "
                              "reproduce. Export a model built by nnfmu.hybrid")


def hybrid_casadi_model(model: HybridStepModel, *, name: str | None = None) -> CasadiModel:
    """The hybrid as a :class:`~nnfmu.system.CasadiModel`; the physical parameters (trained values) are parameters.

    A hybrid trained with an init window of ``N > 1`` samples (``config.init_window``) gets the estimator it trained
    with (:func:`~nnfmu.physics.initial_state.with_init_window`): its FMU takes the window as parameters.
    """
    init, step = hybrid_to_casadi(model)
    meta, prov = model.meta, model.provenance or {}
    spec = SystemSpec(
        name=to_c_identifier(name or meta.get("name") or f"{model.physics.name}_hybrid"),
        Ts=model.Ts,
        inputs=stored_input_variables(meta, model.u_mean, model.u_std),  # with the training range
        outputs=with_starts([Variable(ch["name"], ch.get("unit", ""), ch.get("description", ""))
                             for ch in meta["outputs"]], model.y_mean),  # y0: the training mean
        parameters=model.physics_variables(),
        description=f"hybrid model exported by nnfmu: {model.physics.description} + neural correction "
                    f"({model.config.correction})",
        source={"kind": "nnfmu-hybrid", "arch": model.config.arch, "model_config": model.config.to_dict(),
                "physics_parameters": model.physics_parameter_values(), "checkpoint": prov.get("checkpoint"),
                "best_epoch": prov.get("best_epoch"), "summary": prov.get("summary", {}),
                "dataset_source": prov.get("dataset_source", meta.get("source", {}))},
    )
    exported = CasadiModel(init, step, spec, continuous=hybrid_dynamics(model))
    if model.config.init_window == 1:
        return exported
    # trained from its estimator's start (nnfmu.hybrid.initial_state): the FMU estimates it the same way
    return with_init_window(exported, model.config.init_window, y_scale=model.y_std.detach().double().numpy(),
                            x_scale=model.physics.state_scales or None)


def hybrid_dynamics(model: HybridStepModel) -> ContinuousDynamics | None:
    """``xdot = ode(x, u, p) + delta(x, u)`` and the physics' output map, for a derivative correction.

    This is the ODE that the hybrid's RK4 step integrates, so its FMU offers Model Exchange too. A step
    correction (``x_next = RK4(x) + Ts * delta``) is a discrete-time residual tied to Ts; no ODE has it as
    its discretisation, so such a hybrid stays co-simulation only (None).
    """
    if model.config.correction != "derivative":
        return None
    system, delta = model.physics, _delta_function(model)
    x, u, p = ca.MX.sym("x", model.n_x), ca.MX.sym("u", model.config.n_u), ca.MX.sym("p", len(system.parameters))
    ode = ca.Function("ode", [x, u, p], [system.ode(x, u, p) + delta(x, u)], ["x", "u", "p"], ["xdot"])
    output = ca.Function("output", [x, p], [system.output(x, p)], ["x", "p"], ["y"])
    return ContinuousDynamics(ode=ode, output=output, states=system.states, nominals=system.state_scales)
