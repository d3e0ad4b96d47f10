"""``ModelConfig``: the public base of every architecture's config (the fields every network shares).

A config is everything needed to rebuild a network before its weights are
loaded, so checkpoints store it as a plain dict (:meth:`ModelConfig.to_dict`)
and rebuild it with :meth:`ModelConfig.from_dict`. Each architecture subclasses it in its
own folder (``nnfmu/networks/<name>/config.py``, ``nnfmu/ss/config.py``, a plugin's) and names the
subclass in its record (:mod:`nnfmu.models.architectures`); ``ModelConfig(arch=NAME, ...)`` and
:meth:`ModelConfig.from_dict` build that subclass, so this module knows no architecture by name.
A subclass adapts the shared rules through the public hooks :meth:`~ModelConfig.default_layers`
and :meth:`~ModelConfig.resolve_window`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Mapping

from nnfmu.errors import ConfigError, ShapeError, check_options
from nnfmu.models import architectures

ACTIVATIONS = ("tanh", "relu", "sigmoid", "elu", "silu")
# What the members of one ensemble share: their ports, the window their init sees, their linear path, their mode.
MEMBER_SHARED = ("n_u", "n_y", "init_window", "linear_order", "increment")


def _config_class(arch) -> type:
    """The config class the record of ``arch`` names (a ModelConfig subclass); ConfigError otherwise."""
    cls = architectures.architecture(str(arch)).get("config_class")
    if not (isinstance(cls, type) and issubclass(cls, ModelConfig)):
        raise ConfigError(f"the record of architecture {arch!r} names the config class {cls!r}, which is not a "
                          "ModelConfig subclass; fix its config_class")
    return cls


@dataclass(frozen=True, kw_only=True)
class ModelConfig:
    """Architecture and sizes of a step network: the fields every architecture shares.

    ``ModelConfig(arch=NAME, ...)`` builds the config class that ``NAME``'s record names (e.g.
    :class:`~nnfmu.networks.recurrent.config.RecurrentConfig` for ``"gru"``), as ``pathlib.Path``
    builds the path of its platform; the fields' defaults and checks below are the shared ones, and
    each architecture documents what its own rules add.

    Attributes
    ----------
    arch : str
        A registered architecture's name (:func:`nnfmu.models.architectures.names`).
    n_u, n_y : int
        Number of inputs and outputs of the system.
    hidden : int
        Width of every hidden layer (MLP units, recurrent state size, TCN channels).
    layers : int or None
        Hidden layers (MLP), stacked recurrent layers, or dilated convolution
        layers (TCN, dilation ``2**i`` in layer ``i``). None picks the
        architecture's default (:meth:`default_layers`).
    window : int or None
        ``L``, the number of past samples of ``[y, u]`` the network sees (:meth:`resolve_window`;
        1 for a network whose memory is its state).
    kernel_size : int
        TCN convolution kernel size (ignored otherwise).
    dropout : float
        Dropout probability on hidden activations, in [0, 1); active in training only.
    skip : bool
        Predict the increment: ``y_{k+1} = y_k + skip_scale * N(...)`` (in normalised units).
    skip_scale : float
        Scale of the increment; a small value starts training near "hold the last output".
    increment : bool
        Increment mode, for integrating plants (a position driven by a force): ``y_{k+1} = y_k +
        s * N`` with ``s`` per output the standard deviation of the one-step increments of the
        training data (a buffer, ``increment_scale``, in normalised units; it replaces
        ``skip_scale``), and the network sees its past outputs relative to the newest one, so
        that shifting the output shifts the whole response. Needs ``skip``.
    init_window : int
        ``N``, the samples of ``[y, u]`` that :meth:`StepModel.init` sees: the initial ``(y0, u0)``
        and the ``N - 1`` samples before it. 1 (the default): ``init(y0, u0)`` alone, the plant at
        rest before t0. RNN/LSTM/GRU map the window to their hidden state with a learned encoder
        (:mod:`nnfmu.models.encoder`); the MLP and TCN fill their own window with it.
    encoder_hidden : int
        Width of the two hidden layers of the learned encoder (``init_window > 1``, recurrent only).
    members : int
        1: one network. K > 1: an ensemble of K networks of this config (trained with different
        seeds, :func:`nnfmu.training.train_seeds`) whose mean output is fed back to all of them as
        the one prediction (:mod:`nnfmu.models.ensemble`).
    member_configs : tuple of dict
        Empty: every member of an ensemble is this config with ``members=1``. Otherwise a *mixed*
        ensemble (the time-budget search keeps one): the K members' own configs (:meth:`to_dict`),
        each a single network with this config's ``n_u``, ``n_y``, ``init_window``, ``linear_order``
        and ``increment``; the other fields here are the first member's.
    linear_order : int
        0: the network alone. ``n_z > 0``: the network as a zero-initialised correction on a linear path
        of ``n_z`` states, started at the identified linear baseline (:mod:`nnfmu.models.linear_path`);
        the path replaces the skip connection and increment mode.
    activation : str
        Nonlinearity of the MLP and TCN layers and of the RNN (RNN: 'tanh' or 'relu').
        The LSTM and GRU have their fixed gate nonlinearities.
    """

    arch: str
    n_u: int
    n_y: int
    hidden: int = 32
    layers: int | None = None
    window: int | None = None
    kernel_size: int = 3
    dropout: float = 0.0
    skip: bool = True
    skip_scale: float = 0.1
    activation: str = "tanh"
    increment: bool = False
    init_window: int = 1
    encoder_hidden: int = 64
    members: int = 1
    member_configs: tuple = dataclasses.field(default=(), hash=False)
    linear_order: int = 0

    def __new__(cls, *args, **kwargs):
        if cls is ModelConfig and "arch" in kwargs:
            cls = _config_class(kwargs["arch"])
        return super().__new__(cls)

    def __post_init__(self) -> None:
        self.check_arch()
        for name in ("n_u", "n_y", "hidden", "kernel_size", "init_window", "encoder_hidden", "members"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise ShapeError(f"ModelConfig.{name} must be a positive integer, got {value!r}")
        self._check_member_configs()
        if not isinstance(self.linear_order, int) or isinstance(self.linear_order, bool) or self.linear_order < 0:
            raise ShapeError(f"ModelConfig.linear_order must be an integer >= 0, got {self.linear_order!r}")
        if self.linear_order and self.increment:
            raise ConfigError("increment mode and a linear path both carry the output from step to step: the path "
                              "(linear_order > 0) already integrates what the linear model integrates; drop increment "
                              "or set linear_order=0")
        if self.layers is None:
            object.__setattr__(self, "layers", self.default_layers())
        if not isinstance(self.layers, int) or self.layers < 1:
            raise ShapeError(f"ModelConfig.layers must be a positive integer, got {self.layers!r}")
        w = self.window
        if w is not None and (not isinstance(w, int) or isinstance(w, bool) or w < 1):
            raise ShapeError(f"ModelConfig.window must be a positive integer, got {w!r}")
        object.__setattr__(self, "window", self.resolve_window())
        if not 0.0 <= float(self.dropout) < 1.0:
            raise ConfigError(f"dropout must be in [0, 1), got {self.dropout!r}")
        object.__setattr__(self, "dropout", float(self.dropout))
        object.__setattr__(self, "skip_scale", float(self.skip_scale))
        object.__setattr__(self, "skip", bool(self.skip))
        object.__setattr__(self, "increment", bool(self.increment))
        if self.increment and not self.skip:
            raise ConfigError("increment=True predicts y_{k+1} - y_k, which needs skip=True; drop skip=False")
        valid_act = self.activations()
        if self.activation not in valid_act:
            raise ConfigError(f"activation {self.activation!r} is not available for arch {self.arch!r}; "
                              f"choose one of {', '.join(valid_act)}")

    def _check_member_configs(self) -> None:
        """``member_configs`` as a tuple of dicts, one per member, that agree with this config on what they share."""
        configs = self.member_configs
        if not configs:
            object.__setattr__(self, "member_configs", ())
            return
        if not isinstance(configs, (list, tuple)) or not all(isinstance(d, Mapping) for d in configs):
            raise ShapeError("ModelConfig.member_configs must be a sequence of member config dicts")
        configs = tuple(dict(d) for d in configs)
        if len(configs) != self.members:
            raise ShapeError(f"ModelConfig.member_configs has {len(configs)} configs for members={self.members}")
        for i, d in enumerate(configs):
            if d.get("members", 1) != 1 or d.get("member_configs"):
                raise ShapeError(f"member {i} of an ensemble must be one network (members=1), got {d.get('members')}")
            for name in MEMBER_SHARED:
                default = next(f.default for f in dataclasses.fields(ModelConfig) if f.name == name)
                if d.get(name, default) != getattr(self, name):
                    raise ShapeError(f"member {i} of an ensemble has {name}={d.get(name, default)!r}, the ensemble "
                                     f"{getattr(self, name)!r}: the members of one model share "
                                     f"{', '.join(MEMBER_SHARED)}")
        object.__setattr__(self, "member_configs", configs)

    # ---- what an architecture's config overrides (docs/design.md, "Adding an architecture") --------------
    def check_arch(self) -> None:
        """Raise ConfigError unless the record of ``arch`` names this config's class (or a base of it)."""
        if not isinstance(self, _config_class(self.arch)):
            raise ConfigError(f"{type(self).__name__} cannot describe arch {self.arch!r}, whose config is "
                              f"{_config_class(self.arch).__name__}; build it with ModelConfig(arch={self.arch!r}, ...)")

    def default_layers(self) -> int:
        """``layers`` when left out (here 1)."""
        return 1

    def resolve_window(self) -> int:
        """The window ``L`` (samples seen per step) from the given ``window`` (None: the default; a positive int).

        Here: one sample per step, the state is the memory.
        """
        if self.window not in (None, 1):
            raise ShapeError(f"a {self.arch} network sees one sample per step (its memory is its state), so window "
                             f"must be 1, got {self.window}; leave window out")
        return 1

    def activations(self) -> tuple[str, ...]:
        """The names ``activation`` may take (here :data:`ACTIVATIONS`)."""
        return ACTIVATIONS

    @property
    def n_in(self) -> int:
        """Channels of one sample of the network input ``[y_k, u_k]``."""
        return self.n_y + self.n_u

    def to_dict(self) -> dict:
        """Plain dict (JSON- and ``weights_only``-safe); ``member_configs`` only for a mixed ensemble, so that
        the record of any other model is as it was before mixed ensembles."""
        d = dataclasses.asdict(self)
        if not self.member_configs:
            del d["member_configs"]
        return d

    @classmethod
    def from_dict(cls, d: Mapping) -> "ModelConfig":
        """Rebuild from :meth:`to_dict`; unknown keys raise :class:`~nnfmu.errors.UnknownOptionError`.

        Called on ModelConfig, the config class of ``d["arch"]``'s record rebuilds it
        (:mod:`nnfmu.models.architectures`).
        """
        if cls is ModelConfig and isinstance(d, Mapping) and "arch" in d:
            return _config_class(d["arch"]).from_dict(d)
        check_options(d, {f.name for f in dataclasses.fields(cls)}, cls.__name__)
        d = dict(d)
        if isinstance(d.get("member_configs"), list):  # read back from JSON
            d["member_configs"] = tuple(d["member_configs"])
        return cls(**d)

    def replace(self, **changes) -> "ModelConfig":
        """A copy with ``changes``; sizes derived from the changed fields are recomputed.

        A new ``arch`` of another config class keeps the shared fields (those of ModelConfig) only.
        """
        check_options(changes, {f.name for f in dataclasses.fields(self)}, "ModelConfig")
        if "arch" in changes:
            changes.setdefault("layers", None)
            changes.setdefault("window", None)
            if _config_class(changes["arch"]) is not type(self):
                shared = {f.name: getattr(self, f.name) for f in dataclasses.fields(ModelConfig)}
                return ModelConfig(**{**shared, **changes})
        if {"layers", "kernel_size"} & set(changes):
            changes.setdefault("window", self.kept_window())
        return dataclasses.replace(self, **changes)

    def kept_window(self) -> int | None:
        """The ``window`` that :meth:`replace` keeps when ``layers`` or ``kernel_size`` change (here None: derived
        again); a network whose window is free of them keeps its own."""
        return None

