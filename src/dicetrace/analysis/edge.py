"""The edge saddle of the simulated die, and a pooled rate over every border fit.

A die balanced on an edge is the saddle whose stable manifold the cell
borders are made of.  Linearised about the balance, the rigid-body rotation
about the (held) edge obeys ``I_edge φ'' = m g r φ``: one unstable
eigenvalue ``λ = √(m g r / I_edge)``
(:func:`dicetrace.analysis.settle.edge_balance_rate`; 22.80 /s for the
model's inertia ``I = (1/6) m s²``, ``s = 2`` cm).

* :func:`edge_release_rate` measures the same eigenvalue *in the simulation*:
  the die is set on an edge (two nodes at the depth that carries its weight,
  no velocity) tilted by ``tilt0`` and released; the tilt grows like
  ``exp(λ t)`` once the stable directions have decayed, and its slope is
  fitted from ten times ``tilt0`` up to ``saturation`` rad (where
  ``sin φ = φ`` to 2e-5).  The simulated eigenvalue includes what the
  analytic one leaves out: the compliant ground and a pivot that can slip.
* :func:`edge_jacobian_rate` linearises the simulation itself: the Jacobian of
  the time-T map of the die's planar state about the balance, by central
  differences, and ``λ = ln |μ_max| / T`` from its largest eigenvalue.  It
  exists only where the force law is differentiable at rest: the ``seed``
  preset's friction ``μ P u / σ`` is of degree 0 in the velocities (a
  perturbation of any size meets a friction force of order ``μ P``), so its
  finite differences do not converge as the step shrinks; the function
  reports both steps' rates so that this shows.
* :func:`pooled_rate`: the divergence rates of every border fit pooled
  without selection: median, its standard error (order statistics), a systematic error
  from alternative fits of the same borders, and their sum in quadrature.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import replace

import numpy as np
from scipy import stats

from dicetrace.params import Config
from dicetrace.simulate import Record, simulate

from .release import Release, fit_release
from .simulator import _resolve_config

__all__ = ["EdgeRelease", "edge_release_rate", "EdgeJacobian", "edge_jacobian_rate", "PooledRate", "pooled_rate"]


@dataclasses.dataclass(frozen=True)
class EdgeRelease(Release):
    """The die released from its edge (:class:`~dicetrace.analysis.release.Release`), and the tilt series."""

    t_s: np.ndarray
    tilt: np.ndarray


def _rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def edge_release_rate(*, config: Config | None = None, preset: str = "seed", tilt0: float = 1e-4,
                      saturation: float = 0.01, t_max_s: float = 2.0, **overrides) -> EdgeRelease:
    """The unstable rate of the edge saddle, from the die released at tilt ``tilt0`` (rad) off its edge.

    The die stands on the edge of nodes 1 and 5 (body rotated by 45° +
    ``tilt0`` about x), its centre lowered so that those two nodes sink by
    ``8|g| / (2k)``, the depth at which the penalty ground carries the weight.
    ValueError when the run ends before the tilt reaches ``saturation``
    (e.g. a numerical failure).
    """
    cfg = _balanced_config(_resolve_config(config, preset, overrides), float(tilt0), 0.0, t_max_s)
    roll = simulate(np.zeros(6), config=cfg, orientation=_rot_x(math.pi / 4 + float(tilt0)),
                    record=Record(states=True))
    rot = roll.trace.rotation
    tilt = np.abs(np.arctan2(rot[:, 2, 1], rot[:, 1, 1]) - math.pi / 4)
    t = roll.trace.t_s
    fit = fit_release(roll, t, tilt, tilt0=tilt0, start=10.0, saturation=saturation)
    return EdgeRelease(fit.exponent, fit.stderr, fit.fit_range, roll.status.label, t, tilt)


def _balanced_config(cfg: Config, tilt: float, dz: float, t_max_s: float) -> Config:
    p = cfg.preset
    d_eq = 8.0 * abs(p.g) / (2.0 * p.k)
    theta = math.pi / 4 + tilt
    z0 = p.half_side_cm * (math.sin(theta) + math.cos(theta)) - d_eq + dz
    return replace(cfg, preset=replace(p, z0_cm=z0), numerics=replace(cfg.numerics, t_max_s=t_max_s))


@dataclasses.dataclass(frozen=True)
class EdgeJacobian:
    """``rate`` = ln|μ_max|/T (1/s) at the finite-difference step ``h``; ``rate_fine`` at ``h/100``; eigenvalues."""

    rate: float
    rate_fine: float
    eigenvalues: np.ndarray
    horizon_s: float


def _planar_map(cfg: Config, x: np.ndarray, horizon_s: float) -> np.ndarray:
    """The die's planar state (dz cm, v_y, v_z cm/s, tilt rad, ω_x rad/s) after ``horizon_s`` from ``x``."""
    p = cfg.preset
    c = _balanced_config(cfg, float(x[3]), float(x[0]), horizon_s)
    sign = 1.0 if p.l_convention == "physical" else -1.0  # the program's L is the negative of the physical one
    ic = np.array([0.0, x[1], x[2], sign * p.inertia * x[4], 0.0, 0.0])
    tr = simulate(ic, config=c, orientation=_rot_x(math.pi / 4 + float(x[3])), record=Record(states=True)).trace
    rot = tr.rotation[-1]
    z_ref = _balanced_config(cfg, 0.0, 0.0, horizon_s).preset.z0_cm
    return np.array([tr.cm_pos[-1, 2] - z_ref, tr.cm_vel[-1, 1], tr.cm_vel[-1, 2],
                     math.atan2(rot[2, 1], rot[1, 1]) - math.pi / 4, sign * tr.L[-1, 0] / p.inertia])


def edge_jacobian_rate(*, config: Config | None = None, preset: str = "physical", horizon_s: float = 0.1,
                       h: float = 1e-4, **overrides) -> EdgeJacobian:
    """The unstable eigenvalue of the simulated edge saddle, from the Jacobian of its time-``horizon_s`` map.

    The state is the die's motion in the plane normal to its edge (centre
    height, the two velocities in that plane, the tilt and its rate; the
    position along the ground is neutral and left out), perturbed by ``h``
    times the scales (1e-3 cm, 1 cm/s, 1 cm/s, 1e-3 rad, 0.1 rad/s) in
    central differences about the balance at rest.  The same at ``h/100``
    is ``rate_fine``: the two agree where the map is differentiable.
    """
    cfg = _resolve_config(config, preset, overrides)
    scales = np.array([1e-3, 1.0, 1.0, 1e-3, 1e-1])

    def rate(step: float) -> tuple[float, np.ndarray]:
        jac = np.zeros((5, 5))
        for j in range(5):
            e = np.zeros(5)
            e[j] = step * scales[j]
            jac[:, j] = (_planar_map(cfg, e, horizon_s) - _planar_map(cfg, -e, horizon_s)) / (2 * e[j])
        mu = np.linalg.eigvals(jac)
        return math.log(float(np.abs(mu).max())) / horizon_s, mu

    r, mu = rate(h)
    r_fine, _ = rate(h / 100)
    return EdgeJacobian(r, r_fine, mu, float(horizon_s))


@dataclasses.dataclass(frozen=True)
class PooledRate:
    """Median of all rates, its standard error, the systematic error, the total, n and the quartiles."""

    median: float
    stat: float
    syst: float
    total: float
    n: int
    q25: float
    q75: float


def pooled_rate(rates, *, alternatives=()) -> PooledRate:
    """Pool every fitted rate (no selection) into a median with a total error.

    ``stat``: the bootstrap standard error of the median.  ``syst``: the
    largest shift of the median when the same borders are fitted another
    way (``alternatives``: arrays of rates, e.g. fits on the near and the far
    half of the distances); 0 without alternatives.  ``total`` is the two in
    quadrature.  Non-finite rates are dropped.
    """
    r = np.asarray(rates, dtype=float)
    r = r[np.isfinite(r)]
    if r.size == 0:
        raise ValueError("no finite rates to pool")
    med = float(np.median(r))
    stat = math.nan
    if r.size >= 6:  # distribution-free 95 % interval of the median from order statistics (binomial, p = 1/2)
        s = np.sort(r)
        k = int(stats.binom.ppf(0.025, r.size, 0.5))
        lo, hi = s[max(k - 1, 0)], s[min(r.size - k, r.size - 1)]
        stat = float((hi - lo) / (2 * 1.959963984540054))
    syst = 0.0
    for alt in alternatives:
        a = np.asarray(alt, dtype=float)
        a = a[np.isfinite(a)]
        if a.size:
            syst = max(syst, abs(float(np.median(a)) - med))
    return PooledRate(med, stat, syst, math.hypot(stat, syst) if math.isfinite(stat) else math.nan, int(r.size),
                      float(np.quantile(r, 0.25)), float(np.quantile(r, 0.75)))
