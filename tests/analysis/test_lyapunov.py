"""Lyapunov exponents and escape rates on systems whose answers are known.

Tolerances and sources:
* Hénon map (a = 1.4, b = 0.3): lambda_1 = 0.419 per iteration (Sprott,
  "Chaos and Time-Series Analysis", 2003, table A.1: 0.41922), to 2 %.
* Lorenz flow (sigma = 10, rho = 28, beta = 8/3): lambda_1 = 0.9056 per unit
  time (Sprott 2003, table A.1), to 2 %.
* Linear growth d(t) = d0 exp(lambda t): the fit is exact.
* Open tent map of slope 3 (x -> 3 min(x, 1 - x), escape beyond 1): a third
  of the interval escapes each iteration, P(T > n) = (2/3)**n exactly, so
  kappa = ln(3/2) per iteration; to 3 standard errors.
* Exponential lifetimes with a transient: kappa as drawn, to 3 standard errors.
"""

from __future__ import annotations

import math

import numba
import numpy as np
import pytest

from dicetrace.analysis import escape_rate, finite_time_lyapunov, lyapunov_benettin, survival_function


def henon(x):
    return np.array([1.0 - 1.4 * x[0] * x[0] + x[1], 0.3 * x[0]])


@numba.njit(cache=True)
def _lorenz_rk4(x, h, n):
    s, r, b = 10.0, 28.0, 8.0 / 3.0
    y = x.copy()
    for _ in range(n):
        k1 = np.array([s * (y[1] - y[0]), y[0] * (r - y[2]) - y[1], y[0] * y[1] - b * y[2]])
        z = y + 0.5 * h * k1
        k2 = np.array([s * (z[1] - z[0]), z[0] * (r - z[2]) - z[1], z[0] * z[1] - b * z[2]])
        z = y + 0.5 * h * k2
        k3 = np.array([s * (z[1] - z[0]), z[0] * (r - z[2]) - z[1], z[0] * z[1] - b * z[2]])
        z = y + h * k3
        k4 = np.array([s * (z[1] - z[0]), z[0] * (r - z[2]) - z[1], z[0] * z[1] - b * z[2]])
        y = y + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return y


@pytest.mark.slow  # about a second
def test_henon_maximal_exponent():
    est = lyapunov_benettin(henon, [0.1, 0.1], n_steps=100_000, d0=1e-9)
    assert est.exponent == pytest.approx(0.41922, rel=0.02)
    assert 0 < est.stderr < 0.01 and abs(est.running[-1] - est.exponent) < 1e-12


def test_lorenz_maximal_exponent():
    sub, h = 10, 0.002  # one step = 10 RK4 steps of 0.002: dt = 0.02
    est = lyapunov_benettin(lambda x: _lorenz_rk4(x, h, sub), [1.0, 1.0, 1.0], dt=sub * h,
                            n_steps=60_000, n_transient=500, d0=1e-8, renorm_every=5)
    assert est.exponent == pytest.approx(0.9056, rel=0.02)


def test_a_contracting_map_has_its_exponent():
    est = lyapunov_benettin(lambda x: 0.5 * x, [1.0, 2.0], n_steps=200, n_transient=0, d0=1e-6)
    assert est.exponent == pytest.approx(math.log(0.5), abs=1e-12)


def test_finite_time_exponent_of_a_pure_exponential_and_its_saturation():
    t = np.linspace(0.0, 2.0, 201)
    lam = 23.0
    d = 1e-12 * np.exp(lam * t)
    d_sat = np.minimum(d, 1e-3)  # saturates at 1e-3 (the size of the system)
    r = finite_time_lyapunov(t, d_sat, saturation=1e-5)
    assert r.exponent == pytest.approx(lam, rel=1e-9) and r.fit_range[1] <= math.log(1e-5 / 1e-12) / lam + 1e-9
    np.testing.assert_allclose(r.ftle[1:][t[1:] < 0.5], lam, rtol=1e-9)
    with pytest.raises(ValueError, match="initial distance"):
        finite_time_lyapunov(t, np.zeros_like(t))


def test_open_tent_map_escape_rate_is_ln_3_over_2():
    rng = np.random.default_rng(0)
    x = rng.random(400_000)
    life = np.zeros(len(x), dtype=int)
    alive = np.ones(len(x), dtype=bool)
    for n in range(1, 60):
        x = np.where(alive, 3.0 * np.minimum(x, 1.0 - x), x)
        gone = alive & (x > 1.0)
        life[gone] = n
        alive &= ~gone
    life[alive] = 60
    r = escape_rate(life, discrete=True, censored_at=60)
    assert abs(r.kappa - math.log(1.5)) < 3 * r.stderr and r.stderr < 0.01
    cont = escape_rate(life)  # the continuous estimator on whole iterations is biased low
    assert cont.kappa < math.log(1.5) - 0.05
    t, s = survival_function(life)
    assert s[0] == pytest.approx(1 - 1 / len(life)) and s[-1] == 0.0


def test_exponential_tail_after_a_transient_and_a_time_cap():
    rng = np.random.default_rng(1)
    kappa = 2.0
    life = rng.random(50_000) * 0.5 + rng.exponential(1 / kappa, 50_000)  # a 0.5 s transient, then escape
    capped = np.minimum(life, 3.0)
    r = escape_rate(capped, censored_at=3.0)
    assert abs(r.kappa - kappa) < 3 * r.stderr and r.censored > 0 and r.t1 <= 3.0
    with pytest.raises(ValueError, match="fit range"):
        escape_rate(capped, t0=2.0, t1=1.0)
