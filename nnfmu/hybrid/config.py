"""``HybridConfig``: a physics model (valve or arm), its parameter values and its neural correction.

A :class:`HybridConfig` is a :class:`~nnfmu.models.ModelConfig` with ``arch="hybrid"``, so the
one trainer, checkpoints and ``load_model`` treat a hybrid like any other network. Of the
inherited fields, ``hidden``, ``layers`` (default 2), ``activation`` and ``dropout`` shape the
correction MLP; ``window`` is 1 (the physics state is the memory); ``kernel_size``, ``skip`` and
``skip_scale`` do not apply (the physics plays the part of the skip connection).

Physical parameters are named as the entries of the physics' ``p`` vector
(``valve_system().parameters``: ``k_s``, ``C_max``, ...; the arm's tuple fields
flattened as ``f_b1`` .. ``f_b6``). A parameter file is a JSON object of such names
and numbers; a tuple field may also be given whole as a list (``"f_vis": [6 numbers]``)::

    {"k_s": 32500.0, "C_max": 4.2e-10, "d_c": 0.0}
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import os
from dataclasses import dataclass
from typing import Callable, Mapping

from nnfmu.errors import ConfigError, DataFileError, ShapeError, UnknownOptionError
from nnfmu.hybrid.compiled_torch import BACKENDS
from nnfmu.models.config import ACTIVATIONS, ModelConfig
from nnfmu.physics import PhysicsSystem, arm_system, valve_system

CORRECTIONS = ("derivative", "step")
HYBRID_ARCH = "hybrid"


@dataclass(frozen=True)
class PhysicsEntry:
    """What the hybrid needs to know about one physics model beyond its :class:`PhysicsSystem`.

    ``corrected_states``: the states whose derivative the network corrects by default: the
    ones driven by uncertain forces and flows, not the kinematic identities (d/dt s = sdot).
    ``correction_time`` (s): one unit of network output changes a corrected derivative by
    ``state_scale / correction_time``, i.e. about a typical state change per this time.
    """

    build: Callable[[], PhysicsSystem]
    corrected_states: tuple[str, ...]
    correction_time: float


PHYSICS = {
    "valve": PhysicsEntry(valve_system, ("p", "sdot"), 1e-3),
    "arm": PhysicsEntry(arm_system, tuple(f"qd{j}" for j in range(1, 7)), 1.0),
}


@functools.lru_cache(maxsize=None)
def physics_system(name: str) -> PhysicsSystem:
    """The nominal :class:`PhysicsSystem` called ``name`` (built once per process)."""
    if name not in PHYSICS:
        raise ConfigError(f"unknown physics {name!r}; choose one of {', '.join(PHYSICS)}")
    return PHYSICS[name].build()


def _number(name: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(f"physics parameter {name!r} must be a finite number, got {value!r}")
    return float(value)


def normalise_physics_params(physics: str, params: Mapping) -> tuple[tuple[str, float], ...]:
    """Check parameter overrides against ``physics``' ``p`` names; sorted ``(name, value)`` pairs.

    A list value expands a tuple field: ``{"f_vis": [a, ..]}`` -> ``f_vis1 = a, ...``.
    Raises UnknownOptionError (listing the valid names) or ConfigError (bad value).
    """
    if not isinstance(params, Mapping):
        raise ConfigError(f"physics parameters must be a mapping of name -> number, got {type(params).__name__}")
    valid = [v.name for v in physics_system(physics).parameters]
    out: dict[str, float] = {}
    for name, value in params.items():
        if isinstance(value, (list, tuple)):
            names = [f"{name}{j + 1}" for j in range(len(value))]
            if not all(n in valid for n in names) or f"{name}{len(value) + 1}" in valid:
                raise ConfigError(f"physics parameter {name!r} got a list of {len(value)} values, but {physics} has "
                                  f"no tuple parameter {name!r} of that length; give scalars by entry name")
            out.update((n, _number(n, v)) for n, v in zip(names, value))
        else:
            out[str(name)] = _number(str(name), value)
    unknown = sorted(set(out) - set(valid))
    if unknown:
        raise UnknownOptionError(f"unknown {physics} parameter(s) {', '.join(map(repr, unknown))}; valid names are: "
                                 f"{', '.join(valid)}")
    return tuple(sorted(out.items()))


def load_physics_params(path: str | os.PathLike) -> dict:
    """Read a JSON parameter file (an object of name -> number or list); see the module docstring."""
    try:
        with open(path, encoding="utf-8") as f:
            data = json.load(f)
    except FileNotFoundError:
        raise DataFileError(f"physics parameter file {path} not found; pass a JSON file such as "
                            '{"k_s": 32500.0, "C_max": 4.2e-10}') from None
    except (OSError, UnicodeDecodeError) as exc:
        raise DataFileError(f"cannot read the physics parameter file {path}: {exc}") from exc
    except json.JSONDecodeError as exc:
        raise ConfigError(f"physics parameter file {path} is not valid JSON ({exc}); write an object such as "
                          '{"k_s": 32500.0, "C_max": 4.2e-10}') from exc
    if not isinstance(data, dict):
        raise ConfigError(f"physics parameter file {path} must hold a JSON object of name -> number, "
                          f"got a {type(data).__name__}")
    return data


@dataclass(frozen=True, kw_only=True)
class HybridConfig(ModelConfig):
    """Physics plus neural correction; see the module docstring for the inherited fields.

    Attributes
    ----------
    physics : {'valve', 'arm'}
        The CasADi physics model (:func:`nnfmu.physics.valve_system`, :func:`~nnfmu.physics.arm_system`).
    physics_params : mapping of str to float
        Values replacing the nominal ones (possibly wrong on purpose); a list expands a tuple field.
    train_physics : tuple of str
        Parameters trained with the network, in log-space: ``p = p_given * exp(gain * theta)``,
        ``theta`` starting at 0 (so they keep their sign and cannot cross zero; a parameter
        whose value is 0 cannot be trained this way).
    train_physics_gain : float
        ``gain`` above. Adam moves ``theta`` by about ``lr`` per step, so a physical parameter
        changes by about ``gain * lr`` (relative) per step: 10 lets a 30 % error be corrected
        within tens of steps at lr = 3e-3, as fast as the network learns.
    correction : {'derivative', 'step'}
        ``'derivative'``: ``xdot = ode(x, u, p) + delta(x, u)`` inside every RK4 stage.
        ``'step'``: ``x+ = RK4_physics(x, u, p) + Ts * delta(x, u)``, one network call per sample.
    corrected_states : tuple of str or None
        States whose derivative ``delta`` corrects (None: the physics' default, see :data:`PHYSICS`).
    correction_time : float or None
        Seconds; ``delta_i = state_scale_i / correction_time * N_i`` (None: the physics' default).
    n_sub : int or None
        RK4 sub-steps per sample (None: the physics' own choice).
    physics_backend : {'compiled', 'sx'}
        How torch evaluates the physics: compiled C (fast; without a C compiler it falls back to
        'sx' with a warning) or the :func:`~nnfmu.hybrid.sx_to_torch` translation. Both give
        CasADi's values and gradients (to 1e-12); only the speed differs.
    """

    arch: str = "hybrid"
    physics: str = "valve"
    physics_params: Mapping = ()
    train_physics: tuple = ()
    train_physics_gain: float = 10.0
    correction: str = "derivative"
    corrected_states: tuple | None = None
    correction_time: float | None = None
    n_sub: int | None = None
    physics_backend: str = "compiled"

    def __post_init__(self) -> None:
        if self.arch != "hybrid":
            raise ConfigError(f"HybridConfig has arch 'hybrid', got {self.arch!r}; use ModelConfig for networks")
        if self.physics not in PHYSICS:
            raise ConfigError(f"unknown physics {self.physics!r}; choose one of {', '.join(PHYSICS)}")
        for name, valid in (("correction", CORRECTIONS), ("physics_backend", BACKENDS)):
            if getattr(self, name) not in valid:
                raise ConfigError(f"unknown {name} {getattr(self, name)!r}; choose one of {', '.join(valid)}")
        self._check_network()
        system = physics_system(self.physics)
        for name, n in (("n_u", len(system.inputs)), ("n_y", len(system.outputs))):
            if getattr(self, name) != n:
                raise ShapeError(f"the {self.physics} physics has {name} = {n}, got {getattr(self, name)!r}; "
                                 "train it on data of that system")
        pairs = dict(self.physics_params) if not isinstance(self.physics_params, Mapping) else self.physics_params
        object.__setattr__(self, "physics_params", normalise_physics_params(self.physics, pairs))
        self._check_names("train_physics", [v.name for v in system.parameters], "parameter")
        self._check_trainable_nonzero()
        if self.corrected_states is None:
            object.__setattr__(self, "corrected_states", PHYSICS[self.physics].corrected_states)
        self._check_names("corrected_states", [v.name for v in system.states], "state")
        if not self.corrected_states:
            raise ConfigError("corrected_states is empty: the network would correct nothing; name at least one state")
        if self.correction_time is None:
            object.__setattr__(self, "correction_time", PHYSICS[self.physics].correction_time)
        if not (isinstance(self.correction_time, (int, float)) and self.correction_time > 0):
            raise ConfigError(f"correction_time must be a positive number of seconds, got {self.correction_time!r}")
        object.__setattr__(self, "correction_time", float(self.correction_time))
        if not (isinstance(self.train_physics_gain, (int, float)) and 0 < self.train_physics_gain < math.inf):
            raise ConfigError(f"train_physics_gain must be a positive number, got {self.train_physics_gain!r}")
        object.__setattr__(self, "train_physics_gain", float(self.train_physics_gain))
        if self.n_sub is not None and (isinstance(self.n_sub, bool) or not isinstance(self.n_sub, int)
                                       or self.n_sub < 1):
            raise ConfigError(f"n_sub must be None or a positive integer number of RK4 sub-steps, got {self.n_sub!r}")

    def _check_network(self) -> None:
        for name in ("n_u", "n_y", "hidden"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise ShapeError(f"HybridConfig.{name} must be a positive integer, got {value!r}")
        if self.layers is None:
            object.__setattr__(self, "layers", 2)
        if not isinstance(self.layers, int) or isinstance(self.layers, bool) or self.layers < 1:
            raise ShapeError(f"HybridConfig.layers (hidden layers of the correction MLP) must be a positive "
                             f"integer, got {self.layers!r}")
        if self.window not in (None, 1):
            raise ShapeError(f"a hybrid model's memory is its physics state, so window must be 1, got "
                             f"{self.window!r}; leave window out")
        object.__setattr__(self, "window", 1)
        if self.increment or self.init_window != 1 or self.members != 1:
            raise ConfigError("a hybrid model starts from its physics state (init_state(y0, u0)) and predicts the "
                              "physics' output; increment, init_window and members do not apply to it: leave them out")
        if not 0.0 <= float(self.dropout) < 1.0:
            raise ConfigError(f"dropout must be in [0, 1), got {self.dropout!r}")
        object.__setattr__(self, "dropout", float(self.dropout))
        if self.activation not in ACTIVATIONS:
            raise ConfigError(f"activation {self.activation!r} is not available; "
                              f"choose one of {', '.join(ACTIVATIONS)}")

    def _check_names(self, field: str, valid: list, what: str) -> None:
        names = getattr(self, field)
        if isinstance(names, str):
            names = tuple(n.strip() for n in names.split(",") if n.strip())
        names = tuple(names)
        unknown = [n for n in names if n not in valid]
        if unknown:
            raise UnknownOptionError(f"{field}: unknown {self.physics} {what}(s) {', '.join(map(repr, unknown))}; "
                                     f"valid names are: {', '.join(valid)}")
        if len(set(names)) != len(names):
            raise ConfigError(f"{field} names a {what} twice: {list(names)}")
        object.__setattr__(self, field, names)

    def _check_trainable_nonzero(self) -> None:
        values = self.parameter_values()
        names = [v.name for v in physics_system(self.physics).parameters]
        zero = [n for n in self.train_physics if values[names.index(n)] == 0.0]
        if zero:
            raise ConfigError(f"cannot train {zero}: their value is 0, and physical parameters are trained in "
                              "log-space (p = p_given * exp(gain * theta)); give a nonzero starting value in the "
                              "parameter file, or leave them fixed")

    def parameter_values(self) -> list[float]:
        """The ``p`` vector before training: the nominal values with :attr:`physics_params` applied."""
        system = physics_system(self.physics)
        given = dict(self.physics_params)
        return [given.get(v.name, v.start) for v in system.parameters]

    def to_dict(self) -> dict:
        """Plain dict (JSON- and ``weights_only``-safe); ``physics_params`` as a dict."""
        d = dataclasses.asdict(self)
        d["physics_params"] = dict(self.physics_params)
        d["train_physics"] = list(self.train_physics)
        d["corrected_states"] = list(self.corrected_states)
        return d
