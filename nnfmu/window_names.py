"""Names of an FMU's init-window parameters, shared by the FMU builder and the scoring (fmpy).

A model with an init window of ``N`` samples (:mod:`nnfmu.models.encoder`) takes the ``N - 1``
samples before t0 of every output and input, oldest first, as fixed parameters set before
initialisation, beside the ``<y>_start`` parameters that hold ``y0``:

- FMI 3: one array parameter per channel, ``<name>_past`` of ``N - 1`` values;
- FMI 2 (no arrays): one scalar per sample and channel, ``<name>_past[1]`` .. ``<name>_past[N-1]``
  (``[1]`` the oldest, ``[N-1]`` the sample just before t0); fmpy's ``start_values`` and the
  Reference FMUs' ``fmusim --start-value`` set them by these names.

A sample whose parameters are not set leaves the plant at rest there: the FMU uses ``y0``
(``<y>_start``) and the first input ``u0`` in their place, as ``init(y0, u0)`` always assumed.
"""

from __future__ import annotations

import re
from typing import Sequence

import numpy as np


def past_name(channel: str) -> str:
    """The window parameter of one channel: ``<channel>_past`` (FMI 3 array, FMI 2 prefix)."""
    return f"{channel}_past"


def past_element(channel: str, j: int) -> str:
    """FMI 2 scalar of sample ``j`` (1 = oldest) of one channel: ``<channel>_past[j]``."""
    return f"{channel}_past[{j}]"


def fmu_init_window(model_description, outputs: Sequence[str]) -> int:
    """``N`` of an FMU read by fmpy: 1 + the number of window samples of its first output (1 without any)."""
    if not outputs:
        return 1
    name = past_name(outputs[0])
    pattern = re.compile(re.escape(name) + r"\[(\d+)\]$")
    n_past = 0
    for v in model_description.modelVariables:
        if v.name == name and getattr(v, "shape", None):
            n_past = int(np.prod(v.shape))
        elif pattern.match(v.name):
            n_past += 1
    return 1 + n_past


def window_start_values(info, output_names: Sequence[str], input_names: Sequence[str], y_past: np.ndarray,
                        u_past: np.ndarray) -> dict:
    """fmpy ``start_values`` of an FMU's window parameters from ``y_past`` (n, n_y), ``u_past`` (n, n_u).

    ``n`` must be the FMU's ``init_window - 1`` (:class:`nnfmu.cosim.FmuInfo`).
    """
    values = {}
    for names, past in ((output_names, y_past), (input_names, u_past)):
        past = np.asarray(past, dtype=float)
        for j, channel in enumerate(names):
            column = past[:, j]
            if info.fmi_version.startswith("3"):
                values[past_name(channel)] = [float(v) for v in column]
            else:
                values.update({past_element(channel, k + 1): float(v) for k, v in enumerate(column)})
    return values
