"""Trained torch networks -> CasADi ``(init, step)`` Functions with the same flat state.

::

    init, step = to_casadi(model)         # init(y0, u0) -> x0;  step(x, u) -> (x_next, y_next)
    cmodel = casadi_model(model)          # the pair + SystemSpec (name, Ts, units), for build_fmu

The functions work in physical units (normalisation is inside), include the
skip connection, treat dropout as the identity, and carry exactly the state
vector each architecture documents (its record's ``casadi_step`` and ``casadi_init``, e.g.
:mod:`nnfmu.networks.tcn.export` on the TCN's delay lines), so ``CasadiModel.simulate`` equals
``model.simulate`` (to about 1e-15 per step in float64). The graphs are MX
with the weights as dense constants (see :mod:`nnfmu.export.casadi_layers`).
Every export is checked numerically against the torch step; a model whose
computation ``to_casadi`` does not know raises :class:`~nnfmu.errors.ExportError`.
"""

from __future__ import annotations

import copy

import casadi as ca
import numpy as np
import torch

from nnfmu.errors import ExportError
from nnfmu.export import casadi_layers as nets
from nnfmu.export.ensemble import ensemble_to_casadi, inlined, with_y
from nnfmu.export.init_window import init_function
from nnfmu.identifiers import to_c_identifier
from nnfmu.models import EnsembleStepModel, StepModel, architectures
from nnfmu.models.linear_path import LinearPathStepModel, y_slot
from nnfmu.system import CasadiModel, SystemSpec, Variable
from nnfmu.valid_range import stored_input_variables, with_starts

_VERIFY_RTOL = 1e-9


def _check_modules(model: StepModel) -> None:
    """Every sub-module must be a layer the builders know; name the first one that is not."""
    for name, module in model.named_modules():
        if name and not isinstance(module, nets.SUPPORTED):
            raise nets.unsupported(name, module)


def to_casadi(model: StepModel, *, verify: bool = True) -> tuple[ca.Function, ca.Function]:
    """CasADi ``init(y0, u0) -> x0`` and ``step(x, u) -> (x_next, y_next)`` of a network, in physical units.

    Parameters
    ----------
    model : StepModel
        A model of a registered architecture (any dtype; weights are taken in float64): its record's
        ``casadi_step`` and ``casadi_init`` give the step and the initial state in normalised units
        (:mod:`nnfmu.models.architectures`), or its ``to_casadi`` the whole export (the hybrid: then the
        ports are ``init(y0, u0, p)`` and ``step(x, u, p)``, with ``p`` the physical parameters).
    verify : bool
        Compare one step of the result with the torch step from a random state (relative 1e-9).

    Raises
    ------
    ExportError
        For a layer or model class the builders do not know, or a failed verification.
    """
    if isinstance(model, EnsembleStepModel):
        init, step = ensemble_to_casadi(model, lambda member: to_casadi(member, verify=False))
        if verify:
            verify_export(model, init, step)
        return init, step
    if isinstance(model, LinearPathStepModel):
        init, step = _linear_path_to_casadi(model)
        if verify:
            verify_export(model, init, step)
        return init, step
    record = _record(model)
    if record.to_casadi is not None:  # an architecture with an export of its own (the hybrid)
        return record.get("to_casadi")(model, verify=verify)
    _check_modules(model)
    c = model.config
    x, u = ca.MX.sym("x", model.n_x), ca.MX.sym("u", c.n_u)
    u_mean, u_std, y_mean, y_std = (nets.dm(b) for b in (model.u_mean, model.u_std, model.y_mean, model.y_std))
    init = init_function(model, record.get("casadi_init"), u_mean, u_std, y_mean, y_std)
    x_next, yn_next = record.get("casadi_step")(model, x, (u - u_mean) / u_std)
    step = ca.Function("step", [x, u], [x_next, yn_next * y_std + y_mean], ["x", "u"], ["x_next", "y_next"])
    if verify:
        verify_export(model, init, step)
    return init, step


def _record(model: StepModel) -> architectures.Architecture:
    """The record of ``model``'s architecture; ExportError unless it says how to export it."""
    if not isinstance(model, StepModel):
        raise ExportError(f"cannot export a {type(model).__name__}; to_casadi exports the StepModels of "
                          "nnfmu.models and of the architectures registered with it")
    record = architectures.architecture(model.config.arch)
    if record.casadi_step is None and record.to_casadi is None:
        raise ExportError(f"the architecture {record.name!r} does not say how to export it: its record "
                          "(nnfmu.models.architectures.Architecture) needs casadi_step and casadi_init")
    return record


def _linear_path_to_casadi(model: LinearPathStepModel) -> tuple[ca.Function, ca.Function]:
    """The network's own Functions on its slice of the state, the linear path in normalised units beside them."""
    net_init, net_step = to_casadi(model.net, verify=False)
    c, m = model.config, model.net.n_x
    A, B, b, C, d, G, Ky, Ku, k0, alpha = (nets.dm(getattr(model, k)) for k in (
        "lin_A", "lin_B", "lin_b", "lin_C", "lin_d", "lin_G", "lin_Ky", "lin_Ku", "lin_k0", "alpha"))
    u_mean, u_std, y_mean, y_std = (nets.dm(b_) for b_ in (model.u_mean, model.u_std, model.y_mean, model.y_std))
    ins = [ca.MX.sym(net_init.name_in(i), net_init.sparsity_in(i)) for i in range(net_init.n_in())]
    yn0, un0 = (ins[0] - y_mean) / y_std, (ins[1] - u_mean) / u_std
    x0 = ca.vertcat(inlined(net_init, ins)[0], ca.mtimes(Ky, yn0) + ca.mtimes(Ku, un0) + k0)
    init = ca.Function("init", ins, [x0], net_init.name_in(), ["x0"])
    x, u = ca.MX.sym("x", model.n_x), ca.MX.sym("u", c.n_u)
    h_next, y_net = inlined(net_step, [x[:m], u])
    n = (y_net - y_mean) / y_std  # the network's raw output (its step de-normalises it)
    z_next = ca.mtimes(A, x[m:]) + ca.mtimes(B, (u - u_mean) / u_std) + b + ca.mtimes(G, n)
    yn = ca.mtimes(C, z_next) + d + alpha * n
    x_next = ca.vertcat(with_y(h_next, y_slot(model.net), yn), z_next)
    step = ca.Function("step", [x, u], [x_next, yn * y_std + y_mean], ["x", "u"], ["x_next", "y_next"])
    return init, step


def verify_export(model: StepModel, init: ca.Function, step: ca.Function, seed: int = 0) -> None:
    """Raise ExportError unless ``init`` and one ``step`` from a random state match the torch model."""
    bad = [k for k, t in model.state_dict().items() if t.is_floating_point() and not bool(torch.isfinite(t).all())]
    if bad:  # NaN weights would fail the comparison below with a misleading blame
        raise ExportError(f"the model's weights are not finite (NaN or inf in {', '.join(bad[:3])}): its training "
                          "diverged; retrain it with a lower learning rate (nnfmu train --lr, TrainConfig.lr)")
    ref = copy.deepcopy(model).double().eval()
    rng = np.random.default_rng(seed)
    c = model.config
    y0 = ref.y_mean.numpy() + ref.y_std.numpy() * rng.standard_normal(c.n_y)
    u0 = ref.u_mean.numpy() + ref.u_std.numpy() * rng.standard_normal(c.n_u)
    x = rng.standard_normal(model.n_x)
    past = [ref.y_mean.numpy() + ref.y_std.numpy() * rng.standard_normal((c.init_window - 1, c.n_y)),
            ref.u_mean.numpy() + ref.u_std.numpy() * rng.standard_normal((c.init_window - 1, c.n_u))]
    past_t = {"y_past": torch.from_numpy(past[0])[None], "u_past": torch.from_numpy(past[1])[None]} \
        if c.init_window > 1 else {}
    with torch.no_grad():
        x0_t = ref.init(torch.from_numpy(y0)[None], torch.from_numpy(u0)[None], **past_t)[0].numpy()
        xn_t, yn_t = (a[0].numpy() for a in ref.step(torch.from_numpy(x)[None], torch.from_numpy(u0)[None]))
    past_c = [p.ravel() for p in past] if c.init_window > 1 else []
    pairs = {"x0": (np.asarray(init(y0, u0, *past_c)).ravel(), x0_t)}
    xn_c, yn_c = step(x, u0)
    pairs["x_next"], pairs["y_next"] = (np.asarray(xn_c).ravel(), xn_t), (np.asarray(yn_c).ravel(), yn_t)
    for what, (got, want) in pairs.items():
        scale = max(float(np.max(np.abs(want))), 1e-300)
        err = float(np.max(np.abs(got - want))) / scale if got.size else 0.0
        if not err <= _VERIFY_RTOL:
            raise ExportError(f"the exported {what} differs from the torch model by {err:.3g} (relative, expected "
                              f"<= {_VERIFY_RTOL:g}); {type(model).__name__} computes something to_casadi does not "
                              "reproduce (an overridden method?). Export a model built by nnfmu.models")


def casadi_model(model: StepModel, *, name: str | None = None) -> CasadiModel:
    """The network as a :class:`~nnfmu.system.CasadiModel`: :func:`to_casadi` plus a SystemSpec from ``model.meta``.

    ``name`` (a C identifier) defaults to the meta's name; the spec's ``source``
    records the architecture, its config and the checkpoint's provenance. An architecture with an export
    of its own (the hybrid: its physical parameters become the spec's parameters) makes its own.
    """
    record = _record(model)
    if record.casadi_model is not None:
        return record.get("casadi_model")(model, name=name)
    init, step = to_casadi(model)
    meta = model.meta
    channels = [{k: ch[k] for k in ("name", "unit", "description") if k in ch} for ch in meta["outputs"]]
    spec = SystemSpec(
        name=to_c_identifier(name or meta.get("name") or f"{model.config.arch}_model"),
        Ts=float(meta["Ts"]),
        inputs=stored_input_variables(meta, model.u_mean, model.u_std),  # with the valid range
        outputs=with_starts([Variable(**ch) for ch in channels], model.y_mean),  # y0: the training mean
        description=f"{_what(model)} exported by nnfmu",
        source=_provenance(model),
        init_window=model.config.init_window,
    )
    return CasadiModel(init, step, spec)


def _what(model: StepModel) -> str:
    """``GRU network``, or for an ensemble ``ensemble of 3 networks (LSTM, RNN, LSTM), mean fed back``."""
    if isinstance(model, EnsembleStepModel):
        archs = ", ".join(m.config.arch.upper() for m in model.members)
        return f"ensemble of {len(model.members)} networks ({archs}), mean fed back"
    return f"{model.config.arch.upper()} network"


def _provenance(model: StepModel) -> dict:
    prov = model.provenance or {}
    train_config = prov.get("train_config") or {}
    return {"kind": "nnfmu-network", "arch": model.config.arch, "model_config": model.config.to_dict(),
            "checkpoint": prov.get("checkpoint"), "best_epoch": prov.get("best_epoch"),
            "strategy": train_config.get("strategy"), "summary": prov.get("summary", {}),
            "dataset_source": prov.get("dataset_source", model.meta.get("source", {}))}
