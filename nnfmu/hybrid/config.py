"""``HybridConfig``: a physics model (any registered one, or the user's own), its parameter values and its neural correction.

A :class:`HybridConfig` is a :class:`~nnfmu.models.ModelConfig` with ``arch="hybrid"``, so the
one trainer, checkpoints and ``load_model`` treat a hybrid like any other network. Of the
inherited fields, ``hidden``, ``layers`` (default 2), ``activation`` and ``dropout`` shape the
correction MLP; ``window`` is 1 (the physics state is the memory); ``init_window`` ``N > 1`` starts
every free run, in training too, from the state its FMU's estimator fits over the ``N`` samples up to ``y0``
(:mod:`nnfmu.hybrid.initial_state`; 1: the physics' init rule at ``y0``); ``kernel_size``, ``skip`` and
``skip_scale`` do not apply (the physics plays the part of the skip connection).

The physics is a spec that :func:`nnfmu.physics.resolve_physics` understands: a registered name
(:func:`nnfmu.physics.physics_names`; stored as the name, as before), a model file
``"path/to/file.py:NAME"``, a physics document or grey-box fit result ``"path/to/file.json"``, or a
:class:`~nnfmu.physics.PhysicsSystem` itself. Anything but a registered name is stored in the
config (and so in every checkpoint) as its physics document (:func:`nnfmu.physics.document.system_to_document`:
CasADi's serialization, never Python), so loading, exporting and scoring never need the file again.

Physical parameters are named as the entries of the physics' ``p`` vector
(``valve_system().parameters``: ``k_s``, ``C_max``, ...; the arm's tuple fields
flattened as ``f_b1`` .. ``f_b6``). A parameter file is a JSON object of such names
and numbers; a tuple field may also be given whole as a list (``"f_vis": [6 numbers]``)::

    {"k_s": 32500.0, "C_max": 4.2e-10, "d_c": 0.0}
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass
from typing import Mapping

from nnfmu.errors import ConfigError, ShapeError, UnknownOptionError
from nnfmu.hybrid.compiled_torch import BACKENDS
from nnfmu.hybrid.parameters import (document_system, document_text, ignorable_states, kinematic_states,
                                     normalise_physics_params, physics_system, registered_defaults)
from nnfmu.hybrid.parameters import load_physics_params  # noqa: F401  (nnfmu.hybrid exports it from here)
from nnfmu.limits import MAX_INIT_WINDOW
from nnfmu.models.config import ACTIVATIONS, ModelConfig
from nnfmu.physics import PhysicsSystem
from nnfmu.physics.document import system_to_document
from nnfmu.physics.registry import physics_entry, physics_names, resolve_physics

CORRECTIONS = ("derivative", "step")
HYBRID_ARCH = "hybrid"
#: A model the registry does not know gets ``correction_time = DEFAULT_CORRECTION_SAMPLES * Ts``: the
#: registered models' choices are 10 to 25 samples (slider 0.1 s at 10 ms, arm 1 s at 0.1 s, valve 1 ms at
#: 40 us). One sample made the first epochs' steps ten times too large: on a viscous slider fitted to Stribeck
#: data the first epoch's loss was 0.89 against 0.09 with ten samples.
DEFAULT_CORRECTION_SAMPLES = 10


@dataclass(frozen=True, kw_only=True)
class HybridConfig(ModelConfig):
    """Physics plus neural correction; see the module docstring for the inherited fields.

    Attributes
    ----------
    physics : str or PhysicsSystem or dict
        The CasADi physics model: a spec :func:`nnfmu.physics.resolve_physics` takes (a registered
        name, ``FILE.py:NAME``, ``FILE.json``), the system itself or its document. After
        construction it is a string: the registered name, or a label (the spec as given, or the
        system's name) when :attr:`physics_document` holds the model.
    physics_document : dict or None
        The physics as a :func:`~nnfmu.physics.document.system_to_document` document, filled in
        for anything but a registered name (None for those: their checkpoints stay as they were).
        When present it is the physics, whatever :attr:`physics` says.
    physics_params : mapping of str to float
        Values replacing the nominal ones (possibly wrong on purpose); a list expands a tuple field.
    train_physics : tuple of str or None
        Parameters trained with the network, in log-space: ``p = p_given * exp(gain * theta)``,
        ``theta`` starting at 0 (so they keep their sign and cannot cross zero; a parameter
        whose value is 0 cannot be trained this way), clipped to the parameter's ``min`` / ``max``
        where it has them. None (default): none for a registered model; for any other, its
        ``free_parameters`` (all when it names none) except those whose value is 0, so that a
        hybrid on a grey-box fit result continues the fit jointly with the network.
    train_physics_gain : float
        ``gain`` above. Adam moves ``theta`` by about ``lr`` per step, so a physical parameter
        changes by about ``gain * lr`` (relative) per step: 10 lets a 30 % error be corrected
        within tens of steps at lr = 3e-3, as fast as the network learns.
    correction : {'derivative', 'step'}
        ``'derivative'``: ``xdot = ode(x, u, p) + delta(x, u)`` inside every RK4 stage.
        ``'step'``: ``x+ = RK4_physics(x, u, p) + Ts * delta(x, u)``, one network call per sample.
    corrected_states : tuple of str or None
        States whose derivative ``delta`` corrects (None: the registered model's default, see
        :class:`nnfmu.physics.PhysicsEntry`; for a model the registry does not know, every state except the
        kinematic identities, those whose derivative is exactly another state such as ``dpos/dt = v``
        (:func:`nnfmu.hybrid.parameters.kinematic_states`), or every state if that leaves none).
    correction_inputs : tuple of str or None
        States the correction network sees, besides the inputs (the others' first-layer weights stay zero,
        :func:`~nnfmu.hybrid.parameters.hide_state_inputs`). None: every state for a registered model; for
        any other, every state some derivative of the ODE depends on, leaving out the ignorable ones
        (:func:`~nnfmu.hybrid.parameters.ignorable_states`: a position on a rail, whose value wanders beyond
        the training range on an integrating plant), or every state if that leaves none. A stored config
        without this field (from before it) sees every state, as it was trained.
    correction_time : float or None
        Seconds; ``delta_i = state_scale_i / correction_time * N_i`` (None: the registered model's
        default; :data:`DEFAULT_CORRECTION_SAMPLES` sample times of the physics for a model the registry
        does not know).
    n_sub : int or None
        RK4 sub-steps per sample (None: the physics' own choice).
    physics_backend : {'compiled', 'sx'}
        How torch evaluates the physics: compiled C (fast; without a C compiler it falls back to
        'sx' with a warning) or the :func:`~nnfmu.hybrid.sx_to_torch` translation. Both give
        CasADi's values and gradients (to 1e-12); only the speed differs.
    """

    arch: str = "hybrid"
    physics: str = "valve"
    physics_document: Mapping | str | None = dataclasses.field(default=None, repr=False)  # long: repr shows physics
    physics_params: Mapping = ()
    train_physics: tuple | None = None
    train_physics_gain: float = 10.0
    correction: str = "derivative"
    corrected_states: tuple | None = None
    correction_inputs: tuple | None = None
    correction_time: float | None = None
    n_sub: int | None = None
    physics_backend: str = "compiled"

    def __post_init__(self) -> None:
        if type(self) is HybridConfig and self.arch != HYBRID_ARCH:  # a subclass checks its own arch
            raise ConfigError(f"HybridConfig has arch 'hybrid', got {self.arch!r}; use ModelConfig for networks")
        system = self._resolve_physics()
        for name, valid in (("correction", CORRECTIONS), ("physics_backend", BACKENDS)):
            if getattr(self, name) not in valid:
                raise ConfigError(f"unknown {name} {getattr(self, name)!r}; choose one of {', '.join(valid)}")
        self._check_network()
        for name, n in (("n_u", len(system.inputs)), ("n_y", len(system.outputs))):
            if getattr(self, name) != n:
                raise ShapeError(f"the {self.physics} physics has {name} = {n}, got {getattr(self, name)!r}; "
                                 "train it on data of that system")
        pairs = dict(self.physics_params) if not isinstance(self.physics_params, Mapping) else self.physics_params
        object.__setattr__(self, "physics_params", normalise_physics_params(system, pairs, self.physics))
        if self.train_physics is None:
            object.__setattr__(self, "train_physics", self._default_train_physics(system))
        self._check_names("train_physics", [v.name for v in system.parameters], "parameter")
        self._check_trainable_nonzero()
        entry = registered_defaults(system, None if self.physics_document else self.physics)
        if self.corrected_states is None:
            default = entry.corrected_states if entry is not None else None
            kinematic = kinematic_states(system)
            dynamic = tuple(v.name for v in system.states if v.name not in kinematic)
            object.__setattr__(self, "corrected_states", default or dynamic or tuple(v.name for v in system.states))
        self._check_names("corrected_states", [v.name for v in system.states], "state")
        if not self.corrected_states:
            raise ConfigError("corrected_states is empty: the network would correct nothing; name at least one state")
        if self.correction_inputs is None:
            states = tuple(v.name for v in system.states)
            ignorable = () if entry is not None else ignorable_states(system)
            object.__setattr__(self, "correction_inputs", tuple(n for n in states if n not in ignorable) or states)
        self._check_names("correction_inputs", [v.name for v in system.states], "state")
        if self.correction_time is None:
            default = entry.correction_time if entry is not None else None
            object.__setattr__(self, "correction_time", default or DEFAULT_CORRECTION_SAMPLES * system.Ts)
        if not (isinstance(self.correction_time, (int, float)) and self.correction_time > 0):
            raise ConfigError(f"correction_time must be a positive number of seconds, got {self.correction_time!r}")
        object.__setattr__(self, "correction_time", float(self.correction_time))
        if not (isinstance(self.train_physics_gain, (int, float)) and 0 < self.train_physics_gain < math.inf):
            raise ConfigError(f"train_physics_gain must be a positive number, got {self.train_physics_gain!r}")
        object.__setattr__(self, "train_physics_gain", float(self.train_physics_gain))
        if self.n_sub is not None and (isinstance(self.n_sub, bool) or not isinstance(self.n_sub, int)
                                       or self.n_sub < 1):
            raise ConfigError(f"n_sub must be None or a positive integer number of RK4 sub-steps, got {self.n_sub!r}")

    def _resolve_physics(self) -> PhysicsSystem:
        """Turn :attr:`physics` into a registered name or a label plus :attr:`physics_document`; the system."""
        spec = self.physics
        if isinstance(spec, PhysicsSystem):
            object.__setattr__(self, "physics_document", system_to_document(spec))
            object.__setattr__(self, "physics", spec.name)
        elif isinstance(spec, Mapping):  # a physics document
            object.__setattr__(self, "physics_document", spec)
            object.__setattr__(self, "physics", str(spec.get("name", "physics")))
        elif not isinstance(spec, str) or not spec:
            raise ConfigError(f"physics must be a registered name ({', '.join(physics_names())}), FILE.py:NAME, "
                              f"FILE.json or a PhysicsSystem, got {spec!r}")
        elif self.physics_document is None and spec not in physics_names():
            object.__setattr__(self, "physics_document", system_to_document(resolve_physics(spec)))
        if self.physics_document is None:
            return physics_system(self.physics)
        object.__setattr__(self, "physics_document", document_text(self.physics_document))
        return document_system(self.physics_document)

    def system(self) -> PhysicsSystem:
        """The physics at its nominal parameters (before :attr:`physics_params`), built once per process."""
        if self.physics_document is not None:
            return document_system(self.physics_document)
        return physics_system(self.physics)

    def physics_key(self) -> tuple[str, str]:
        """What identifies the physics for caches: ``("name", name)`` or ``("document", json_text)``."""
        if self.physics_document is not None:
            return ("document", self.physics_document)
        return ("name", self.physics)

    def _default_train_physics(self, system: PhysicsSystem) -> tuple[str, ...]:
        if self.physics_document is None:
            return ()  # a registered model: the physics stays as given unless told (as before the registry)
        given = dict(self.physics_params)
        free = system.free_parameters if system.free_parameters is not None else [v.name for v in system.parameters]
        return tuple(v.name for v in system.parameters
                     if v.name in free and given.get(v.name, v.start) != 0.0)

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
        if self.increment or self.members != 1:
            raise ConfigError("a hybrid model starts from its physics state and predicts the physics' output; "
                              "increment and members do not apply to it: leave them out")
        if (isinstance(self.init_window, bool) or not isinstance(self.init_window, int)
                or not 1 <= self.init_window <= MAX_INIT_WINDOW):
            raise ShapeError(f"a hybrid's init_window (the samples its estimator fits the start state over) must "
                             f"be a whole number from 1 to {MAX_INIT_WINDOW:,}, got {self.init_window!r}")
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
        names = [v.name for v in self.system().parameters]
        zero = [n for n in self.train_physics if values[names.index(n)] == 0.0]
        if zero:
            raise ConfigError(f"cannot train {zero}: their value is 0, and physical parameters are trained in "
                              "log-space (p = p_given * exp(gain * theta)); give a nonzero starting value in the "
                              "parameter file, or leave them fixed")

    def parameter_values(self) -> list[float]:
        """The ``p`` vector before training: the nominal values with :attr:`physics_params` applied."""
        given = dict(self.physics_params)
        return [given.get(v.name, v.start) for v in self.system().parameters]

    def replace(self, **changes) -> "HybridConfig":
        """A copy with ``changes``; a new :attr:`physics` replaces the stored document and the network's state inputs
        too (unless given)."""
        if "physics" in changes:
            changes.setdefault("physics_document", None)
            changes.setdefault("correction_inputs", None)
        return super().replace(**changes)

    def to_dict(self) -> dict:
        """Plain dict (JSON- and ``weights_only``-safe); ``physics_params`` and the physics document as dicts.

        A registered model's config has no ``physics_document`` key (as before the registry), so
        checkpoints of built-in hybrids are the same as they were.
        """
        d = dataclasses.asdict(self)
        del d["member_configs"]  # one hybrid, never a mixed ensemble
        if self.physics_document is None:
            del d["physics_document"]
        else:
            d["physics_document"] = json.loads(self.physics_document)
        d["physics_params"] = dict(self.physics_params)
        d["train_physics"] = list(self.train_physics)
        d["corrected_states"] = list(self.corrected_states)
        d["correction_inputs"] = list(self.correction_inputs)
        return d

    @classmethod
    def from_dict(cls, d: Mapping) -> "HybridConfig":
        """Rebuild from :meth:`to_dict`; a config stored before :attr:`correction_inputs` sees every state."""
        config = super().from_dict(d)
        if isinstance(d, Mapping) and "correction_inputs" not in d and isinstance(config, HybridConfig):
            config = config.replace(correction_inputs=tuple(v.name for v in config.system().states))
        return config
