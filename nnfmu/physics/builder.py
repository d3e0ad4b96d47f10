"""Write a physics model in a few lines: :class:`ModelBuilder` turns CasADi expressions into a PhysicsSystem.

A model file (docs/own-physics.md) defines a top-level function that returns a model::

    import casadi as ca
    from nnfmu.physics import ModelBuilder

    def tank():
        m = ModelBuilder("tank", Ts=1.0, n_sub=2, description="one tank drained through a hole")
        h = m.state("h", "m", "water level", scale=0.3)
        q = m.input("q", "m3/s", "inflow", min=0.0, max=2e-4)
        A = m.parameter("A", 0.015, "m2", "cross-section", free=False)
        a = m.parameter("a", 5e-5, "m2", "outlet area", min=1e-6, max=1e-3)
        m.ode(h=(q - a * ca.sqrt(2 * 9.81 * ca.fmax(h, 0))) / A)
        m.output("level", "m", "measured level", h)
        return m.build()

Every declaration returns a CasADi SX scalar (a state, an input, a parameter, or, for an output, the
*measured* value of that output at the start of a record). The initial-state rule, :meth:`ModelBuilder.init`,
writes each state from those measured values, the first inputs and the parameters; a state left out starts at
the output that is exactly that state (``level`` above is ``h``), else at its ``start``. :meth:`build` checks
the sizes, the bounds and that the model is finite at a plausible point (:func:`check_system`).
"""

from __future__ import annotations

import dataclasses
import re
from types import SimpleNamespace

import casadi as ca
import numpy as np

from nnfmu.errors import ConfigError, ShapeError
from nnfmu.physics.base import PhysicsSystem, check_model_header, parameter_variables
from nnfmu.system import Variable

__all__ = ["ModelBuilder", "check_system"]


class ModelBuilder:
    """Collects the states, inputs, parameters, outputs, ODE and initial-state rule of one physics model.

    Parameters
    ----------
    name : str
        A C identifier; the FMU's model name.
    Ts : float
        Sample time of the data and of the discrete model, in seconds.
    n_sub : int
        RK4 sub-steps per ``Ts`` (the step is ``Ts / n_sub``; choose it so that RK4 is stable and accurate).
    description : str
        One line for humans.
    settle_time : float, optional
        A typical settling time in seconds; ``nnfmu generate`` scales its excitation signals to it
        (default ``50 * Ts``). Stored in the model's ``source``.
    source : dict, optional
        Provenance, JSON-serialisable (merged into the model's ``source``).
    """

    def __init__(self, name: str, *, Ts: float, n_sub: int = 1, description: str = "",
                 settle_time: float | None = None, source: dict | None = None) -> None:
        if not (isinstance(Ts, (int, float)) and np.isfinite(Ts) and Ts > 0):
            raise ConfigError(f"{name}: Ts must be a positive number of seconds, got {Ts!r}")
        check_model_header(name, n_sub)  # before a CasADi function is named after it, or RK4 unrolled n_sub times
        if settle_time is not None and not (np.isfinite(settle_time) and settle_time > 0):
            raise ConfigError(f"{name}: settle_time must be a positive number of seconds, got {settle_time!r}")
        self.name, self.Ts, self.n_sub, self.description = name, float(Ts), n_sub, description
        self._source = dict(source or {})
        if settle_time is not None:
            self._source["settle_time"] = float(settle_time)
        self._states: list[tuple[Variable, ca.SX, float]] = []
        self._inputs: list[tuple[Variable, ca.SX]] = []
        self._parameters: list[tuple[Variable, ca.SX, bool]] = []
        self._outputs: list[tuple[Variable, ca.SX, ca.SX]] = []
        self._xdot: dict[str, ca.SX] | None = None
        self._init: dict[str, ca.SX] = {}

    def _new(self, kind: str, name: str) -> None:
        """States have their own names (an FMU calls them ``x.<name>``); inputs, outputs and parameters share one."""
        group = self._states if kind == "state" else [*self._inputs, *self._parameters, *self._outputs]
        if name in {v.name for v, *_ in group}:
            raise ShapeError(f"{self.name}: {kind} {name!r} reuses a name; "
                             + ("every state needs its own" if kind == "state" else
                                "every input, output and parameter needs its own (a state may share one)"))

    def state(self, name: str, unit: str = "", description: str = "", *, scale: float = 1.0,
              start: float = 0.0) -> ca.SX:
        """A state (its typical magnitude ``scale``; ``start`` where the init rule says nothing); its symbol."""
        self._new("state", name)
        sym = ca.SX.sym(name)
        self._states.append((Variable(name, unit, description, float(start)), sym, float(scale)))
        return sym

    def input(self, name: str, unit: str = "", description: str = "", *, min: float | None = None,
              max: float | None = None, start: float | None = None) -> ca.SX:
        """An input with its valid range ``[min, max]`` (the FMU declares it; ``generate`` excites within it).

        ``start``: the FMU's value before an importer sets one; default 0, or the range's middle (its one bound)
        where the range excludes 0. A start outside the range is refused.
        """
        self._new("input", name)
        sym = ca.SX.sym(name)
        variable = Variable(name, unit, description, _default_start(min, max) if start is None else float(start),
                            min, max)
        _check_bounds(self.name, variable, "input", "start value", "start= to a value inside them")
        self._inputs.append((variable, sym))
        return sym

    def parameter(self, name: str, nominal: float, unit: str = "", description: str = "", *,
                  min: float | None = None, max: float | None = None, free: bool = True) -> ca.SX:
        """A physical parameter: its nominal value, bounds, and whether a grey-box fit estimates it by default."""
        self._new("parameter", name)
        variable = Variable(name, unit, description, float(nominal), min, max)
        _check_bounds(self.name, variable)
        sym = ca.SX.sym(name)
        self._parameters.append((variable, sym, bool(free)))
        return sym

    def parameters_from(self, params) -> SimpleNamespace:
        """Every tunable field of a parameter dataclass (:func:`nnfmu.physics.param`) as parameters, all free.

        Returns the fields by name (a tuple field as a list of symbols, a non-tunable field as its value),
        as :func:`nnfmu.physics.unpack_parameters` does.
        """
        symbols = {v.name: self.parameter(v.name, v.start, v.unit, v.description, min=v.min, max=v.max)
                   for v in parameter_variables(params)}
        values = {}
        for f in dataclasses.fields(params):
            value = getattr(params, f.name)
            if not f.metadata.get("tunable", False):
                values[f.name] = value
            elif isinstance(value, tuple):
                values[f.name] = [symbols[f"{f.name}{j + 1}"] for j in range(len(value))]
            else:
                values[f.name] = symbols[f.name]
        return SimpleNamespace(**values)

    def output(self, name: str, unit: str, description: str, expr, *, start: float = 0.0,
               min: float | None = None, max: float | None = None) -> ca.SX:
        """A measured output ``y = expr(x, p)``; returns the symbol of its *measured* value at the start (for
        :meth:`init`). ``start`` is the FMU's default ``<name>_start``; ``min``/``max`` its expected range."""
        self._new("output", name)
        expr = ca.SX(expr)
        if expr.shape != (1, 1):
            raise ShapeError(f"{self.name}: output {name!r} is {expr.shape[0]}x{expr.shape[1]}, expected a scalar; "
                             f"declare one output per measured channel")
        sym = ca.SX.sym(f"{name}_0")
        self._outputs.append((Variable(name, unit, description, float(start), min, max), expr, sym))
        return sym

    @property
    def x(self) -> ca.SX:
        """The states as one column ``(n_x, 1)``, in declaration order."""
        return ca.vertcat(*[s for _, s, _ in self._states])

    @property
    def u(self) -> ca.SX:
        """The inputs as one column ``(n_u, 1)``."""
        return ca.vertcat(*[s for _, s in self._inputs])

    def ode(self, xdot=None, /, **by_state) -> None:
        """The right-hand side: a column ``(n_x, 1)`` in state order, or one expression per state by name."""
        names = [v.name for v, _, _ in self._states]
        if xdot is not None and by_state:
            raise ShapeError(f"{self.name}: give the ODE as one column or by state name, not both")
        if xdot is not None:
            xdot = self._as_sx(xdot, "the ODE", f"a column of {len(names)} derivatives, one per state")
            if xdot.shape != (len(names), 1):
                raise ShapeError(f"{self.name}: the ODE gives {xdot.shape[0]}x{xdot.shape[1]} derivatives for "
                                 f"{len(names)} states ({', '.join(names)}); give one per state, in that order")
            by_state = {n: xdot[i] for i, n in enumerate(names)}
        unknown, missing = sorted(set(by_state) - set(names)), [n for n in names if n not in by_state]
        if unknown:
            raise ShapeError(f"{self.name}: the ODE names {', '.join(unknown)}, which are not states; the states are "
                             f"{', '.join(names)}")
        if missing:
            raise ShapeError(f"{self.name}: the ODE has no derivative for {', '.join(missing)}; give one for every "
                             f"state ({', '.join(names)})")
        by_state = {n: self._as_sx(e, f"the ODE's derivative of {n}", "one scalar expression per state")
                    for n, e in by_state.items()}
        for n, e in by_state.items():
            if e.shape != (1, 1):
                raise ShapeError(f"{self.name}: the ODE's derivative of {n} is {e.shape[0]}x{e.shape[1]}, expected "
                                 f"1x1; give one scalar expression per state ({', '.join(names)})")
        self._xdot = {n: by_state[n] for n in names}

    def _as_sx(self, value, what: str, expected: str) -> ca.SX:
        """``value`` as CasADi SX (a list or tuple stacked as a column); one line naming ``what`` if it is none."""
        try:
            return ca.vertcat(*value) if isinstance(value, (list, tuple)) else ca.SX(value)
        except (NotImplementedError, TypeError, RuntimeError):  # CasADi lists every constructor's prototype
            raise ShapeError(f"{self.name}: {what} is a {type(value).__name__}, not a CasADi expression or number; "
                             f"give {expected}") from None

    def init(self, **by_state) -> None:
        """The initial-state rule: ``state=expr`` of the measured outputs, the first inputs and the parameters."""
        names = [v.name for v, _, _ in self._states]
        unknown = sorted(set(by_state) - set(names))
        if unknown:
            raise ShapeError(f"{self.name}: init names {', '.join(unknown)}, which are not states "
                             f"({', '.join(names)})")
        self._init.update({n: ca.SX(e) for n, e in by_state.items()})

    def build(self) -> PhysicsSystem:
        """The :class:`PhysicsSystem`, checked (sizes, bounds, finite at a plausible point)."""
        system = self._system()
        check_system(system)
        return system

    def _system(self) -> PhysicsSystem:
        if not self._states or not self._outputs:
            raise ShapeError(f"{self.name}: a model needs at least one state and one output")
        if self._xdot is None:
            raise ShapeError(f"{self.name}: no ODE; call ode(...) with a derivative for every state")
        x, u = self.x, self.u if self._inputs else ca.SX(0, 1)
        p = ca.vertcat(*[s for _, s, _ in self._parameters]) if self._parameters else ca.SX(0, 1)
        y0 = ca.vertcat(*[s for _, _, s in self._outputs])
        n = self.name
        ode = self._function("ode", [x, u, p], ca.vertcat(*self._xdot.values()), ["x", "u", "p"], "xdot",
                             "states, inputs and parameters")
        output = self._function("output", [x, p], ca.vertcat(*[e for _, e, _ in self._outputs]), ["x", "p"], "y",
                                "states and parameters (no inputs)")
        init = self._function("init_state", [y0, u, p], ca.vertcat(*self._initial_states()), ["y0", "u0", "p"],
                              "x0", "the measured outputs (the symbols output() returns), inputs and parameters")
        free = tuple(v.name for v, _, f in self._parameters if f)
        return PhysicsSystem(
            name=n, Ts=self.Ts, n_sub=self.n_sub, ode=ode, output=output, init_state=init,
            states=tuple(v for v, _, _ in self._states), inputs=tuple(v for v, _ in self._inputs),
            outputs=tuple(v for v, _, _ in self._outputs), parameters=tuple(v for v, _, _ in self._parameters),
            state_scales=tuple(s for _, _, s in self._states), description=self.description,
            source=dict(self._source), free_parameters=None if len(free) == len(self._parameters) else free)

    def _function(self, what: str, args: list, result, names: list[str], out: str, allowed: str) -> ca.Function:
        try:
            return ca.Function(f"{self.name}_{what}", args, [result], names, [out])
        except RuntimeError as exc:
            found = re.search(r"variables (\[.*?\]) are free", str(exc))
            free = found.group(1) if found else str(exc).splitlines()[-1]
            raise ShapeError(f"{self.name}: the {what} uses symbols it cannot see ({free}); it may use only "
                             f"{allowed}") from None

    def _initial_states(self) -> list[ca.SX]:
        """Each state's initial value: the init rule, else the output that is exactly it, else its start."""
        values = []
        for v, s, _ in self._states:
            measured = [y0 for _, expr, y0 in self._outputs if ca.is_equal(expr, s)]
            values.append(self._init.get(v.name, measured[0] if measured else ca.SX(v.start)))
        return values


def _default_start(low: float | None, high: float | None) -> float:
    """0 where the range holds it, else the range's middle, or its one bound."""
    if (low is None or low <= 0) and (high is None or high >= 0):
        return 0.0
    if low is not None and high is not None:
        return 0.5 * (low + high)
    return float(low if low is not None else high)


def _check_bounds(model: str, v: Variable, kind: str = "parameter", value: str = "nominal value",
                  fix: str = "the nominal value") -> None:
    low, high = -np.inf if v.min is None else v.min, np.inf if v.max is None else v.max
    if not (np.isfinite(v.start) and low <= v.start <= high):
        raise ConfigError(f"{model}: {kind} {v.name!r} has {value} {v.start:g} outside its bounds "
                          f"[{low:g}, {high:g}]; widen the bounds or change {fix}")


def _plausible(v: Variable) -> float:
    """The mid-point of a variable's range, else its start."""
    return 0.5 * (v.min + v.max) if v.min is not None and v.max is not None else v.start


def check_system(system: PhysicsSystem) -> None:
    """Refuse a model whose parameters lie outside their bounds or that is not finite where it should work.

    The plausible point: the inputs and outputs at the mid-points of their ranges (at their ``start``
    where a range is open), the state the init rule builds from them, the nominal parameters.
    """
    for v in system.parameters:
        _check_bounds(system.name, v)
    for v in system.inputs:  # a JSON document's inputs too: the FMU refuses a start outside the range
        _check_bounds(system.name, v, "input", "start value", "its start to a value inside them")
    u = np.array([_plausible(v) for v in system.inputs], dtype=float)
    y0 = np.array([_plausible(v) for v in system.outputs], dtype=float)
    p = system.parameter_values()
    x0 = np.asarray(system.init_state(y0, u, p), dtype=float).ravel()
    where = f"at u = {u.tolist()}, y0 = {y0.tolist()} and the nominal parameters"
    for what, values, names in (("init_state", x0, system.states),
                                ("ode", np.asarray(system.ode(x0, u, p), dtype=float).ravel(), system.states),
                                ("output", np.asarray(system.output(x0, p), dtype=float).ravel(), system.outputs)):
        bad = [v.name for v, value in zip(names, values, strict=True) if not np.isfinite(value)]
        if bad:
            raise ConfigError(f"{system.name}: {what} is NaN or Inf for {', '.join(bad)} {where} (state "
                              f"{x0.tolist()}); check the formulas (a division by zero, sqrt or log of a "
                              f"negative) and the nominal values")
