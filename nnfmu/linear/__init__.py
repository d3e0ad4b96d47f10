"""Linear state-space baseline: subspace identification, output-error refinement, CasADi export.

``identify_linear(dataset, order=None, init="estimate")`` returns a
:class:`LinearModel` (``x[k+1] = A x + B u + b``, ``y = C x + d``, ``D = 0``) in the
dataset's units; ``model.casadi_model()`` is the ``(init, step)`` pair that
``nnfmu.export.build_fmu`` turns into an FMU. ``nnfmu linear`` is the command line.
"""

from nnfmu.linear.identify import LinearConfig, identify_linear
from nnfmu.linear.model import LinearModel, load_linear
from nnfmu.linear.refine import X0_OPTIONS, EarlyStop, RefineResult, refine
from nnfmu.linear.statespace import (
    INIT_OPTIONS,
    StateSpace,
    free_run,
    init_gains,
    stabilise,
)
from nnfmu.linear.subspace import SubspaceFit, fit_subspace, realise

__all__ = [
    "INIT_OPTIONS",
    "X0_OPTIONS",
    "EarlyStop",
    "LinearConfig",
    "LinearModel",
    "RefineResult",
    "StateSpace",
    "SubspaceFit",
    "fit_subspace",
    "free_run",
    "identify_linear",
    "init_gains",
    "load_linear",
    "realise",
    "refine",
    "stabilise",
]
