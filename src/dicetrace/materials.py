"""Materials in a physicist's terms: the coefficient of restitution and the friction of the ground law.

The ground law (docs/model.md §4) pushes each node k below the ground with
P_k = k·d_k·(1 − γ·u_z,k), clamped at 0 in ``physical``, d_k the depth and
u_z,k the node's vertical velocity, and rubs it with the regularised Coulomb
friction μ·P_k·u_xy,k/√(|u_xy,k|² + v_reg²).  Users think in a coefficient of
restitution e and a friction coefficient; this module gives the map between
the two, derived in docs/model.md "Materials: restitution and friction":

- :func:`restitution`: e of a point mass on the law as a function of γ and the
  impact speed v alone, in closed form (k and the mass drop out):
  e = (1 + W₀(−(1 + a)·e^{−(1+a)}))/a with a = γ·v, W₀ Lambert's W.
- :func:`gamma_for_restitution`: its inverse, γ(e, v_ref), and with gravity
  during the contact γ(e, v_ref, k, g) for a point mass or the die's flat drop.
- :func:`impact`: the impact ODE itself, solved with scipy's ``solve_ivp``
  (gravity, the clamp, any number of nodes in contact): e, contact time and
  greatest depth.
- :func:`friction_coefficient_at`, :func:`friction_relaxation_time`: the
  friction law's effective coefficient at a slip speed, and the time its
  viscous regime takes to stop a slow slide.

:data:`LITERATURE` holds, with their sources, the measured values found for
steel on a wooden table and for a hand's throw, and says what could not be
found.  Units are dicetrace's: cm, s, node mass (docs/model.md §2).

Bottom layer: numpy and scipy only, no other dicetrace module, so that the
configuration layer (:mod:`dicetrace.params`) may use it.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy import integrate, optimize, special

__all__ = [
    "LITERATURE", "Impact", "drop_speed", "friction_coefficient_at", "friction_relaxation_time",
    "gamma_for_restitution", "impact", "restitution",
]

# e(a) = Σ c_i a^i for small a = γ·v, from f(−e·a) = f(a), f(x) = x − log(1 + x), solved order by order
# with exact fractions: 1, −2/3, 4/9, −44/135, 104/405, −40/189, 7648/42525, −2848/18225, 31712/229635,
# −23429344/189448875, 89072576/795685275, −1441952704/14105329875.
_SERIES = (1.0, -2 / 3, 4 / 9, -44 / 135, 104 / 405, -40 / 189, 7648 / 42525, -2848 / 18225, 31712 / 229635,
           -23429344 / 189448875, 89072576 / 795685275, -1441952704 / 14105329875)
# Below this a the series is used: its remainder is < 1e-16 there, while W₀ near its branch point
# −1/e loses about eps/a² of relative precision.
_SERIES_BELOW = 0.05


def _positive(name: str, v, *, allow_zero: bool = False) -> np.ndarray:
    arr = np.asarray(v, dtype=float)
    ok = np.all(np.isfinite(arr)) and (np.all(arr >= 0) if allow_zero else np.all(arr > 0))
    if not ok:
        raise ValueError(f"{name} must be finite and {'>= 0' if allow_zero else '> 0'}, got {v!r}")
    return arr


def _out(x: np.ndarray):
    return float(x) if np.ndim(x) == 0 else x


def restitution(v_impact, gamma):
    """Coefficient of restitution of a point mass hitting the ground law at speed ``v_impact``, without gravity.

    With d the depth and m the mass, the contact obeys
    m·d̈ = −k·d·(1 + γ·ḋ) (u_z = −ḋ).  Write v = ḋ, so d̈ = v·dv/dd, and
    separate: v·dv/(1 + γv) = −(k/m)·d·dd.  Since v/(1 + γv) = (1 − 1/(1 + γv))/γ,
    the first integral is (v − ln(1 + γv)/γ)/γ + (k/m)·d²/2 = const.  Entry
    (d = 0, v = v₀ > 0) and exit (d = 0, v = −v₁) are at the same depth, so
    with a = γv₀ and b = γv₁

        a − ln(1 + a) = −b − ln(1 − b),

    that is t − ln t takes the same value at t = 1 + a and t = 1 − b: they are
    the two roots t of t·e^{−t} = (1 + a)·e^{−(1+a)}, one above 1 and one below:
    1 − b = −W₀(−(1 + a)·e^{−(1+a)}), and e = v₁/v₀ = b/a.  Neither k nor m appears:
    e depends on γ·v₀ alone, for any stiffness and any effective mass.  The
    factor 1 + γv stays positive all through (v − ln(1 + γv)/γ would grow
    without bound as v → −1/γ, so v never gets there), so the clamp of ``physical`` never acts on this
    impact and ``seed`` and ``physical`` give the same e.  Series for small a:
    e = 1 − 2a/3 + 4a²/9 − 44a³/135 + …; for large a, e → 1/a (the exit speed
    saturates at 1/γ).

    Parameters
    ----------
    v_impact : float or array_like
        Normal impact speed, cm/s (> 0).
    gamma : float or array_like
        Damping coefficient γ of the ground law, s/cm (>= 0; 0 gives e = 1).
    """
    v = _positive("impact speed", v_impact)
    g = _positive("gamma", gamma, allow_zero=True)
    a = np.asarray(v * g, dtype=float)
    small = a < _SERIES_BELOW
    e = np.empty(a.shape)
    if np.any(small):
        x = a[small]
        e[small] = np.polynomial.polynomial.polyval(x, _SERIES)
    if np.any(~small):
        s = 1.0 + a[~small]
        w = special.lambertw(-s * np.exp(-s), 0).real
        e[~small] = (1.0 + w) / a[~small]
    return _out(e)


@dataclasses.dataclass(frozen=True)
class Impact:
    """One normal impact on the ground law, solved as an ODE.

    Attributes
    ----------
    e : float
        Exit speed over impact speed (0 when the body never leaves the ground).
    v_out : float
        Exit speed, cm/s.
    contact_time : float
        Time from entry (d = 0) to exit (d = 0), s; nan when it never leaves.
    max_depth : float
        Greatest depth below the ground, cm.
    separated : bool
        Whether it left the ground within the time it was given.
    """

    e: float
    v_out: float
    contact_time: float
    max_depth: float
    separated: bool


def impact(v_impact: float, k: float, gamma: float, *, g: float = 0.0, n_contact: int = 1, mass: float = 1.0,
           clamp: bool = True, rtol: float = 1e-12) -> Impact:
    """Solve the normal impact of a body of ``mass`` node masses on ``n_contact`` nodes of the ground law.

    mass·d̈ = mass·|g| − n_contact·k·d·(1 + γ·ḋ), the force clamped at 0 when
    ``clamp`` (``physical``), from d = 0, ḋ = ``v_impact`` until d returns to 0
    (scipy's ``solve_ivp``, DOP853, an event at d = 0 going up).  A point mass is
    n_contact = 1, mass = 1; the die dropped flat on a face (no rotation, four
    nodes touching at once, eight node masses) is n_contact = 4, mass = 8, the
    law of a point mass with stiffness k/2.  ``g`` is the preset's gravity
    (cm/s², <= 0; 0 for none).  A body that turns back down before reaching the
    ground again never leaves it (e = 0): at that highest point d̈ >= 0 puts it
    at a depth d <= |g|·m/(n·k), where its energy ½ḋ² + ½(n·k/m)·d² − |g|·d is
    negative, and the energy only falls while the ground damps it, whereas
    leaving needs the energy ½ḋ² >= 0 of d = 0.
    """
    v0 = float(_positive("impact speed", v_impact))
    kk = float(_positive("k", k))
    gam = float(_positive("gamma", gamma, allow_zero=True))
    m = float(_positive("mass", mass))
    if not (isinstance(n_contact, (int, np.integer)) and 1 <= n_contact <= 8):
        raise ValueError(f"n_contact must be an integer in 1..8, got {n_contact!r}")
    if not (math.isfinite(g) and g <= 0):
        raise ValueError(f"g must be a finite number <= 0 (the preset's gravity, cm/s²), got {g!r}")
    w2 = n_contact * kk / m
    grav = -g

    def rhs(t, y):
        d, dd = y
        f = w2 * max(d, 0.0) * (1.0 + gam * dd)  # no force above the ground (a step may overshoot the exit)
        if clamp and f < 0.0:
            f = 0.0
        return [dd, grav - f]

    def exit_(t, y):
        return y[0]

    def turn(t, y):  # deepest point: ḋ crosses 0 going negative
        return y[1]

    def rest(t, y):  # highest point short of the ground: ḋ crosses 0 going positive
        return y[1]

    exit_.terminal = True
    exit_.direction = -1
    turn.direction = -1
    rest.terminal = True
    rest.direction = 1
    omega = math.sqrt(w2)
    half_period = math.pi / omega
    sol = integrate.solve_ivp(rhs, (0.0, 200 * half_period), [0.0, v0], method="DOP853", events=(exit_, turn, rest),
                              rtol=rtol, atol=[1e-13 * v0 / omega, 1e-13 * v0], first_step=half_period * 1e-5)
    depth = float(max(np.max(sol.y[0]), np.max(sol.y_events[1][:, 0], initial=0.0)))
    if sol.t_events[0].size:
        v1 = float(-sol.y_events[0][0][1])
        return Impact(e=v1 / v0, v_out=v1, contact_time=float(sol.t_events[0][0]), max_depth=depth, separated=True)
    if sol.t_events[2].size:
        return Impact(e=0.0, v_out=0.0, contact_time=math.nan, max_depth=depth, separated=False)
    raise ArithmeticError(f"the impact at {v0!r} cm/s neither ended nor came to rest ({sol.message})")


def gamma_for_restitution(e: float, v_ref: float, k: float | None = None, *, g: float = 0.0, n_contact: int = 1,
                          mass: float = 1.0) -> float:
    """The damping γ (s/cm) that gives restitution ``e`` at impact speed ``v_ref`` (cm/s).

    Without gravity (``g = 0``, the default) the inverse of :func:`restitution`
    in closed form: a = γ·v_ref solves (1 − e·a)·e^{e·a} = (1 + a)·e^{−a}; e(a)
    falls monotonically from 1 (a = 0) to 0 (a → ∞), so every e in (0, 1] has
    one γ, and k, ``n_contact`` and ``mass`` do not matter.  With gravity
    (``g < 0``) the answer depends on the stiffness: γ is found by Brent's
    method on :func:`impact` (``k`` required), for the body it describes (a
    point mass, or the die's flat drop: ``n_contact=4, mass=8``).
    """
    ee = float(e)
    if not (math.isfinite(ee) and 0 < ee <= 1):
        raise ValueError(f"restitution e must be in (0, 1], got {e!r}")
    v = float(_positive("v_ref", v_ref))
    if ee == 1.0:  # no damping: the spring and gravity both conserve energy, entry and exit are at d = 0
        return 0.0
    if g == 0.0:
        # b = e·a; solve φ(a) = a − ln(1 + a) + e·a + ln(1 − e·a) = 0 for a in (0, 1/e)
        def phi(a):
            return a - math.log1p(a) + ee * a + math.log1p(-ee * a)

        hi = 1.0 / ee
        a = optimize.brentq(lambda x: restitution(x, 1.0) - ee, 1e-300, hi * (1 - 1e-15), xtol=1e-300, rtol=1e-15)
        if abs(phi(a)) > 1e-9 * max(1.0, a):  # the closed form and its defining equation must agree
            raise ArithmeticError(f"restitution inverse did not converge for e={ee!r}")
        return a / v
    if k is None:
        raise ValueError("with gravity (g < 0) the stiffness k is needed: the restitution then depends on it")
    kk = float(_positive("k", k))

    def miss(gam):
        return impact(v, kk, gam, g=g, n_contact=n_contact, mass=mass).e - ee

    hi = 1.0 / v
    while miss(hi) > 0:
        hi *= 2.0
        if hi > 1e12 / v:
            raise ValueError(f"no γ gives e={ee!r} at v_ref={v!r} with gravity {g!r}")
    return float(optimize.brentq(miss, 0.0, hi, xtol=1e-15, rtol=1e-13))


def drop_speed(height_cm, g: float = -980.0):
    """Impact speed √(2|g|h) of a body dropped from rest through ``height_cm`` (cm/s)."""
    h = _positive("height", height_cm, allow_zero=True)
    if not (math.isfinite(g) and g < 0):
        raise ValueError(f"g must be a finite number < 0, got {g!r}")
    return _out(np.sqrt(2.0 * -g * h))


def friction_coefficient_at(slip_speed, mu: float, v_reg: float):
    """The per-node law's friction over normal force at a slip speed: μ·u/√(u² + v_reg²).

    Coulomb's μ for u ≫ v_reg (98 % of it at u = 5·v_reg), viscous
    (μ·u/v_reg) for u ≪ v_reg.
    """
    u = _positive("slip speed", slip_speed, allow_zero=True)
    m = float(_positive("mu", mu, allow_zero=True))
    vr = float(_positive("v_reg", v_reg))
    return _out(m * u / np.sqrt(u * u + vr * vr))


def friction_relaxation_time(mu: float, v_reg: float, g: float = -980.0) -> float:
    """Time constant v_reg/(μ·|g|) with which the law's viscous regime stops a slow slide on a face, s.

    A die resting on a face carries its weight on four nodes, each with the
    same slip u ≪ v_reg: m·du/dt = −μ·m·|g|·u/v_reg, so u decays as e^{−t/τ}.
    Below v_reg the law has no static friction: a die never sticks, it creeps.
    """
    m = float(_positive("mu", mu))
    vr = float(_positive("v_reg", v_reg))
    if not (math.isfinite(g) and g < 0):
        raise ValueError(f"g must be a finite number < 0, got {g!r}")
    return vr / (m * -g)


#: Measured values found for the materials and the throw of issue 43, with sources; None where none was found.
LITERATURE = {
    "friction_steel_on_wood": (
        {"value": (0.2, 0.6), "kind": "static", "pair": "wood on metal, clean and dry",
         "source": 'mech.subwiki.org, "Table of friction coefficients" (citing The Engineer\'s Handbook and the '
                   "Engineering Toolbox)"},
        {"value": 0.49, "kind": "static", "pair": "cast iron on oak, clean and dry",
         "source": "Physics Fundamentals (eCampusOntario Pressbooks), Appendix A, Table A.1"},
        {"value": 0.5, "kind": "static", "pair": "metal on wood",
         "source": 'S. A. Hill, "Coefficients of Friction" (howwhy.nfshost.com, 2022)'},
        {"value": 0.3, "kind": "kinetic", "pair": "metal on wood",
         "source": 'S. A. Hill, "Coefficients of Friction" (howwhy.nfshost.com, 2022)'},
    ),
    "restitution_steel_on_wood": None,
    "hand_throw": None,
    "not_found": (
        "A measured coefficient of restitution of steel (or of a die) on a wooden table: the sources that "
        "could be read give none (a 2022 study of balls on wood, J. Soc. Mat. Sci. Japan 71(7):603, says "
        "only in its abstract that the restitution depends on the wood's density and that the collisions can "
        "be elastic or inelastic).",
        "Measured release height, speed and spin of a hand's throw of a die: M. Kapitaniak, J. Strzalko, "
        "J. Grabski and T. Kapitaniak, \"The three-dimensional dynamics of the die throw\", Chaos (2012), "
        "filmed throws with a high-speed camera, but only press summaries could be read (the face lowest at "
        "the start is the likeliest outcome; bounces on a hard table make the outcome harder to predict "
        "than landing on a soft surface); none of their numbers.",
    ),
}
