"""``dicetrace.analysis.release``: the fit of the tilt of a die released from a balance, shared by the edge and corner."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from dicetrace.analysis.release import fit_release

ROLL = SimpleNamespace(status=SimpleNamespace(label="time_cap"), steps=42)


def test_fit_starts_at_start_times_tilt0_and_stops_at_saturation():
    t = np.linspace(0.0, 1.0, 1001)
    tilt = 1e-6 * np.exp(20.0 * t) + 1e-6 * np.exp(-50.0 * t)  # a decaying stable part, then the growth
    fit = fit_release(ROLL, t, tilt, tilt0=1e-6, start=100.0, saturation=1e-2)
    assert fit.exponent == pytest.approx(20.0, rel=1e-6)
    lo, hi = fit.fit_range
    assert tilt[t == lo][0] > 1e-4 >= tilt[t < lo][-1]  # the first sample above start·tilt0
    assert tilt[t == hi][0] <= 1e-2 < tilt[t > hi][0]  # the last one up to saturation


def test_a_tilt_that_never_saturates_names_the_run():
    t = np.linspace(0.0, 1.0, 11)
    with pytest.raises(ValueError, match=r"tilt 1e-06 never reached 0.01 rad \(status time_cap after 42 steps\)"):
        fit_release(ROLL, t, np.full(11, 1e-6), tilt0=1e-6, start=10.0, saturation=1e-2)
