"""Grey-box identification: a physics model's free parameters from measured data (``nnfmu fit``).

- :func:`fit_greybox` / :class:`FitConfig` / :class:`GreyboxFit`: the fit by simulation error over windows
  with estimated initial states, bounds, several starts, Gauss-Newton standard errors and scores.
- :func:`identifiability_report`: which parameters the data determine (correlations, weak directions, flags
  that name the fix; :mod:`nnfmu.greybox.identifiability`), in every fit's report.
- :func:`save_fit` / :func:`load_fit`: the fitted model and its report as JSON (``nnfmu-greybox-fit/1``).
"""

from nnfmu.greybox.document import FIT_FORMAT, fit_document, load_fit, save_fit
from nnfmu.greybox.fit import FitConfig, GreyboxFit, fit_greybox, score_system, standard_errors
from nnfmu.greybox.identifiability import RELATIVE_LIMIT, identifiability_report
from nnfmu.greybox.solvers import SOLVERS

__all__ = ["FIT_FORMAT", "FitConfig", "GreyboxFit", "RELATIVE_LIMIT", "SOLVERS", "fit_document", "fit_greybox",
           "identifiability_report", "load_fit", "save_fit", "score_system", "standard_errors"]
