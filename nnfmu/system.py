"""The one model contract every stage meets: a discrete-time ``(init, step)`` pair.

docs/design.md's "one idea": the networks, the linear baseline, the physics models
(discretised with a fixed-step RK4) and hybrids all reduce to::

    init(y0, u0)     -> x0                 # (p) optional parameter vector as a 3rd input;
                                           # (y_past, u_past) last, for an init window (below)
    step(x, u)       -> (x_next, y_next)   # one sample period Ts; y_next is y(t + Ts)

as CasADi Functions with exactly those port names. :class:`CasadiModel` bundles
the pair with a :class:`SystemSpec` (name, Ts, named and unit-carrying inputs,
outputs and parameters). The FMU builder takes nothing else, and
:meth:`CasadiModel.simulate` is the reference free run that FMUs are tested
against.

Conventions
-----------
- No direct feedthrough: ``y(t0) = y0``; ``y[k+1]`` depends on ``u[0..k]``.
- ``simulate(u, y0)`` returns ``N`` rows for ``N`` input rows; ``u[N-1]`` is
  not used (it would only influence ``y[N]``).
- Everything is in physical units; normalisation lives inside the functions.
- A model with an init window of ``N > 1`` samples (``spec.init_window``) also takes the
  ``N - 1`` samples before ``y0`` and ``u0``: ``init(y0, u0[, p], y_past, u_past)`` with
  ``y_past`` ``((N-1) n_y,)`` and ``u_past`` ``((N-1) n_u,)``, oldest sample first. Without
  them the plant is taken at rest: ``y0`` and ``u0`` repeated.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import casadi as ca
import numpy as np

from nnfmu.errors import ShapeError
from nnfmu.identifiers import is_c_identifier

@dataclass(frozen=True)
class Variable:
    """A named scalar of an exported model: an input, output or parameter.

    ``name`` must be a C identifier; ``start`` is the default value of a
    parameter or an input, and for an output that of its ``<name>_start``
    parameter, the initial output y0 (docs/fmu.md). ``min`` and ``max`` bound the
    valid values of an input, in its unit: the FMU declares them and warns
    when an input leaves them (see docs/fmu.md). None: unbounded on that side.
    """

    name: str
    unit: str = ""
    description: str = ""
    start: float = 0.0
    min: float | None = None
    max: float | None = None

    def __post_init__(self) -> None:
        if not is_c_identifier(self.name):
            raise ShapeError(f"variable name {self.name!r} is not a C identifier; use ASCII letters, digits, '_'")
        for bound in ("min", "max"):
            value = getattr(self, bound)
            if value is not None and not np.isfinite(value):
                raise ShapeError(f"{bound} of variable {self.name!r} is {value!r}; give a finite bound or None")
        if self.min is not None and self.max is not None and self.min > self.max:
            raise ShapeError(f"variable {self.name!r} has min {self.min!r} > max {self.max!r}; swap them")


def _as_variable(v) -> Variable:
    if isinstance(v, Variable):
        return v
    if hasattr(v, "name") and hasattr(v, "unit"):  # nnfmu.data.Channel
        return Variable(v.name, v.unit, getattr(v, "description", ""))
    if isinstance(v, str):
        return Variable(v)
    if isinstance(v, dict):
        return Variable(**v)
    raise ShapeError(f"expected a Variable, a Channel, a name or a dict, got {v!r}")


@dataclass(frozen=True)
class SystemSpec:
    """What an exported model is: its name, sample time and named variables.

    Attributes
    ----------
    name : str
        Model name; a C identifier (it becomes the FMU's modelIdentifier).
    Ts : float
        Sample time in seconds.
    inputs, outputs : tuple of Variable
        ``n_u`` inputs and ``n_y`` outputs, in the order of the ``u`` and ``y`` ports.
    parameters : tuple of Variable
        ``n_p`` tunable parameters fed to the optional ``p`` port, with default ``start`` values.
    description : str
        One line for humans (the FMU's description).
    source : dict
        Provenance (checkpoint, dataset, training figures), JSON-serialisable.
    init_window : int
        ``N``: samples ``init`` sees (1: ``y0`` and ``u0``; more: also ``y_past``, ``u_past``).
    """

    name: str
    Ts: float
    inputs: tuple[Variable, ...]
    outputs: tuple[Variable, ...]
    parameters: tuple[Variable, ...] = ()
    description: str = ""
    source: dict = field(default_factory=dict)
    init_window: int = 1

    def __post_init__(self) -> None:
        if isinstance(self.init_window, bool) or not isinstance(self.init_window, int) or self.init_window < 1:
            raise ShapeError(f"init_window must be a positive integer number of samples, got {self.init_window!r}")
        for attr in ("inputs", "outputs", "parameters"):
            object.__setattr__(self, attr, tuple(_as_variable(v) for v in getattr(self, attr)))
        if not is_c_identifier(self.name):
            raise ShapeError(f"model name {self.name!r} is not a C identifier; use ASCII letters, digits, '_'")
        if not (np.isfinite(self.Ts) and self.Ts > 0):
            raise ShapeError(f"sample time Ts must be positive seconds, got {self.Ts!r}")
        names = [v.name for v in self.inputs + self.outputs + self.parameters]
        names += [f"{v.name}_start" for v in self.outputs]
        if self.init_window > 1:  # the FMU's init-window parameters (nnfmu.window_names)
            names += [f"{v.name}_past" for v in self.outputs + self.inputs]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ShapeError(f"variable names must be unique (outputs also claim '<name>_start', and with an init "
                             f"window every channel '<name>_past'); repeated: {dup}")

    @property
    def n_u(self) -> int:
        return len(self.inputs)

    @property
    def n_y(self) -> int:
        return len(self.outputs)

    @property
    def n_p(self) -> int:
        return len(self.parameters)


@dataclass(frozen=True)
class ContinuousDynamics:
    """The ODE that a continuous-time model's ``step`` discretises; its FMU also offers Model Exchange.

    ``ode(x[n_x], u[n_u](, p[n_p])) -> xdot[n_x]`` (state units per second) and
    ``output(x[n_x](, p[n_p])) -> y[n_y]``, on the same state ``x`` as the model's
    ``init`` and ``step`` (so ``x0 = init(y0, u0, p)`` starts both), with the ``p``
    port iff the spec has parameters. ``states`` name the entries of ``x`` (name,
    unit, description) and ``nominals`` give their typical magnitudes (> 0), which
    an importer's solver uses to scale its error control.
    """

    ode: ca.Function
    output: ca.Function
    states: tuple[Variable, ...]
    nominals: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "states", tuple(_as_variable(v) for v in self.states))
        nominals = tuple(float(n) for n in self.nominals) or (1.0,) * len(self.states)
        if len(nominals) != len(self.states) or not all(np.isfinite(n) and n > 0 for n in nominals):
            raise ShapeError(f"nominals must be {len(self.states)} positive numbers (one per state), got {self.nominals!r}")
        object.__setattr__(self, "nominals", nominals)


@dataclass(frozen=True)
class CasadiModel:
    """An ``(init, step)`` pair of CasADi Functions plus its :class:`SystemSpec`.

    ``init(y0[n_y], u0[n_u](, p[n_p])) -> x0[n_x]`` and
    ``step(x[n_x], u[n_u](, p[n_p])) -> (x_next[n_x], y_next[n_y])``, all dense
    column vectors. The ``p`` port exists on both or on neither, iff the spec
    has parameters. ``continuous`` (optional) is the ODE that ``step`` discretises,
    for continuous-time models (physics, hybrids with a derivative correction).
    """

    init: ca.Function
    step: ca.Function
    spec: SystemSpec
    continuous: ContinuousDynamics | None = None

    def __post_init__(self) -> None:
        check_pair(self.init, self.step, self.spec)
        if self.continuous is not None:
            check_continuous(self.continuous, self.n_x, self.spec)

    @property
    def n_x(self) -> int:
        return self.step.size1_in(0)

    def parameter_values(self, p: Sequence[float] | None = None) -> np.ndarray:
        """Parameter vector ``(n_p,)``: ``p`` if given, else the spec's start values."""
        if p is None:
            return np.array([v.start for v in self.spec.parameters], dtype=float)
        p = np.asarray(p, dtype=float).ravel()
        if p.shape != (self.spec.n_p,):
            raise ShapeError(f"p has {p.size} values, expected {self.spec.n_p} ({[v.name for v in self.spec.parameters]})")
        return p

    def past_window(self, y0, u0, y_past=None, u_past=None) -> list[np.ndarray]:
        """The ``init`` arguments after ``y0``, ``u0`` (and ``p``): ``[y_past, u_past]`` flattened, or ``[]``.

        ``y_past`` (N-1, n_y) and ``u_past`` (N-1, n_u), oldest first; default the rest state repeated.
        """
        n_past, spec = self.spec.init_window - 1, self.spec
        if n_past == 0:
            if y_past is not None or u_past is not None:
                raise ShapeError(f"{spec.name} has no init window (init_window 1); drop y_past and u_past")
            return []
        out = []
        for name, given, rest, width in (("y_past", y_past, y0, spec.n_y), ("u_past", u_past, u0, spec.n_u)):
            a = np.tile(np.ravel(rest), (n_past, 1)) if given is None else np.asarray(given, dtype=float)
            if a.shape != (n_past, width):
                raise ShapeError(f"{name} has shape {a.shape}, expected {(n_past, width)}: the init_window - 1 "
                                 "samples before t0, oldest first")
            out.append(a.ravel())
        return out

    def simulate(self, u, y0, p: Sequence[float] | None = None, *, y_past=None, u_past=None) -> np.ndarray:
        """Free run: ``u`` (N, n_u) and ``y0`` (n_y,) in physical units -> y (N, n_y), y[0] = y0.

        ``y_past``, ``u_past``: the samples before t0 of a model with an init window (see
        :meth:`past_window`). Uses ``step.mapaccum`` so that the loop runs inside CasADi, in float64.
        """
        u = np.asarray(u, dtype=float)
        y0 = np.asarray(y0, dtype=float).ravel()
        if u.ndim != 2 or u.shape[1] != self.spec.n_u:
            raise ShapeError(f"u has shape {u.shape}, expected (n_steps, {self.spec.n_u})")
        if y0.shape != (self.spec.n_y,):
            raise ShapeError(f"y0 has shape {y0.shape}, expected ({self.spec.n_y},)")
        extra = [self.parameter_values(p)] if self.spec.n_p else []
        x0 = self.init(y0, u[0], *extra, *self.past_window(y0, u[0], y_past, u_past))
        n = u.shape[0]
        if n == 1:
            return y0[None, :].copy()
        sim = self.step.mapaccum("simulate", n - 1, [0], [0])
        _, ys = sim(x0, u[:n - 1].T, *(np.repeat(e[:, None], n - 1, axis=1) for e in extra))
        return np.vstack([y0[None, :], np.asarray(ys).T])


def check_pair(init: ca.Function, step: ca.Function, spec: SystemSpec) -> None:
    """Check port names and sizes of an ``(init, step)`` pair against ``spec``; raise ShapeError."""
    with_p, n_past = spec.n_p > 0, spec.init_window - 1
    want_init = (["y0", "u0"] + (["p"] if with_p else []) + (["y_past", "u_past"] if n_past else []), ["x0"])
    want_step = (["x", "u"] + (["p"] if with_p else []), ["x_next", "y_next"])
    for fn, (ins, outs) in ((init, want_init), (step, want_step)):
        if fn.name_in() != ins or fn.name_out() != outs:
            raise ShapeError(
                f"CasADi Function {fn.name()!r} has ports {fn.name_in()} -> {fn.name_out()}, "
                f"expected {ins} -> {outs}; name the ports when creating the Function"
            )
    n_x = step.size1_in(0)
    sizes = {
        "init y0": (init.size_in(0), spec.n_y), "init u0": (init.size_in(1), spec.n_u),
        "init x0": (init.size_out(0), n_x), "step u": (step.size_in(1), spec.n_u),
        "step x_next": (step.size_out(0), n_x), "step y_next": (step.size_out(1), spec.n_y),
    }
    if with_p:
        sizes["init p"] = (init.size_in(2), spec.n_p)
        sizes["step p"] = (step.size_in(2), spec.n_p)
    if n_past:
        first = 3 if with_p else 2
        sizes["init y_past"] = (init.size_in(first), n_past * spec.n_y)
        sizes["init u_past"] = (init.size_in(first + 1), n_past * spec.n_u)
    for what, (got, n) in sizes.items():
        if tuple(got) != (n, 1):
            raise ShapeError(f"{what} has shape {tuple(got)}, expected ({n}, 1) for the spec {spec.name!r}")


def check_continuous(dynamics: ContinuousDynamics, n_x: int, spec: SystemSpec) -> None:
    """Check the ODE's and the output map's ports and sizes against the state size and ``spec``."""
    extra = ["p"] if spec.n_p else []
    for fn, ins, outs in ((dynamics.ode, ["x", "u"] + extra, ["xdot"]), (dynamics.output, ["x"] + extra, ["y"])):
        if fn.name_in() != ins or fn.name_out() != outs:
            raise ShapeError(f"CasADi Function {fn.name()!r} has ports {fn.name_in()} -> {fn.name_out()}, "
                             f"expected {ins} -> {outs}")
    sizes = {"ode x": (dynamics.ode.size_in(0), n_x), "ode u": (dynamics.ode.size_in(1), spec.n_u),
             "ode xdot": (dynamics.ode.size_out(0), n_x), "output x": (dynamics.output.size_in(0), n_x),
             "output y": (dynamics.output.size_out(0), spec.n_y), "states": ((len(dynamics.states), 1), n_x)}
    for what, (got, n) in sizes.items():
        if tuple(got) != (n, 1):
            raise ShapeError(f"{what} has shape {tuple(got)}, expected ({n}, 1) for the spec {spec.name!r}")
