"""Resampling to a coarser sample time by an integer factor, with an anti-aliasing filter.

Keeping every q-th sample of a 1 kHz record folds everything above the new
Nyquist frequency back into the band a model must learn; a network then fits
noise that no longer looks like noise. :func:`decimate` low-pass filters first,
in stages of at most 10: a linear-phase FIR filter (``scipy.signal.firwin``,
Hamming window, ``10 q + 1`` taps, cut off at the new Nyquist frequency, gain
exactly 1 at zero frequency) run forward and backward by
``scipy.signal.filtfilt`` (zero phase, odd extension at the ends, so a record
keeps its level up to its first and last sample). Sample ``k`` of the result
is taken at ``t_0 + k * q * Ts`` without delay. scipy's own ``decimate`` is not
used: its Chebyshev filter lowers a constant level by 1 % (its passband ripple
sits below 0 dB at zero frequency), and its FIR path pads the ends with zeros.
"""

from __future__ import annotations

import numpy as np

from nnfmu.errors import DataError

_MAX_STAGE = 10
_TAPS_PER_FACTOR = 10


def stages(factor: int) -> list[int]:
    """Split ``factor`` into decimation stages of at most 10 where it factors so (1000 -> [10, 10, 10])."""
    out, rest = [], factor
    while rest > 1:
        step = next((d for d in range(_MAX_STAGE, 1, -1) if rest % d == 0), rest)
        out.append(step)
        rest //= step
    return out


def decimate(x: np.ndarray, factor: int, where: str = "trajectory") -> np.ndarray:
    """Low-pass filter ``x`` (n_steps, n) along time and keep every ``factor``-th sample.

    Returns an array of shape ``(ceil(n_steps / factor), n)``; ``factor == 1`` returns ``x`` unchanged.
    """
    from scipy.signal import filtfilt, firwin

    if isinstance(factor, bool) or not isinstance(factor, (int, np.integer)) or factor < 1:
        raise DataError(f"the resampling factor must be a positive integer, got {factor!r}")
    if factor == 1:
        return x
    y = np.asarray(x, dtype=np.float64)
    for q in stages(int(factor)):
        taps = _TAPS_PER_FACTOR * q + 1
        if len(y) <= taps:
            raise DataError(f"{where} has {len(x)} samples, too short to resample by {factor} (the anti-aliasing "
                            f"filter spans {taps} samples per stage of at most 10); lower the factor or drop the "
                            "short record")
        b = firwin(taps, 1.0 / q)  # cutoff relative to the Nyquist frequency; scaled to gain 1 at 0 Hz
        y = filtfilt(b, [1.0], y, axis=0, padtype="odd", padlen=min(3 * taps, len(y) - 1))[::q]
    return np.ascontiguousarray(y)
