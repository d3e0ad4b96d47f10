"""What every physics reference model shares: :class:`PhysicsSystem` and the parameter helpers.

A physics model is a continuous-time ODE ``xdot = ode(x, u, p)`` with an
output map ``y = output(x, p)`` and a rule ``x0 = init_state(y0, u0, p)`` that
builds a plausible state from a measured output. :meth:`PhysicsSystem.model`
discretises it with fixed-step RK4 (:mod:`nnfmu.physics.rk4`) into the
toolkit's one model contract, the ``(init, step)`` pair of
:class:`nnfmu.system.CasadiModel`, which the FMU builder and the scoring take.

Physical parameters live in frozen dataclasses (``ValveParams``,
``ArmParams``) whose fields carry ``unit``, ``description`` and ``tunable``
metadata (see :func:`param`). Tunable fields become the ``p`` vector of the
ODE, in field order, with tuple fields flattened as ``name1, name2, ...``;
non-tunable fields (geometry that nobody re-identifies) are baked in as
constants.
"""

from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass, field
from types import SimpleNamespace

import casadi as ca
import numpy as np

from nnfmu.errors import ConfigError, ShapeError
from nnfmu.identifiers import to_c_identifier
from nnfmu.limits import MAX_MODEL_NAME, MAX_RK4_SUBSTEPS
from nnfmu.physics.rk4 import rk4_function
from nnfmu.system import CasadiModel, ContinuousDynamics, SystemSpec, Variable

__all__ = ["PhysicsSystem", "param", "parameter_variables", "unpack_parameters", "params_to_json"]


def param(default, unit: str, description: str, *, tunable: bool = True, min: float | None = None,
          max: float | None = None):
    """A dataclass field for a physical parameter: its default, unit and one-line description.

    ``tunable=False`` marks structural constants (e.g. DH geometry) that are
    baked into the ODE instead of going through its ``p`` port. ``min``/``max`` bound every entry (a
    friction coefficient: ``min=0``): the grey-box fit and a hybrid's trained parameters stay inside, and
    the FMU declares them.
    """
    return field(default=default, metadata={"unit": unit, "description": description, "tunable": tunable,
                                            "min": min, "max": max})


def _tunable_fields(params) -> list[dataclasses.Field]:
    return [f for f in dataclasses.fields(params) if f.metadata.get("tunable", False)]


def parameter_variables(params) -> tuple[Variable, ...]:
    """The ``p`` vector's entries as Variables (name, unit, description, start = nominal value)."""
    out = []
    for f in _tunable_fields(params):
        value = getattr(params, f.name)
        unit, desc = f.metadata["unit"], f.metadata["description"]
        bounds = f.metadata.get("min"), f.metadata.get("max")
        if isinstance(value, tuple):
            out += [Variable(f"{f.name}{j + 1}", unit, f"{desc} (joint {j + 1})", float(v), *bounds)
                    for j, v in enumerate(value)]
        else:
            out.append(Variable(f.name, unit, desc, float(value), *bounds))
    return tuple(out)


def unpack_parameters(params, p) -> SimpleNamespace:
    """Name the entries of a parameter vector ``p`` (SX or DM, ``(n_p, 1)``) after ``params``' fields.

    Tunable fields come from ``p`` (a tuple field becomes a list of entries);
    non-tunable fields keep their Python values from ``params``.
    """
    n_p = len(parameter_variables(params))
    if p.shape[0] != n_p:
        raise ShapeError(f"parameter vector has {p.shape[0]} entries, expected {n_p} for {type(params).__name__}")
    values, k = {}, 0
    for f in dataclasses.fields(params):
        value = getattr(params, f.name)
        if not f.metadata.get("tunable", False):
            values[f.name] = value
        elif isinstance(value, tuple):
            values[f.name] = [p[k + j] for j in range(len(value))]
            k += len(value)
        else:
            values[f.name] = p[k]
            k += 1
    return SimpleNamespace(**values)


def params_to_json(params) -> dict:
    """``params`` as a JSON-serialisable dict (tuples become lists)."""
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in dataclasses.asdict(params).items()}


#: A model's name: it prefixes the CasADi functions (``<name>_ode``) and names the FMU and its C symbols, so it
#: starts with a letter and holds ASCII letters, digits and single underscores between them (CasADi's rule).
MODEL_NAME = re.compile(r"[A-Za-z][A-Za-z0-9]*(?:_[A-Za-z0-9]+)*")


def check_model_header(name, n_sub) -> None:
    """A model's name follows :data:`MODEL_NAME`, and ``n_sub`` is from 1 to ``nnfmu.limits.MAX_RK4_SUBSTEPS``."""
    if isinstance(name, str) and len(name) > MAX_MODEL_NAME:
        raise ConfigError(f"model name {name[:20]}... has {len(name)} characters, above nnfmu's limit of "
                          f"{MAX_MODEL_NAME} (nnfmu.limits.MAX_MODEL_NAME): it names the FMU's files; shorten it")
    if not isinstance(name, str) or not MODEL_NAME.fullmatch(name):
        fix = re.sub(r"_+", "_", to_c_identifier(str(name)))
        raise ConfigError(f"model name {name!r} is not valid: it names the FMU and its C functions, so it starts with "
                          f"a letter and holds only ASCII letters, digits and single underscores; e.g. {fix!r}")
    if isinstance(n_sub, bool) or not isinstance(n_sub, int) or not 1 <= n_sub <= MAX_RK4_SUBSTEPS:
        raise ConfigError(f"{name}: n_sub must be a whole number from 1 to {MAX_RK4_SUBSTEPS:,} (nnfmu.limits."
                          f"MAX_RK4_SUBSTEPS), got {n_sub!r}; give the RK4 sub-steps per sample in that range")


def _check_ports(fn: ca.Function, ins: list[str], outs: list[str], what: str) -> None:
    if fn.name_in() != ins or fn.name_out() != outs:
        raise ShapeError(f"{what} has ports {fn.name_in()} -> {fn.name_out()}, expected {ins} -> {outs}")


@dataclass(frozen=True, kw_only=True)
class PhysicsSystem:
    """A continuous-time physics model with named, unit-carrying variables.

    Attributes
    ----------
    name : str
        Model name, a C identifier (becomes the FMU's model identifier).
    Ts : float
        Sample time of the data and of :meth:`model`, in seconds.
    n_sub : int
        Default number of RK4 sub-steps per ``Ts`` used by :meth:`model`.
    ode : casadi.Function
        SX Function ``ode(x[n_x], u[n_u], p[n_p]) -> xdot[n_x]``.
    output : casadi.Function
        ``output(x, p) -> y[n_y]``, in the dataset's units.
    init_state : casadi.Function
        ``init_state(y0, u0, p) -> x0``: a state consistent with a measured output (velocities zero).
    states, inputs, outputs, parameters : tuple of Variable
        Names and units; ``parameters[i].start`` is the nominal value of ``p[i]``.
    state_scales : tuple of float
        Typical magnitude of each state (e.g. for normalising a learned correction of ``xdot``).
    description : str
        One line for humans.
    source : dict
        Provenance and the parameter set, JSON-serialisable.
    free_parameters : tuple of str, optional
        Names of the parameters a grey-box fit estimates by default (None: all of them). Bounds
        are each parameter's ``min`` / ``max``; its ``start`` is the nominal value.
    """

    name: str
    Ts: float
    n_sub: int
    ode: ca.Function
    output: ca.Function
    init_state: ca.Function
    states: tuple[Variable, ...]
    inputs: tuple[Variable, ...]
    outputs: tuple[Variable, ...]
    parameters: tuple[Variable, ...]
    state_scales: tuple[float, ...] = ()
    description: str = ""
    source: dict = field(default_factory=dict)
    free_parameters: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        check_model_header(self.name, self.n_sub)
        _check_ports(self.ode, ["x", "u", "p"], ["xdot"], f"{self.name} ode")
        _check_ports(self.output, ["x", "p"], ["y"], f"{self.name} output")
        _check_ports(self.init_state, ["y0", "u0", "p"], ["x0"], f"{self.name} init_state")
        sizes = {"ode x": (self.ode.size1_in(0), len(self.states)),
                 "ode u": (self.ode.size1_in(1), len(self.inputs)),
                 "ode p": (self.ode.size1_in(2), len(self.parameters)),
                 "output y": (self.output.size1_out(0), len(self.outputs))}
        for what, (got, want) in sizes.items():
            if got != want:
                raise ShapeError(f"{self.name}: {what} has {got} entries but {want} variables are named")
        if self.state_scales and len(self.state_scales) != len(self.states):
            raise ShapeError(f"{self.name}: {len(self.state_scales)} state scales for {len(self.states)} states")
        names = [v.name for v in self.parameters]
        unknown = sorted(set(self.free_parameters or ()) - set(names))
        if unknown:
            raise ShapeError(f"{self.name}: free parameter(s) {', '.join(unknown)} are not among its parameters "
                             f"({', '.join(names)})")

    @property
    def n_x(self) -> int:
        return len(self.states)

    def parameter_values(self) -> np.ndarray:
        """Nominal parameter vector, shape ``(n_p,)``."""
        return np.array([v.start for v in self.parameters], dtype=float)

    def spec(self, *, expose_parameters: bool = True) -> SystemSpec:
        """The :class:`SystemSpec` of :meth:`model` (parameters only when exposed)."""
        return SystemSpec(name=self.name, Ts=self.Ts, inputs=self.inputs, outputs=self.outputs,
                          parameters=self.parameters if expose_parameters else (),
                          description=self.description, source=dict(self.source))

    def model(self, *, n_sub: int | None = None, expose_parameters: bool = True) -> CasadiModel:
        """The RK4-discretised ``(init, step)`` pair, code-generable.

        Parameters
        ----------
        n_sub : int, optional
            RK4 sub-steps per ``Ts`` (default :attr:`n_sub`).
        expose_parameters : bool
            True: ``init(y0, u0, p)`` and ``step(x, u, p)`` take the physical
            parameters as a ``p`` port (tunable FMU parameters, ``spec.parameters``).
            False: the nominal values are baked in and the ports are ``(y0, u0)``, ``(x, u)``.
            A model without parameters has no ``p`` port either way.
        """
        n_sub = self.n_sub if n_sub is None else n_sub
        expose_parameters = expose_parameters and bool(self.parameters)
        advance = rk4_function(self.ode, Ts=self.Ts, n_sub=n_sub, name=f"{self.name}_rk4")
        sym = ca.SX if advance.is_a("SXFunction") else ca.MX
        x, u = sym.sym("x", self.n_x), sym.sym("u", len(self.inputs))
        y0, p_sym = sym.sym("y0", len(self.outputs)), sym.sym("p", len(self.parameters))
        p = p_sym if expose_parameters else ca.DM(self.parameter_values())
        x_next = advance(x, u, p)
        y_next = self.output(x_next, p)
        x0 = self.init_state(y0, u, p)
        extra, extra_names = ([p_sym], ["p"]) if expose_parameters else ([], [])
        init = ca.Function("init", [y0, u] + extra, [x0], ["y0", "u0"] + extra_names, ["x0"])
        step = ca.Function("step", [x, u] + extra, [x_next, y_next], ["x", "u"] + extra_names,
                           ["x_next", "y_next"])
        return CasadiModel(init=init, step=step, spec=self.spec(expose_parameters=expose_parameters),
                           continuous=self.dynamics(expose_parameters=expose_parameters))

    def dynamics(self, *, expose_parameters: bool = True) -> ContinuousDynamics:
        """The ODE and output map that :meth:`model` discretises (its FMU's Model Exchange interface).

        ``ode(x, u(, p)) -> xdot`` and ``output(x(, p)) -> y``; ``expose_parameters`` as in :meth:`model`.
        """
        x, u, p_sym = ca.SX.sym("x", self.n_x), ca.SX.sym("u", len(self.inputs)), ca.SX.sym("p", len(self.parameters))
        expose_parameters = expose_parameters and bool(self.parameters)
        p = p_sym if expose_parameters else ca.DM(self.parameter_values())
        extra, extra_names = ([p_sym], ["p"]) if expose_parameters else ([], [])
        ode = ca.Function("ode", [x, u] + extra, [self.ode(x, u, p)], ["x", "u"] + extra_names, ["xdot"])
        output = ca.Function("output", [x] + extra, [self.output(x, p)], ["x"] + extra_names, ["y"])
        return ContinuousDynamics(ode=ode, output=output, states=self.states, nominals=self.state_scales)
