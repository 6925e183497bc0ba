"""Ball–hill wedge (writeup 4.2 / appendix 8.1)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dicetrace.analysis import (
    ball_hill_energy,
    ball_hill_outcome,
    ball_hill_outcome_energy,
    ball_hill_saddle_rate,
    ball_hill_separatrices,
    ball_hill_transit_time,
    ball_hill_vector_field,
    fit_settle_divergence,
)
from dicetrace.analysis.wedge import OVER, RETURN, UNDEFINED

G, R = 980.0, 1.0


def test_vector_field_and_energy_conservation():
    dth, dom = ball_hill_vector_field(math.pi / 2, 0.0)
    assert dth == 0.0 and abs(dom) < 1e-12  # the saddle is an equilibrium
    rng = np.random.default_rng(0)
    th, om = rng.uniform(0, math.pi, 50), rng.uniform(-60, 60, 50)
    u, v = ball_hill_vector_field(th, om, g=G, radius_cm=R)
    # dE/dt = Omega * Omega' + (g/R) cos(theta) * theta' = 0 (analytic)
    dE = om * v + (G / R) * np.cos(th) * u
    np.testing.assert_allclose(dE, 0.0, atol=1e-9)


def test_separatrices_lie_on_saddle_energy():
    seps = ball_hill_separatrices(g=G, radius_cm=R)
    assert set(seps) == {"stable_left", "unstable_left", "unstable_right", "stable_right"}
    for curve in seps.values():
        e = ball_hill_energy(curve[:, 0], curve[:, 1], g=G, radius_cm=R)
        np.testing.assert_allclose(e, G / R, rtol=1e-12)
        assert curve[-1, 0] == pytest.approx(math.pi / 2) and curve[-1, 1] == pytest.approx(0.0, abs=1e-6)
    assert (seps["stable_left"][:-1, 1] > 0).all() and (seps["unstable_left"][:-1, 1] < 0).all()


def test_outcome_flips_exactly_at_half_v2_equals_gH():
    rng = np.random.default_rng(1)
    H = rng.uniform(0.01, 2.0, 100)
    vc = np.sqrt(2 * G * H)
    assert (ball_hill_outcome_energy(vc * (1 + 1e-12), H) == OVER).all()
    assert (ball_hill_outcome_energy(vc * (1 - 1e-12), H) == RETURN).all()
    # an exactly representable equality: v = 4, g = 8, H = 1 (1/2 v^2 = g H = 8)
    assert ball_hill_outcome_energy(4.0, 1.0, g=8.0) == UNDEFINED
    # phase-space form: theta0 < pi/2 moving up with Omega = v / R, H = R (1 - sin theta0)
    th0 = rng.uniform(0.05, 1.5, 100)
    H0 = R * (1 - np.sin(th0))
    om_c = np.sqrt(2 * G * H0) / R
    assert (ball_hill_outcome(th0, om_c * (1 + 1e-9)) == OVER).all()
    assert (ball_hill_outcome(th0, om_c * (1 - 1e-9)) == RETURN).all()
    # mirror side moves with negative Omega; moving away always returns
    assert (ball_hill_outcome(math.pi - th0, -om_c * (1 + 1e-9)) == OVER).all()
    assert (ball_hill_outcome(th0, -om_c * 2) == RETURN).all()
    assert ball_hill_outcome(math.pi / 2, 0.0) == UNDEFINED


def test_integration_agrees_and_transit_time_diverges_at_saddle_rate():
    th0 = 0.3
    vc = math.sqrt(2 * G * R * (1 - math.sin(th0)))
    for sign, expected in ((+1, OVER), (-1, RETURN)):
        t, out = ball_hill_transit_time(th0, vc * (1 + sign * 1e-3) / R)
        assert out == expected == ball_hill_outcome(th0, vc * (1 + sign * 1e-3) / R)
    # T = T0 - ln(d) / lambda with lambda = sqrt(g/R) (linearised saddle);
    # corrections are O(d), so over d = 1e-9..1e-4 the fit is within 0.5%.
    d = np.geomspace(1e-9, 1e-4, 6)
    T = [ball_hill_transit_time(th0, vc * (1 + x) / R)[0] for x in d]
    fit = fit_settle_divergence(d, T)
    assert fit.lambda_per_s == pytest.approx(ball_hill_saddle_rate(g=G, radius_cm=R), rel=5e-3)
