"""Seeded excitation signals that respect amplitude and slew-rate limits by construction.

A signal is composed of sections (physics.md section 2):

- ``hold``: a constant level (a static section);
- ``ramp``: a straight line between two levels;
- ``aprbs``: random levels held for random times (holds cover the settling time);
- ``multisine``: harmonics of a base frequency with Schroeder or random phases;
- ``chirp``: a sine whose frequency sweeps logarithmically through a band.

The composed reference ``r`` is clipped to ``[u_min, u_max]`` and passed
through a slew-rate limiter, ``u[k] = u[k-1] + clip(r[k] - u[k-1], +-rate_max Ts)``.
Because ``u[k]`` lies between ``u[k-1]`` and ``r[k]``, both inside the range,
the limits hold exactly for every sample. The multisine and chirp amplitudes
are chosen so that their own slope stays below ``rate_max``
(``sum A_k w_k <= rate_max`` and ``A(t) <= rate_max / (2 pi f(t))``), so the
limiter only acts at section boundaries and APRBS/ramp steps.

Everything is drawn from a :class:`numpy.random.Generator`; the same seed
gives the same signal. Example (two valve voltages, 500 samples at 40 us)::

    limits = [SignalLimits(u_min=0, u_max=250, rate_max=5e5)] * 2
    u = excitation(500, Ts=40e-6, limits=limits, config=cfg, seed=3)   # (500, 2) in V
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from nnfmu.errors import ConfigError, ShapeError

__all__ = ["SignalLimits", "ExcitationConfig", "SECTION_KINDS", "excitation", "excitation_reference",
           "excitation_channel",
           "slew_limit", "hold", "ramp", "aprbs", "multisine", "chirp"]

SECTION_KINDS = ("hold", "ramp", "aprbs", "multisine", "chirp")


@dataclass(frozen=True, kw_only=True)
class SignalLimits:
    """Limits of one input channel: range ``[u_min, u_max]`` and slew rate ``rate_max`` (units per second)."""

    u_min: float
    u_max: float
    rate_max: float

    def __post_init__(self) -> None:
        if not (np.isfinite(self.u_min) and np.isfinite(self.u_max) and self.u_min < self.u_max):
            raise ConfigError(f"expected finite u_min < u_max, got u_min={self.u_min}, u_max={self.u_max}")
        if not (np.isfinite(self.rate_max) and self.rate_max > 0):
            raise ConfigError(f"expected a positive finite rate_max (units/s), got {self.rate_max}")


@dataclass(frozen=True, kw_only=True)
class ExcitationConfig:
    """How sections are drawn; all times in seconds, frequencies in Hz.

    Attributes
    ----------
    section_time : (float, float)
        Range of the duration of one section.
    aprbs_hold : (float, float)
        Range of the APRBS hold times (the lower end should cover the settling time).
    multisine_band, chirp_band : (float, float)
        Frequency bands; the multisine's base frequency is drawn from the lower half-octave.
    kinds, weights : tuple
        Section kinds to draw from (any of :data:`SECTION_KINDS`) and their relative probabilities.
    extreme_fraction : float
        Fraction of hold and APRBS levels put exactly at ``u_min`` or ``u_max``, so that
        saturated operating points (e.g. end-stop contacts) are well represented.
    phases : str
        ``"schroeder"`` or ``"random"`` multisine phases.
    """

    section_time: tuple[float, float]
    aprbs_hold: tuple[float, float]
    multisine_band: tuple[float, float]
    chirp_band: tuple[float, float]
    kinds: tuple[str, ...] = SECTION_KINDS
    weights: tuple[float, ...] = (1.0, 1.0, 1.0, 1.0, 1.0)
    extreme_fraction: float = 0.2
    phases: str = "schroeder"

    def __post_init__(self) -> None:
        bad = sorted(set(self.kinds) - set(SECTION_KINDS))
        if bad:
            raise ConfigError(f"unknown section kind(s) {bad}; valid kinds are {', '.join(SECTION_KINDS)}")
        if len(self.weights) != len(self.kinds) or min(self.weights, default=0) < 0 or sum(self.weights) <= 0:
            raise ConfigError(f"expected {len(self.kinds)} non-negative weights with a positive sum, "
                              f"got {self.weights}")
        for name in ("section_time", "aprbs_hold", "multisine_band", "chirp_band"):
            lo, hi = getattr(self, name)
            if not 0 < lo <= hi:
                raise ConfigError(f"{name} must be (low, high) with 0 < low <= high, got {(lo, hi)}")
        if self.phases not in ("schroeder", "random"):
            raise ConfigError(f"phases must be 'schroeder' or 'random', got {self.phases!r}")
        if not 0.0 <= self.extreme_fraction <= 1.0:
            raise ConfigError(f"extreme_fraction must be in [0, 1], got {self.extreme_fraction}")


def _level(rng: np.random.Generator, lim: SignalLimits, extreme_fraction: float) -> float:
    if rng.random() < extreme_fraction:
        return lim.u_max if rng.random() < 0.5 else lim.u_min
    return float(rng.uniform(lim.u_min, lim.u_max))


def hold(n: int, level: float) -> np.ndarray:
    """``n`` samples of a constant ``level``; shape ``(n,)``."""
    return np.full(n, float(level))


def ramp(n: int, start: float, end: float) -> np.ndarray:
    """``n`` samples on a straight line from ``start`` to ``end`` (inclusive); shape ``(n,)``."""
    return np.linspace(float(start), float(end), n)


def aprbs(n: int, *, Ts: float, lim: SignalLimits, hold_time: tuple[float, float],
          rng: np.random.Generator, extreme_fraction: float = 0.0) -> np.ndarray:
    """Amplitude-modulated PRBS: levels uniform over the range (plus extremes), holds in ``hold_time`` s."""
    out = np.empty(n)
    k = 0
    while k < n:
        length = max(1, int(round(rng.uniform(*hold_time) / Ts)))
        out[k:k + length] = _level(rng, lim, extreme_fraction)
        k += length
    return out


def multisine(n: int, *, Ts: float, lim: SignalLimits, band: tuple[float, float],
              rng: np.random.Generator, phases: str = "schroeder") -> np.ndarray:
    """Sum of harmonics of a random base frequency inside ``band`` around a random offset.

    Amplitudes satisfy ``sum A_k <= A_max`` (stays in range) and
    ``sum A_k 2 pi f_k <= rate_max`` (slope within the slew limit).
    """
    f_base = rng.uniform(band[0], min(band[1], band[0] * 2 ** 0.5))
    freqs = f_base * np.arange(1, max(1, int(band[1] // f_base)) + 1)
    weights = rng.uniform(0.2, 1.0, len(freqs))
    k = np.arange(1, len(freqs) + 1)
    phi = -np.pi * k * (k - 1) / len(freqs) if phases == "schroeder" else rng.uniform(0, 2 * np.pi, len(freqs))
    span = lim.u_max - lim.u_min
    amp_total = rng.uniform(0.1, 0.5) * span
    scale = min(amp_total / weights.sum(), lim.rate_max / (weights * 2 * np.pi * freqs).sum())
    amps = scale * weights
    offset = rng.uniform(lim.u_min + amps.sum(), lim.u_max - amps.sum())
    t = np.arange(n) * Ts
    return offset + (amps[:, None] * np.sin(2 * np.pi * freqs[:, None] * t + phi[:, None])).sum(0)


def chirp(n: int, *, Ts: float, lim: SignalLimits, band: tuple[float, float],
          rng: np.random.Generator) -> np.ndarray:
    """A logarithmic sweep through ``band`` (up or down) with ``A(t) <= rate_max / (2 pi f(t))``."""
    f0, f1 = (band[0], band[1]) if rng.random() < 0.5 else (band[1], band[0])
    duration = max(n - 1, 1) * Ts
    t = np.arange(n) * Ts
    f = f0 * (f1 / f0) ** (t / duration)
    phase = 2 * np.pi * f0 * duration / np.log(f1 / f0) * ((f1 / f0) ** (t / duration) - 1) if f1 != f0 \
        else 2 * np.pi * f0 * t
    span = lim.u_max - lim.u_min
    a_max = rng.uniform(0.1, 0.5) * span
    # 0.9: the amplitude envelope changes in time too, which adds to the slope.
    amp = np.minimum(a_max, 0.9 * lim.rate_max / (2 * np.pi * f))
    offset = rng.uniform(lim.u_min + a_max, lim.u_max - a_max)
    return offset + amp * np.sin(phase + rng.uniform(0, 2 * np.pi))


def slew_limit(r: np.ndarray, *, Ts: float, rate_max, u_min, u_max, u0=None) -> np.ndarray:
    """Clip ``r`` (..., N) to ``[u_min, u_max]`` and limit its slew rate; ``u0`` (...) is the start value.

    ``rate_max``, ``u_min``, ``u_max`` broadcast against ``r[..., 0]`` (one value
    per channel, or one for all). Without ``u0`` the first sample is the clipped
    ``r[..., 0]``. The loop runs over time only, vectorised over leading axes.
    """
    lo, hi = np.asarray(u_min, dtype=float), np.asarray(u_max, dtype=float)
    r = np.clip(np.asarray(r, dtype=float), lo[..., None], hi[..., None])
    step = np.broadcast_to(np.asarray(rate_max, dtype=float) * Ts, r.shape[:-1])
    out = np.empty_like(r)
    prev = r[..., 0].copy() if u0 is None else np.clip(np.asarray(u0, float), lo, hi) + np.zeros(r.shape[:-1])
    for k in range(r.shape[-1]):
        prev = np.minimum(np.maximum(r[..., k], prev - step), prev + step)
        out[..., k] = prev
    return out


def _section(kind: str, n: int, Ts: float, lim: SignalLimits, cfg: ExcitationConfig,
             rng: np.random.Generator, last: float) -> np.ndarray:
    if kind == "hold":
        return hold(n, _level(rng, lim, cfg.extreme_fraction))
    if kind == "ramp":
        return ramp(n, last, _level(rng, lim, cfg.extreme_fraction))
    if kind == "aprbs":
        return aprbs(n, Ts=Ts, lim=lim, hold_time=cfg.aprbs_hold, rng=rng, extreme_fraction=cfg.extreme_fraction)
    if kind == "multisine":
        return multisine(n, Ts=Ts, lim=lim, band=cfg.multisine_band, rng=rng, phases=cfg.phases)
    return chirp(n, Ts=Ts, lim=lim, band=cfg.chirp_band, rng=rng)


def excitation_channel(n_steps: int, *, Ts: float, lim: SignalLimits, config: ExcitationConfig,
                       rng: np.random.Generator) -> tuple[np.ndarray, list[str]]:
    """Reference of one channel before slew limiting, shape ``(n_steps,)``, and the section kinds used."""
    probs = np.asarray(config.weights, float) / sum(config.weights)
    ref, kinds, k, last = np.empty(n_steps), [], 0, _level(rng, lim, config.extreme_fraction)
    while k < n_steps:
        kind = config.kinds[rng.choice(len(config.kinds), p=probs)]
        n = min(max(2, int(round(rng.uniform(*config.section_time) / Ts))), n_steps - k)
        ref[k:k + n] = _section(kind, n, Ts, lim, config, rng, last)
        last, k = ref[k + n - 1], k + n
        kinds.append(kind)
    return ref, kinds


def excitation_reference(n_steps: int, *, Ts: float, limits: Sequence[SignalLimits], config: ExcitationConfig,
                         seed: int | np.random.Generator = 0) -> np.ndarray:
    """The composed reference before slew limiting, clipped to each range; shape ``(n_steps, n_u)``.

    Use :func:`excitation` for a ready signal; this is for callers that splice
    references (e.g. behind a warm-up) and slew-limit a whole batch at once.
    """
    if n_steps < 2:
        raise ShapeError(f"expected at least 2 samples, got n_steps={n_steps}")
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    refs = [excitation_channel(n_steps, Ts=Ts, lim=lim, config=config, rng=rng)[0] for lim in limits]
    return np.clip(np.stack(refs, axis=1), [lim.u_min for lim in limits], [lim.u_max for lim in limits])


def excitation(n_steps: int, *, Ts: float, limits: Sequence[SignalLimits], config: ExcitationConfig,
               seed: int | np.random.Generator = 0) -> np.ndarray:
    """A composed, clipped and slew-limited excitation of ``len(limits)`` channels.

    Parameters
    ----------
    n_steps : int
        Number of samples.
    Ts : float
        Sample time in seconds.
    limits : sequence of SignalLimits
        One per channel (``n_u`` channels).
    config : ExcitationConfig
        Section kinds, durations and bands.
    seed : int or numpy.random.Generator
        The same seed gives the same signal.

    Returns
    -------
    ndarray, shape (n_steps, n_u), in the channels' units.
    """
    ref = excitation_reference(n_steps, Ts=Ts, limits=limits, config=config, seed=seed)
    return slew_limit(ref.T, Ts=Ts, rate_max=[lim.rate_max for lim in limits],
                      u_min=[lim.u_min for lim in limits], u_max=[lim.u_max for lim in limits]).T
