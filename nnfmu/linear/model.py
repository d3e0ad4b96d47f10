"""The identified linear baseline in physical units: simulation, CasADi export, save and load.

``x[k+1] = A x[k] + B u[k] + b``, ``y[k] = C x[k] + d`` with ``D = 0`` (the
contract has no direct feedthrough). The initial-state rule is one of
:data:`~nnfmu.linear.statespace.INIT_OPTIONS`:

- ``estimate`` (default of :func:`~nnfmu.linear.identify_linear`): ``b`` and ``d`` are the
  identified offsets, and ``x0`` is the state that reproduces ``y0`` and is closest to
  an equilibrium for ``u0`` (:func:`~nnfmu.linear.statespace.init_gains`). The state of
  the exported model is ``x`` (``n`` values).
- ``zero-offset``: the robot benchmark's convention. ``b = 0`` and ``d = 0`` are
  stored; at run time the inputs are taken relative to their initial value,
  ``x0 = 0`` and ``y = y0 + C x``. The exported state is ``[x; u0; y0]``, so that
  ``step`` knows the offsets.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from nnfmu.atomic import write_text_atomic
from nnfmu.data import Channel
from nnfmu.errors import CheckpointError, ConfigError, DataFileError, ShapeError
from nnfmu.linear.statespace import INIT_OPTIONS, StateSpace, free_run, init_gains
from nnfmu.system import CasadiModel, SystemSpec, Variable
from nnfmu.valid_range import with_ranges, with_starts

FORMAT = "nnfmu-linear"


@dataclass(frozen=True)
class LinearModel:
    """A linear state-space model of a dataset's system, in the dataset's units.

    Attributes
    ----------
    system : StateSpace
        ``A`` (n, n), ``B`` (n, n_u) per input unit, ``b`` (n,), ``C`` (n_y, n) in output
        units, ``d`` (n_y,) in output units.
    init : {"estimate", "zero-offset"}
        The initial-state rule (module docstring).
    y_scale : ndarray, shape (n_y,)
        Output scales (training std) that weight the ``estimate`` rule's fit of ``y0``.
    Ts : float
        Sample time in s.
    inputs, outputs : tuple of Channel
        Names and units, as in the dataset.
    info : dict
        How the model was identified (order, singular values, scores); JSON-serialisable.
    input_range : tuple of (min, max) or None
        Per input, the valid range the FMU declares: the training data's range widened by
        :data:`nnfmu.valid_range.RANGE_MARGIN` (None for a model saved without one).
    """

    system: StateSpace
    init: str
    y_scale: np.ndarray
    Ts: float
    inputs: tuple[Channel, ...]
    outputs: tuple[Channel, ...]
    info: dict = field(default_factory=dict)
    input_range: tuple | None = None

    def __post_init__(self) -> None:
        if self.init not in INIT_OPTIONS:
            raise ConfigError(f"init must be one of {', '.join(INIT_OPTIONS)}, got {self.init!r}")
        n, sys = self.system.n_x, self.system
        shapes = {"A": (sys.A, (n, n)), "B": (sys.B, (n, len(self.inputs))), "b": (sys.b, (n,)),
                  "C": (sys.C, (len(self.outputs), n)), "d": (sys.d, (len(self.outputs),)),
                  "y_scale": (self.y_scale, (len(self.outputs),))}
        for name, (arr, shape) in shapes.items():
            if np.shape(arr) != shape:
                raise ShapeError(f"linear model: {name} has shape {np.shape(arr)}, expected {shape} "
                                 f"for {n} states, {len(self.inputs)} inputs and {len(self.outputs)} outputs")
        if self.init == "zero-offset" and (np.any(sys.b) or np.any(sys.d)):
            raise ShapeError("a zero-offset model takes its offsets from u0 and y0; expected b = 0 and d = 0")

    @property
    def n_x(self) -> int:
        return self.system.n_x

    @property
    def D(self) -> np.ndarray:
        """The direct feedthrough, always zero (n_y, n_u): ``y[k+1]`` depends on inputs up to ``u[k]``."""
        return np.zeros((len(self.outputs), len(self.inputs)))

    def initial_state(self, y0, u0) -> np.ndarray:
        """``x0`` (n,) for the initial output ``y0`` (n_y,) and input ``u0`` (n_u,), physical units."""
        y0, u0 = np.asarray(y0, dtype=float).ravel(), np.asarray(u0, dtype=float).ravel()
        if self.init == "zero-offset":
            return np.zeros(self.n_x)
        K_y, K_u, k_0 = init_gains(self.system, self.y_scale)
        return K_y @ (y0 - self.system.d) + K_u @ u0 + k_0

    def simulate(self, u, y0) -> np.ndarray:
        """Free run: ``u`` (N, n_u) and ``y0`` (n_y,) -> ``y`` (N, n_y) with ``y[0] = y0``; physical units."""
        u = np.asarray(u, dtype=float)
        y0 = np.asarray(y0, dtype=float).ravel()
        if u.ndim != 2 or u.shape[1] != len(self.inputs) or y0.shape != (len(self.outputs),):
            raise ShapeError(f"expected u of shape (n_steps, {len(self.inputs)}) and y0 of shape "
                             f"({len(self.outputs)},), got {u.shape} and {y0.shape}")
        sys = self.system
        if self.init == "zero-offset":
            sys, u = sys.replace(d=y0), u - u[0]
        _, y = free_run(sys, self.initial_state(y0, u[0])[None], u[None])
        y = y[0]
        y[0] = y0
        return y

    def spec(self, name: str = "linear", description: str | None = None) -> SystemSpec:
        """The :class:`SystemSpec` of the exported model: the dataset's channels and ``Ts``; start values
        the training means (``info["training_mean"]``), an input's clipped into its range."""
        text = description or (f"linear state-space model, {self.n_x} states, init rule '{self.init}'")
        source = {"kind": "linear", "init": self.init, "order": self.n_x,
                  **{k: self.info[k] for k in ("nrmse_valid", "dataset") if k in self.info}}
        mean = self.info.get("training_mean") or {}  # neutral start values (None: saved before they were stored)
        inputs, outputs = ([Variable(c.name, c.unit, getattr(c, "description", "")) for c in channels]
                           for channels in (self.inputs, self.outputs))
        inputs = with_ranges(with_starts(inputs, mean.get("u")), self.input_range)
        outputs = with_starts(outputs, mean.get("y"))
        return SystemSpec(name=name, Ts=self.Ts, inputs=inputs, outputs=outputs,
                          description=text, source=source)

    def casadi_model(self, name: str = "linear", description: str | None = None) -> CasadiModel:
        """The ``(init, step)`` pair as CasADi Functions, in physical units (see the module docstring)."""
        import casadi as ca

        sys, n_u, n_y = self.system, len(self.inputs), len(self.outputs)
        y0, u0, u = ca.SX.sym("y0", n_y), ca.SX.sym("u0", n_u), ca.SX.sym("u", n_u)
        A, B, C = ca.DM(sys.A), ca.DM(sys.B), ca.DM(sys.C)
        if self.init == "estimate":
            K_y, K_u, k_0 = (ca.DM(m) for m in init_gains(sys, self.y_scale))
            x0 = ca.mtimes(K_y, y0 - ca.DM(sys.d)) + ca.mtimes(K_u, u0) + k_0
            x = ca.SX.sym("x", self.n_x)
            x_next = ca.mtimes(A, x) + ca.mtimes(B, u) + ca.DM(sys.b)
            y_next, state_next = ca.mtimes(C, x_next) + ca.DM(sys.d), x_next
        else:  # the state carries the offsets u0 and y0 next to x
            x0 = ca.vertcat(ca.DM.zeros(self.n_x), u0, y0)
            x = ca.SX.sym("x", self.n_x + n_u + n_y)
            lin, u_ref, y_ref = x[:self.n_x], x[self.n_x:self.n_x + n_u], x[self.n_x + n_u:]
            x_next = ca.mtimes(A, lin) + ca.mtimes(B, u - u_ref)
            y_next = y_ref + ca.mtimes(C, x_next)
            state_next = ca.vertcat(x_next, u_ref, y_ref)
        init = ca.Function("init", [y0, u0], [x0], ["y0", "u0"], ["x0"])
        step = ca.Function("step", [x, u], [state_next, y_next], ["x", "u"], ["x_next", "y_next"])
        return CasadiModel(init, step, self.spec(name, description))

    def to_json(self) -> dict:
        """Everything needed to rebuild the model, as plain JSON (floats round-trip exactly)."""
        sys = self.system
        return {
            "format": FORMAT, "version": 1, "Ts": self.Ts, "init": self.init,
            "inputs": [c.to_json() for c in self.inputs], "outputs": [c.to_json() for c in self.outputs],
            "A": sys.A.tolist(), "B": sys.B.tolist(), "C": sys.C.tolist(), "D": self.D.tolist(),
            "b": sys.b.tolist(), "d": sys.d.tolist(), "y_scale": self.y_scale.tolist(), "info": self.info,
            "input_range": None if self.input_range is None else [list(r) for r in self.input_range],
        }

    def save(self, path: str | os.PathLike) -> Path:
        """Write the model as JSON to ``path`` (via a temporary file, so nothing half-written remains)."""
        return write_text_atomic(Path(path), json.dumps(self.to_json(), indent=1) + "\n")


def load_linear(path: str | os.PathLike) -> LinearModel:
    """Read a model written by :meth:`LinearModel.save`."""
    path = Path(path)
    try:
        raw = json.loads(path.read_text())
    except FileNotFoundError as exc:
        raise DataFileError(f"linear model file {path} not found; write one with 'nnfmu linear --save'") from exc
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise CheckpointError(f"{path} is not valid JSON ({exc}); it is not an nnfmu linear model") from exc
    if not isinstance(raw, dict) or raw.get("format") != FORMAT:
        raise CheckpointError(f"{path} is not an nnfmu linear model (expected \"format\": \"{FORMAT}\")")
    try:
        arrays = {k: np.array(raw[k], dtype=float) for k in ("A", "B", "C", "b", "d", "y_scale")}
        n = arrays["A"].shape[0]
        sys = StateSpace(arrays["A"].reshape(n, n), arrays["B"].reshape(n, -1), arrays["b"],
                         arrays["C"].reshape(-1, n), arrays["d"])
        return LinearModel(sys, raw["init"], arrays["y_scale"], float(raw["Ts"]),
                           tuple(Channel(**c) for c in raw["inputs"]),
                           tuple(Channel(**c) for c in raw["outputs"]), raw.get("info", {}),
                           None if raw.get("input_range") is None else tuple(map(tuple, raw["input_range"])))
    except (KeyError, TypeError, ValueError) as exc:
        raise CheckpointError(f"{path}: damaged nnfmu linear model ({type(exc).__name__}: {exc})") from exc
