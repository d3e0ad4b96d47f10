"""``SSConfig``: the subspace-encoder state-space network's sizes (``arch="ss"``, :mod:`nnfmu.ss`)."""

from __future__ import annotations

from dataclasses import dataclass

from nnfmu.errors import ConfigError, ShapeError
from nnfmu.models import ModelConfig

SS_ARCH = "ss"


@dataclass(frozen=True, kw_only=True)
class SSConfig(ModelConfig):
    """:class:`~nnfmu.models.ModelConfig` for ``arch="ss"``.

    The shared fields mean: ``hidden`` and ``layers``, the width and number of hidden layers of each of the
    state map ``f`` and the output map ``h`` (default 64 and 2, SUBNET's); ``init_window`` ``N``, the measured
    samples the encoder sees (SUBNET's ``n_a = n_b = N``); ``encoder_hidden``, the encoder's width;
    ``activation``, the hidden layers' nonlinearity; ``linear_order``, the identified linear model's states
    that the state starts as. ``window`` is 1 (the state is the memory); ``skip`` and ``kernel_size`` are not
    used; ``increment`` is refused (the linear path integrates what the plant integrates).

    Attributes
    ----------
    states : int or None
        ``n_x``, the size of the latent state. None: the linear path's order (``linear_order``), or without a
        path ``max(2 n_y, 4)``. On a path it is at least ``linear_order``; the states beyond it start with no
        linear dynamics and are driven by ``f`` alone.
    """

    arch: str = SS_ARCH
    hidden: int = 64
    states: int | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.increment:
            raise ConfigError("the ss network has no increment mode: its linear path integrates what the plant "
                              "integrates; drop --increment")
        s = self.states
        if s is not None and (not isinstance(s, int) or isinstance(s, bool) or s < 1):
            raise ShapeError(f"SSConfig.states must be a positive integer or None, got {s!r}")
        if s is not None and s < self.linear_order:
            raise ShapeError(f"the ss network's state ({s}) must hold its linear path's {self.linear_order} states; "
                             f"pass states >= {self.linear_order} or leave it out")

    def default_layers(self) -> int:
        return 2

    def resolve_window(self) -> int:
        if self.window not in (None, 1):
            raise ShapeError(f"the ss network's memory is its state: it sees one sample per step, so window must "
                             f"be 1, got {self.window}; leave window out")
        return 1

    @property
    def n_states(self) -> int:
        """``n_x`` of the latent state (see :attr:`states`)."""
        if self.states is not None:
            return self.states
        return self.linear_order if self.linear_order else max(2 * self.n_y, 4)
