"""``ModelConfig``: the typed, frozen description of one network (architecture and sizes).

A config is everything needed to rebuild a network before its weights are
loaded, so checkpoints store it as a plain dict (:meth:`ModelConfig.to_dict`)
and rebuild it with :meth:`ModelConfig.from_dict`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Mapping

from nnfmu.errors import ConfigError, ShapeError, check_options
from nnfmu.models import architectures

ARCHS = ("mlp", "rnn", "lstm", "gru", "tcn")
RECURRENT_ARCHS = ("rnn", "lstm", "gru")
WINDOW_ARCHS = ("mlp", "tcn")
ACTIVATIONS = ("tanh", "relu", "sigmoid", "elu", "silu")
# nn.RNN only knows these two nonlinearities.
RNN_ACTIVATIONS = ("tanh", "relu")

# Per-architecture defaults for the options left as None.
_DEFAULT_LAYERS = {"mlp": 2, "rnn": 1, "lstm": 1, "gru": 1, "tcn": 3}
_DEFAULT_MLP_WINDOW = 4
# What the members of one ensemble share: their ports, the window their init sees, their linear path, their mode.
MEMBER_SHARED = ("n_u", "n_y", "init_window", "linear_order", "increment")


def tcn_receptive_field(layers: int, kernel_size: int) -> int:
    """Number of past samples a TCN with dilations 1, 2, 4, ... sees: ``1 + (k-1)(2^layers - 1)``."""
    return 1 + (kernel_size - 1) * (2 ** layers - 1)


@dataclass(frozen=True, kw_only=True)
class ModelConfig:
    """Architecture and sizes of a step network.

    Attributes
    ----------
    arch : {'mlp', 'rnn', 'lstm', 'gru', 'tcn'}
    n_u, n_y : int
        Number of inputs and outputs of the system.
    hidden : int
        Width of every hidden layer (MLP units, recurrent state size, TCN channels).
    layers : int or None
        Hidden layers (MLP), stacked recurrent layers, or dilated convolution
        layers (TCN, dilation ``2**i`` in layer ``i``). None picks the
        architecture's default: MLP 2, RNN/LSTM/GRU 1, TCN 3.
    window : int or None
        ``L``, the number of past samples of ``[y, u]`` the network sees. MLP:
        free (default 4). TCN: must equal its receptive field
        ``1 + (kernel_size-1)(2**layers - 1)`` (None computes it). Recurrent
        networks see one sample, so their window is 1.
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

    def __post_init__(self) -> None:
        self._check_arch()
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
        if self.arch == "tcn" and self.kernel_size < 2:
            raise ShapeError(f"a TCN needs kernel_size >= 2, got {self.kernel_size}")
        if self.layers is None:
            object.__setattr__(self, "layers", self._default_layers())
        if not isinstance(self.layers, int) or self.layers < 1:
            raise ShapeError(f"ModelConfig.layers must be a positive integer, got {self.layers!r}")
        object.__setattr__(self, "window", self._resolve_window())
        if not 0.0 <= float(self.dropout) < 1.0:
            raise ConfigError(f"dropout must be in [0, 1), got {self.dropout!r}")
        object.__setattr__(self, "dropout", float(self.dropout))
        object.__setattr__(self, "skip_scale", float(self.skip_scale))
        object.__setattr__(self, "skip", bool(self.skip))
        object.__setattr__(self, "increment", bool(self.increment))
        if self.increment and not self.skip:
            raise ConfigError("increment=True predicts y_{k+1} - y_k, which needs skip=True; drop skip=False")
        valid_act = RNN_ACTIVATIONS if self.arch == "rnn" else ACTIVATIONS
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

    # ---- what a subclass of another architecture overrides (a plugin's config, docs/design.md) -------------
    def _check_arch(self) -> None:
        """Raise ConfigError unless ``arch`` is one this class describes (here: the five networks)."""
        if self.arch not in ARCHS:
            raise ConfigError(f"unknown architecture {self.arch!r}; choose one of {', '.join(ARCHS)}")

    def _default_layers(self) -> int:
        """``layers`` when left out."""
        return _DEFAULT_LAYERS[self.arch]

    def _resolve_window(self) -> int:
        """The window ``L`` (samples seen per step) from the given ``window`` (None: the default)."""
        w = self.window
        if w is not None and (not isinstance(w, int) or isinstance(w, bool) or w < 1):
            raise ShapeError(f"ModelConfig.window must be a positive integer, got {w!r}")
        if self.arch in RECURRENT_ARCHS:
            if w not in (None, 1):
                raise ShapeError(f"a {self.arch.upper()} sees one sample per step (its memory is the hidden "
                                 f"state), so window must be 1, got {w}; leave window out")
            return 1
        if self.arch == "tcn":
            field = tcn_receptive_field(self.layers, self.kernel_size)
            if w not in (None, field):
                raise ShapeError(f"a TCN with {self.layers} layers and kernel_size {self.kernel_size} sees "
                                 f"{field} samples, got window={w}; pass window={field}, leave it out, or "
                                 "change layers/kernel_size")
            return field
        return _DEFAULT_MLP_WINDOW if w is None else w

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

        An architecture registered by another package (:mod:`nnfmu.models.architectures`: the hybrid,
        a plugin) is rebuilt by its own config class.
        """
        if cls is ModelConfig and isinstance(d, Mapping) and d.get("arch") not in ARCHS:
            other = architectures.config_class(str(d.get("arch")))
            if other is not None and other is not cls:
                return other.from_dict(d)
        check_options(d, {f.name for f in dataclasses.fields(cls)}, cls.__name__)
        d = dict(d)
        if isinstance(d.get("member_configs"), list):  # read back from JSON
            d["member_configs"] = tuple(d["member_configs"])
        return cls(**d)

    def replace(self, **changes) -> "ModelConfig":
        """A copy with ``changes``; sizes derived from the changed fields are recomputed."""
        check_options(changes, {f.name for f in dataclasses.fields(self)}, "ModelConfig")
        if "arch" in changes:
            changes.setdefault("layers", None)
        if {"arch", "layers", "kernel_size"} & set(changes):
            changes.setdefault("window", None if self.arch != "mlp" or "arch" in changes else self.window)
        return dataclasses.replace(self, **changes)

