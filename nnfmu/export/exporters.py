"""Exporters of model classes defined above ``export``: a registry that their packages fill when imported.

:func:`nnfmu.export.to_casadi` and :func:`nnfmu.export.casadi_model` translate the networks of
:mod:`nnfmu.models` themselves. A package built on top of ``export`` with a model class of its own
(``nnfmu.hybrid``, or a third party) registers how to export it when it is imported::

    register_exporter(HybridStepModel, to_casadi=hybrid_to_casadi, casadi_model=hybrid_casadi_model)

so that ``export`` never imports the packages above it. A model is an instance of a class that its
package defines, so that package has been imported, and its exporter registered, before the model exists.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from nnfmu.errors import ConfigError

__all__ = ["Exporter", "register_exporter", "exporter_for"]


@dataclass(frozen=True)
class Exporter:
    """How to export one model class.

    ``to_casadi(model, *, verify) -> (init, step)``: the CasADi Functions, as :func:`nnfmu.export.to_casadi`.
    ``casadi_model(model, *, name) -> CasadiModel``: the Functions with their SystemSpec, as
    :func:`nnfmu.export.casadi_model`.
    """

    to_casadi: Callable
    casadi_model: Callable


_EXPORTERS: dict[type, Exporter] = {}


def register_exporter(model_class: type, *, to_casadi: Callable, casadi_model: Callable) -> None:
    """Export instances of ``model_class`` (and its subclasses) with these functions.

    Registering the same functions again is a no-op; other functions for a registered class are an error.
    """
    exporter = Exporter(to_casadi, casadi_model)
    if _EXPORTERS.get(model_class, exporter) != exporter:
        raise ConfigError(f"an exporter for {model_class.__name__} is already registered; register "
                          f"a subclass of it instead")
    _EXPORTERS[model_class] = exporter


def exporter_for(model) -> Exporter | None:
    """The exporter registered for ``model``'s class or the nearest base class; None for the built-in networks."""
    for cls in type(model).__mro__:
        if cls in _EXPORTERS:
            return _EXPORTERS[cls]
    return None
