"""Test models, a per-session cache of built FMUs and small fmpy helpers for the FMU tests.

Imported by tests/test_fmu_*.py. FMUs are compiled once per session (the
cache is keyed by model and FMI version) so that the FMU tests stay within
their time budget.
"""

from __future__ import annotations

import atexit
import ctypes
import shutil
import tempfile
from pathlib import Path

import casadi as ca
import fmpy
import numpy as np
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import fmi2True
from fmpy.fmi3 import fmi3Boolean, fmi3Float64

from nnfmu.export.fmu import BuildOptions, build_fmu
from nnfmu.system import CasadiModel, SystemSpec, Variable

__all__ = ["FMICallException", "Instance", "MODELS", "built_fmu", "excitation", "fmpy_simulate", "get_model", "unzipped"]


def linear_model(damping: float = 0.95) -> CasadiModel:
    """A damped oscillator sampled at Ts = 0.01 s: SX, 1 input, 2 outputs, no parameters."""
    x, u = ca.SX.sym("x", 2), ca.SX.sym("u", 1)
    A = ca.DM([[0.98, 0.01], [-0.3, damping]])
    B = ca.DM([[0.0], [0.02]])
    x_next = ca.mtimes(A, x) + ca.mtimes(B, u)
    step = ca.Function("step", [x, u], [x_next, x_next], ["x", "u"], ["x_next", "y_next"])
    y0, u0 = ca.SX.sym("y0", 2), ca.SX.sym("u0", 1)
    init = ca.Function("init", [y0, u0], [y0], ["y0", "u0"], ["x0"])
    spec = SystemSpec("oscillator", 0.01, [Variable("force", "N", "applied force F (≥ 0 pushes)")],
                      [Variable("pos", "m", "position", start=0.1), Variable("vel", "m/s", "velocity")],
                      description="a damped linear oscillator")
    return CasadiModel(init, step, spec)


def nonlinear_model() -> CasadiModel:
    """A small recurrent network as MX with dense weights (the patched kernel) and a ``p`` port.

    x = [y (2), h (8)]; h' = tanh(W h + V [y, u] * gain + b); y' = y + scale * (C h' + d);
    init fills h from y0 and u0 (so u0 matters). Parameters gain [-] and scale [-].
    """
    rng = np.random.default_rng(7)
    W, V = ca.DM(rng.normal(size=(8, 8)) / 4), ca.DM(rng.normal(size=(8, 4)) / 2)
    b, C, d = ca.DM(rng.normal(size=8) / 4), ca.DM(rng.normal(size=(2, 8)) / 2), ca.DM(rng.normal(size=2) / 10)
    R = ca.DM(rng.normal(size=(2, 8)) / 3)  # row-vector times matrix: ncol_y > 1 in the kernel
    x, u, p = ca.MX.sym("x", 10), ca.MX.sym("u", 2), ca.MX.sym("p", 2)
    y, h = x[:2], x[2:]
    h_next = ca.tanh(ca.mtimes(W, h) + ca.mtimes(V, ca.vertcat(y, u)) * p[0] + b)
    y_next = y + p[1] * (ca.mtimes(C, h_next) + d) + 0.01 * ca.mtimes(h_next.T, R.T).T
    step = ca.Function("step", [x, u, p], [ca.vertcat(y_next, h_next), y_next], ["x", "u", "p"],
                       ["x_next", "y_next"])
    y0, u0 = ca.MX.sym("y0", 2), ca.MX.sym("u0", 2)
    init = ca.Function("init", [y0, u0, p], [ca.vertcat(y0, ca.tanh(ca.mtimes(V, ca.vertcat(y0, u0)) * p[0]))],
                       ["y0", "u0", "p"], ["x0"])
    spec = SystemSpec("tinynet", 0.002, [Variable("u1", "V", min=-3.0, max=3.0), Variable("u2", "V", min=-3.0, max=3.0)],
                      [Variable("s", "mm", "stroke"), Variable("q", "bar", "pressure", start=1.0)],
                      [Variable("gain", "", "input gain", start=1.0), Variable("scale", "", "output scale", start=0.2)])
    return CasadiModel(init, step, spec)


def blowup_model() -> CasadiModel:
    """y' = y * exp(u): finite for small u, overflows to inf for u = 800 (a non-finite result)."""
    x, u = ca.SX.sym("x", 1), ca.SX.sym("u", 1)
    y_next = x * ca.exp(u)
    step = ca.Function("step", [x, u], [y_next, y_next], ["x", "u"], ["x_next", "y_next"])
    y0, u0 = ca.SX.sym("y0", 1), ca.SX.sym("u0", 1)
    init = ca.Function("init", [y0, u0], [y0], ["y0", "u0"], ["x0"])
    return CasadiModel(init, step, SystemSpec("blowup", 0.5, ["u"], [Variable("y", start=1.0)]))


def valve_gru_model() -> CasadiModel:
    """A tiny random GRU (hidden 3) with the valve's channels, Ts = 40 us and a stored input range [0, 10] V.

    Exported as a trained network is (torch -> CasADi, with the normalisation inside), so its FMU is what
    ``python -m nnfmu.export`` writes, at a fraction of the cost.
    """
    import torch

    from nnfmu.export import casadi_model
    from nnfmu.models import ModelConfig, build_model

    meta = {"name": "valve_gru", "Ts": 4e-5, "input_range": [[0.0, 10.0], [0.0, 10.0]],
            "inputs": [{"name": "u1", "unit": "V"}, {"name": "u2", "unit": "V"}],
            "outputs": [{"name": "s", "unit": "m"}, {"name": "p", "unit": "Pa"}]}
    torch.manual_seed(3)
    net = build_model(ModelConfig(arch="gru", n_u=2, n_y=2, hidden=3), meta).double()
    with torch.no_grad():
        net.u_mean.fill_(5.0), net.u_std.fill_(2.0)
        net.y_mean.copy_(torch.tensor([5e-4, 3e5])), net.y_std.copy_(torch.tensor([2e-4, 1e5]))
    return casadi_model(net.eval())


MODELS = {"linear": linear_model(), "nonlinear": nonlinear_model(), "blowup": blowup_model(),
          "linear_twin": linear_model(damping=0.5)}  # same name and variables, other maths
_LAZY_MODELS = {"valve_gru": valve_gru_model}  # built on first use (they need torch)
_WORK = Path(tempfile.mkdtemp(prefix="nnfmu-test-fmus-"))
atexit.register(shutil.rmtree, _WORK, ignore_errors=True)
_BUILT: dict[tuple, Path] = {}
_LOGGERS: list = []


def instantiate_logged(folder, md, kind: str, logger):
    """``fmpy.instantiate_fmu`` with a Python ``logger``, kept alive for the whole session.

    fmpy's FMI 2 logger proxy remembers the last Python logger in a C global and sends every later
    instance's messages there, even those of instances made with fmpy's default callbacks. A logger
    that is garbage-collected leaves that global dangling: the next FMU that logs calls freed memory
    (a segfault, or a stray call into whatever callback took its place). Every test that passes a
    logger goes through here.
    """
    fmu = fmpy.instantiate_fmu(str(folder), md, kind, logger=logger)
    _LOGGERS.append((logger, getattr(fmu, "callbacks", None), getattr(fmu, "logMessage", None)))
    return fmu


def oscillator_dataset(folder: Path) -> Path:
    """The linear oscillator's tiny dataset (force in N -> pos in m, vel in m/s; 3 train and 1 test trajectory of 60
    samples at 0.01 s) saved in ``folder``, for the CLI tests."""
    from nnfmu.data import Channel, from_arrays, save_dataset

    model, rng = MODELS["linear"], np.random.default_rng(0)
    us = [rng.normal(size=(60, 1)) for _ in range(4)]
    ys = [model.simulate(u, [0.1, 0.0]) for u in us]
    ds = from_arrays(Ts=0.01, u_train=us[:3], y_train=ys[:3], u_test=us[3:], y_test=ys[3:],
                     input_names=[Channel("force", "N")], output_names=[Channel("pos", "m"), Channel("vel", "m/s")])
    return save_dataset(ds, folder)


def get_model(name: str) -> CasadiModel:
    """``MODELS[name]``, or one of the models built on first use (``valve_gru``)."""
    if name not in MODELS:
        MODELS[name] = _LAZY_MODELS[name]()
    return MODELS[name]


def built_fmu(name: str, fmi_version: int, options: BuildOptions | None = None) -> Path:
    """The FMU of ``get_model(name)``, built once per session for each (name, version, options)."""
    key = (name, fmi_version, options)
    if key not in _BUILT:
        path = _WORK / f"{name}_fmi{fmi_version}_{len(_BUILT)}.fmu"
        _BUILT[key] = build_fmu(get_model(name), path, fmi_version=fmi_version, options=options)
    return _BUILT[key]


def unzipped(fmu: Path) -> Path:
    folder = fmu.with_suffix("")
    if not folder.exists():
        fmpy.extract(str(fmu), str(folder))
    return folder


def excitation(model: CasadiModel, n: int, seed: int = 0) -> np.ndarray:
    """Smooth random inputs (n, n_u) with steps, in the model's units."""
    rng = np.random.default_rng(seed)
    t = np.arange(n)[:, None]
    u = np.sin(t * rng.uniform(0.02, 0.2, model.spec.n_u)) + 0.5 * np.sign(np.sin(t * 0.037 + 1))
    return u + 0.1 * rng.normal(size=u.shape)


def fmpy_simulate(fmu: Path, model: CasadiModel, u: np.ndarray, y0, p=None) -> np.ndarray:
    """fmpy co-simulation with output interval Ts and ``<y>_start`` = y0; returns y (n, n_y)."""
    spec = model.spec
    n = u.shape[0]
    signals = np.zeros(n, dtype=[("time", float)] + [(v.name, float) for v in spec.inputs])
    signals["time"] = np.arange(n) * spec.Ts
    for i, v in enumerate(spec.inputs):
        signals[v.name] = u[:, i]
    start = {f"{v.name}_start": float(y0[i]) for i, v in enumerate(spec.outputs)}
    if p is not None:
        start.update({v.name: float(p[i]) for i, v in enumerate(spec.parameters)})
    result = fmpy.simulate_fmu(str(fmu), start_time=0.0, stop_time=(n - 1) * spec.Ts, output_interval=spec.Ts,
                               input=signals, start_values=start)
    assert len(result) == n, f"fmpy returned {len(result)} rows, expected {n}"
    return np.stack([result[v.name] for v in spec.outputs], axis=1)


class Instance:
    """One FMU instance through fmpy with the same calls for FMI 2 and 3; ``logs`` collects messages."""

    def __init__(self, fmu: Path, name: str = "instance"):
        folder = unzipped(fmu)
        self.md = fmpy.read_model_description(str(folder))
        self.fmi3 = self.md.fmiVersion.startswith("3")
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.logs: list[tuple[int, str]] = []
        self.fmu = instantiate_logged(folder, self.md, "CoSimulation", self._log)
        self.time = 0.0

    def _log(self, *args) -> None:  # FMI 2: (env, name, status, category, msg); FMI 3: (env, status, category, msg)
        status, message = args[-3], args[-1]
        self.logs.append((status, message.decode() if isinstance(message, bytes) else message))

    def initialize(self, start: dict | None = None, start_time: float = 0.0) -> "Instance":
        if not self.fmi3:
            self.fmu.setupExperiment(startTime=start_time)
            self.fmu.enterInitializationMode()
        else:
            self.fmu.enterInitializationMode(startTime=start_time)
        if start:
            self.set(start)
        self.fmu.exitInitializationMode()
        self.time = start_time
        return self

    def set(self, values: dict) -> None:
        refs, vals = [self.vr[k] for k in values], [float(v) for v in values.values()]
        (self.fmu.setFloat64 if self.fmi3 else self.fmu.setReal)(refs, vals)

    def get(self, names) -> np.ndarray:
        refs = [self.vr[k] for k in names]
        return np.array((self.fmu.getFloat64 if self.fmi3 else self.fmu.getReal)(refs))

    def step(self, h: float, t: float | None = None) -> int:
        """doStep(t, h) (t: where the last step ended); returns the status (OK 0, Warning 1), raises on errors."""
        t = self.time if t is None else t
        if self.fmi3:
            flags = [fmi3Boolean() for _ in range(3)] + [fmi3Float64()]
            status = self.fmu.fmi3DoStep(self.fmu.component, t, h, fmi3Boolean(True), *map(ctypes.byref, flags))
        else:
            status = self.fmu.fmi2DoStep(self.fmu.component, t, h, fmi2True)
        self.time = t + h
        return status

    def set_int(self, name: str, value: int) -> None:
        """Set the Integer (FMI 3: Int32) or Boolean parameter ``name``."""
        ref, boolean = [self.vr[name]], name == "input_range_error"
        if self.fmi3:
            (self.fmu.setBoolean if boolean else self.fmu.setInt32)(ref, [bool(value) if boolean else int(value)])
        else:
            (self.fmu.setBoolean if boolean else self.fmu.setInteger)(ref, [bool(value) if boolean else int(value)])

    def run(self, model: CasadiModel, u: np.ndarray) -> np.ndarray:
        """Set u[k] and step Ts for each row; return the outputs after each step (n, n_y)."""
        ins, outs = [v.name for v in model.spec.inputs], [v.name for v in model.spec.outputs]
        ys = []
        for row in u:
            self.set(dict(zip(ins, row, strict=True)))
            self.fmu.doStep(self.time, model.spec.Ts)
            self.time = self.fmu_time()
            ys.append(self.get(outs))
        return np.array(ys)

    def fmu_time(self) -> float:
        return float(self.get(["time"])[0])

    def get_state(self):
        return self.fmu.getFMUState() if self.fmi3 else self.fmu.getFMUstate()

    def set_state(self, state) -> None:
        (self.fmu.setFMUState if self.fmi3 else self.fmu.setFMUstate)(state)
        self.time = self.fmu_time()

    def serialize(self, state) -> bytes:
        return bytes(self.fmu.serializeFMUState(state) if self.fmi3 else self.fmu.serializeFMUstate(state))

    def deserialize(self, data: bytes):
        return self.fmu.deserializeFMUState(data) if self.fmi3 else self.fmu.deSerializeFMUstate(data)

    def free_state(self, state) -> None:
        (self.fmu.freeFMUState if self.fmi3 else self.fmu.freeFMUstate)(state)

    def reset(self) -> None:
        self.fmu.reset()
        self.time = 0.0

    def errors(self) -> list[str]:
        return [m for s, m in self.logs if s >= 3]

    def warnings(self) -> list[str]:
        return [m for s, m in self.logs if s == 1]

    def close(self) -> None:
        self.fmu.freeInstance()  # fmpy also unloads the library here (one dlclose per load)


def exported_symbols(fmu: Path, names) -> dict[str, bool]:
    """Which of ``names`` the FMU's binary exports (ctypes sees only exported symbols)."""
    binaries = list((unzipped(fmu) / "binaries").rglob("*.so"))
    lib = ctypes.CDLL(str(binaries[0]))
    return {name: hasattr(lib, name) for name in names}
