"""Export: trained networks to CasADi, and any CasADi ``(init, step)`` model to a standalone FMU.

- :func:`to_casadi` (torch network -> ``(init, step)`` CasADi Functions) and
  :func:`casadi_model` (the same, bundled with its :class:`nnfmu.system.SystemSpec`);
- :func:`build_fmu` (any :class:`nnfmu.system.CasadiModel` -> ``.fmu``, FMI 2.0 or 3.0 co-simulation).

``python -m nnfmu.export model.pt -o model.fmu`` is the command line.
Names are imported on first use so that ``import nnfmu.export`` does not import torch.
(The torch part lives in :mod:`nnfmu.export.torch_to_casadi`: a submodule named ``to_casadi`` would
shadow the function of that name once imported.)
"""

from __future__ import annotations

from nnfmu._lazy import lazy_exports

_LAZY = {
    "to_casadi": "nnfmu.export.torch_to_casadi",
    "casadi_model": "nnfmu.export.torch_to_casadi",
    "build_fmu": "nnfmu.export.fmu",
    "BuildOptions": "nnfmu.export.fmu",
}

__all__ = sorted(_LAZY)


__getattr__, __dir__ = lazy_exports("nnfmu.export", globals(), _LAZY)
