"""Excitation signals: limits by construction, reproducibility, the section kinds."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from nnfmu.errors import ConfigError, ShapeError
from nnfmu.signals import (SECTION_KINDS, ExcitationConfig, SignalLimits, aprbs, chirp, excitation,
                           excitation_reference, multisine, slew_limit)

TS = 1e-3
LIMITS = (SignalLimits(u_min=0.0, u_max=250.0, rate_max=5e3), SignalLimits(u_min=-2.0, u_max=3.0, rate_max=40.0))
CONFIG = ExcitationConfig(section_time=(0.05, 0.4), aprbs_hold=(0.02, 0.1), multisine_band=(1.0, 30.0),
                          chirp_band=(0.5, 40.0))


def _within_limits(u: np.ndarray, limits) -> bool:
    for j, lim in enumerate(limits):
        if u[:, j].min() < lim.u_min or u[:, j].max() > lim.u_max:
            return False
        if np.abs(np.diff(u[:, j])).max() > lim.rate_max * TS * (1 + 1e-12):
            return False
    return True


@pytest.mark.parametrize("seed", range(6))
def test_composed_signal_respects_amplitude_and_slew_limits(seed):
    u = excitation(3000, Ts=TS, limits=LIMITS, config=CONFIG, seed=seed)
    assert u.shape == (3000, 2)
    assert _within_limits(u, LIMITS)
    # ... and it is not trivially small: it explores most of each range.
    for j, lim in enumerate(LIMITS):
        assert np.ptp(u[:, j]) > 0.5 * (lim.u_max - lim.u_min)


@pytest.mark.parametrize("kind", SECTION_KINDS)
def test_each_section_kind_alone_respects_the_limits(kind):
    config = dataclasses.replace(CONFIG, kinds=(kind,), weights=(1.0,))
    for seed in range(4):
        u = excitation(2000, Ts=TS, limits=LIMITS, config=config, seed=seed)
        assert _within_limits(u, LIMITS)
        assert np.ptp(u[:, 0]) > 0


def test_same_seed_same_signal_other_seed_other_signal():
    a = excitation(800, Ts=TS, limits=LIMITS, config=CONFIG, seed=11)
    b = excitation(800, Ts=TS, limits=LIMITS, config=CONFIG, seed=11)
    c = excitation(800, Ts=TS, limits=LIMITS, config=CONFIG, seed=12)
    assert np.array_equal(a, b)
    assert not np.allclose(a, c)
    rng_a, rng_b = np.random.default_rng(5), np.random.default_rng(5)
    assert np.array_equal(excitation(300, Ts=TS, limits=LIMITS, config=CONFIG, seed=rng_a),
                          excitation(300, Ts=TS, limits=LIMITS, config=CONFIG, seed=rng_b))


@pytest.mark.parametrize("seed", range(5))
def test_multisine_and_chirp_slopes_fit_the_slew_limit_by_construction(seed):
    # Amplitudes are chosen so that the limiter has nothing to do inside these sections.
    lim, rng = LIMITS[0], np.random.default_rng(seed)
    for r in (multisine(3000, Ts=TS, lim=lim, band=(1.0, 30.0), rng=rng),
              chirp(3000, Ts=TS, lim=lim, band=(0.5, 40.0), rng=rng)):
        assert np.abs(np.diff(r)).max() <= lim.rate_max * TS
        assert lim.u_min <= r.min() and r.max() <= lim.u_max
        limited = slew_limit(r, Ts=TS, rate_max=lim.rate_max, u_min=lim.u_min, u_max=lim.u_max)
        assert np.allclose(limited, r, rtol=0, atol=1e-9)


def test_aprbs_levels_fill_the_range_and_holds_cover_the_minimum_time():
    lim = SignalLimits(u_min=-1.0, u_max=1.0, rate_max=1e9)
    r = aprbs(20000, Ts=TS, lim=lim, hold_time=(0.02, 0.1), rng=np.random.default_rng(0))
    change = np.flatnonzero(np.diff(r)) + 1
    holds = np.diff(change)
    assert holds.min() >= 20 and holds.max() <= 100  # 20 ms .. 100 ms at Ts = 1 ms
    levels = r[change]
    assert levels.min() < -0.9 and levels.max() > 0.9
    assert np.histogram(levels, bins=4, range=(-1, 1))[0].min() > 0.15 * len(levels)


def test_slew_limiter_follows_the_textbook_rule():
    r = np.array([0.0, 10.0, 10.0, 10.0, -10.0, 5.0])
    u = slew_limit(r, Ts=1.0, rate_max=4.0, u_min=-6.0, u_max=8.0, u0=0.0)
    assert np.allclose(u, [0.0, 4.0, 8.0, 8.0, 4.0, 5.0])


def test_reference_is_clipped_but_not_slew_limited():
    r = excitation_reference(2000, Ts=TS, limits=LIMITS, config=CONFIG, seed=3)
    assert r.shape == (2000, 2)
    assert r[:, 0].min() >= 0 and r[:, 0].max() <= 250
    assert np.abs(np.diff(r[:, 0])).max() > LIMITS[0].rate_max * TS  # APRBS/hold steps are still in it


@pytest.mark.parametrize("kwargs, message", [
    ({"kinds": ("hold", "sawtooth"), "weights": (1, 1)}, "unknown section kind.*valid kinds are hold"),
    ({"weights": (1, 1)}, "expected 5 non-negative weights"),
    ({"section_time": (0.5, 0.1)}, "section_time must be"),
    ({"phases": "zero"}, "phases must be 'schroeder' or 'random'"),
])
def test_bad_configuration_names_the_problem(kwargs, message):
    with pytest.raises(ConfigError, match=message):
        dataclasses.replace(CONFIG, **kwargs)


def test_bad_limits_and_lengths_are_rejected():
    with pytest.raises(ConfigError, match="u_min < u_max"):
        SignalLimits(u_min=1.0, u_max=1.0, rate_max=1.0)
    with pytest.raises(ConfigError, match="positive finite rate_max"):
        SignalLimits(u_min=0.0, u_max=1.0, rate_max=0.0)
    with pytest.raises(ShapeError, match="at least 2 samples"):
        excitation(1, Ts=TS, limits=LIMITS, config=CONFIG)
