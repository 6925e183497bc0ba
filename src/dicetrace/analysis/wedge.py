"""Ball–hill model of a "wedge" (writeup section 4.2 and appendix 8.1).

A ball (a ring on a rail) moves without friction on a circular hill of radius
``R`` about its centre; ``theta`` is its polar angle seen from the centre
(the top of the hill is ``theta = pi/2``) and ``Omega = dtheta/dt``. The
equations of motion are

    dtheta/dt = Omega,    dOmega/dt = -(g / R) cos(theta),

with the energy per unit mass and ``R**2``
``e = Omega**2 / 2 + (g / R) sin(theta)``. The top ``(pi/2, 0)`` is a saddle
(an unstable equilibrium): its four separatrices are the level set
``Omega**2 = 2 (g / R) (1 - sin theta)``. A ball starting below the top with
speed ``v = R |Omega|`` towards it goes over when ``v**2 / 2 > g H`` and comes
back when ``v**2 / 2 < g H`` (``H = R (1 - sin theta0)`` the height still to
climb); at equality it approaches the top forever and the outcome is
undefined. Linearised at the top, ``phi = theta - pi/2`` obeys
``phi'' = (g / R) phi``: the saddle's rate is ``sqrt(g / R)``, and the transit
time of a ball near the separatrix diverges like ``-ln(d) / sqrt(g / R)``.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import solve_ivp

__all__ = [
    "OVER",
    "RETURN",
    "UNDEFINED",
    "ball_hill_vector_field",
    "ball_hill_energy",
    "ball_hill_separatrices",
    "ball_hill_outcome",
    "ball_hill_outcome_energy",
    "ball_hill_saddle_rate",
    "ball_hill_transit_time",
]

#: The ball crosses the top and ends on the other side.
OVER = 1
#: The ball stays on (returns to) the side it started on.
RETURN = -1
#: The ball approaches the top forever (or sits on it).
UNDEFINED = 0

_TOP = math.pi / 2


def ball_hill_vector_field(theta, omega, *, g: float = 980.0, radius_cm: float = 1.0):
    """Phase-space velocity ``(dtheta/dt, dOmega/dt)``.

    Parameters
    ----------
    theta : array_like
        Polar angle, rad (top of the hill at pi/2).
    omega : array_like
        Angular velocity, rad/s.
    g : float, optional
        Gravity, cm/s^2.
    radius_cm : float, optional
        Hill radius ``R``, cm.

    Returns
    -------
    (dtheta_dt, domega_dt) : tuple of numpy.ndarray
        rad/s and rad/s^2, broadcast shape.
    """
    theta = np.asarray(theta, dtype=float)
    omega = np.asarray(omega, dtype=float)
    k = g / radius_cm
    dth = omega + 0.0 * theta
    dom = -k * np.cos(theta) + 0.0 * omega
    return dth, dom


def ball_hill_energy(theta, omega, *, g: float = 980.0, radius_cm: float = 1.0):
    """Energy per unit mass and ``R**2``: ``Omega**2/2 + (g/R) sin(theta)``, 1/s^2."""
    theta = np.asarray(theta, dtype=float)
    omega = np.asarray(omega, dtype=float)
    return 0.5 * omega**2 + (g / radius_cm) * np.sin(theta)


def ball_hill_saddle_rate(*, g: float = 980.0, radius_cm: float = 1.0) -> float:
    """Instability rate ``sqrt(g / R)`` of the top of the hill, 1/s."""
    return math.sqrt(g / radius_cm)


def ball_hill_separatrices(
    *,
    g: float = 980.0,
    radius_cm: float = 1.0,
    theta_range: tuple[float, float] = (0.0, math.pi),
    n: int = 201,
) -> dict[str, np.ndarray]:
    """The four separatrices through the saddle ``(pi/2, 0)``.

    Parameters
    ----------
    g, radius_cm : float, optional
        Gravity (cm/s^2) and hill radius (cm).
    theta_range : (float, float), optional
        Angles covered, rad; must contain pi/2.
    n : int, optional
        Points per branch.

    Returns
    -------
    dict
        ``"stable_left"`` (theta < pi/2, Omega > 0: arriving from the left),
        ``"unstable_left"`` (theta < pi/2, Omega < 0: leaving to the left),
        ``"unstable_right"``, ``"stable_right"``: arrays (n, 2) of
        ``(theta, Omega)``, each ending at the saddle, on the level set
        ``Omega**2 = 2 (g/R) (1 - sin theta)``.
    """
    lo, hi = theta_range
    if not lo <= _TOP <= hi:
        raise ValueError("theta_range must contain pi/2")
    k = g / radius_cm
    left = np.linspace(lo, _TOP, n)
    right = np.linspace(hi, _TOP, n)
    wl = np.sqrt(np.maximum(2 * k * (1 - np.sin(left)), 0.0))
    wr = np.sqrt(np.maximum(2 * k * (1 - np.sin(right)), 0.0))
    return {
        "stable_left": np.column_stack([left, wl]),
        "unstable_left": np.column_stack([left, -wl]),
        "unstable_right": np.column_stack([right, wr]),
        "stable_right": np.column_stack([right, -wr]),
    }


def ball_hill_outcome_energy(v_cm_s, height_cm, *, g: float = 980.0):
    """Outcome of a ball sent up the hill with speed ``v`` and height ``H`` to climb.

    Parameters
    ----------
    v_cm_s : array_like
        Speed towards the top, cm/s (>= 0).
    height_cm : array_like
        Height of the top above the ball, cm (>= 0).
    g : float, optional
        Gravity, cm/s^2.

    Returns
    -------
    numpy.ndarray of int
        ``OVER`` (1) when ``v**2/2 > g H``, ``RETURN`` (-1) when
        ``v**2/2 < g H``, ``UNDEFINED`` (0) at equality (compared exactly in
        floating point).
    """
    v = np.asarray(v_cm_s, dtype=float)
    H = np.asarray(height_cm, dtype=float)
    kin = 0.5 * v * v
    pot = g * H
    return np.where(kin > pot, OVER, np.where(kin < pot, RETURN, UNDEFINED))


def ball_hill_outcome(theta0, omega0, *, g: float = 980.0, radius_cm: float = 1.0):
    """Outcome of the ball–hill motion from a phase-space state.

    Parameters
    ----------
    theta0 : array_like
        Starting angle, rad (top at pi/2).
    omega0 : array_like
        Starting angular velocity, rad/s.
    g, radius_cm : float, optional

    Returns
    -------
    numpy.ndarray of int
        ``OVER`` (1): ends on the other side of the top than it started;
        ``RETURN`` (-1): ends on its starting side (never reaches the top, or
        moves away from it); ``UNDEFINED`` (0): on a stable separatrix (or
        at the top).

    Notes
    -----
    With ``v = R |Omega0|`` and ``H = R (1 - sin theta0)`` this is
    :func:`ball_hill_outcome_energy` for a ball moving towards the top.
    """
    th = np.asarray(theta0, dtype=float)
    om = np.asarray(omega0, dtype=float)
    th, om = np.broadcast_arrays(th, om)
    side = np.sign(th - _TOP)  # -1 left, +1 right, 0 on top
    towards = (np.sign(om) == -side) & (side != 0)
    v = radius_cm * np.abs(om)
    H = radius_cm * (1.0 - np.sin(th))
    by_energy = ball_hill_outcome_energy(v, H, g=g)
    out = np.where(towards, by_energy, RETURN)
    out = np.where(side == 0, UNDEFINED, out)
    return out.astype(np.int64) if out.ndim else int(out)


def ball_hill_transit_time(
    theta0: float,
    omega0: float,
    *,
    g: float = 980.0,
    radius_cm: float = 1.0,
    t_max: float = 10.0,
    rtol: float = 1e-11,
) -> tuple[float, int]:
    """Time for the ball to leave the hill's neighbourhood, by integration.

    The transit ends when the ball is back at its starting height: at
    ``pi - theta0`` on the far side (over) or at ``theta0`` (return).

    Parameters
    ----------
    theta0 : float
        Starting angle, rad, below the top (``theta0 != pi/2``).
    omega0 : float
        Starting angular velocity towards the top, rad/s.
    g, radius_cm : float, optional
    t_max : float, optional
        Integration limit, s.
    rtol : float, optional
        Relative tolerance of the DOP853 integrator (absolute tolerance
        ``rtol * 1e-3``).

    Returns
    -------
    (t_s, outcome) : (float, int)
        Transit time in s (``nan`` when ``t_max`` is reached) and
        ``OVER``/``RETURN`` (``UNDEFINED`` when ``t_max`` is reached).
    """
    k = g / radius_cm
    th0 = float(theta0)
    far = math.pi - th0
    side = math.copysign(1.0, th0 - _TOP)

    def rhs(t, y):
        return [y[1], -k * math.cos(y[0])]

    def over(t, y):
        return (y[0] - far) * side  # crosses zero on the far side

    def back(t, y):
        return (y[0] - th0) * side

    over.terminal = True
    over.direction = -1.0
    back.terminal = True
    back.direction = 1.0
    sol = solve_ivp(
        rhs, (0.0, t_max), [th0, float(omega0)], method="DOP853",
        rtol=rtol, atol=rtol * 1e-3, events=[over, back],
    )
    t_over = sol.t_events[0]
    t_back = sol.t_events[1][sol.t_events[1] > 1e-12]
    cands = []
    if len(t_over):
        cands.append((float(t_over[0]), OVER))
    if len(t_back):
        cands.append((float(t_back[0]), RETURN))
    if not cands:
        return math.nan, UNDEFINED
    return min(cands)
