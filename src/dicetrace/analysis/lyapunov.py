"""Lyapunov exponents: Benettin's renormalised pair for flows and maps, and finite-time exponents from a divergence.

Two measures of how fast nearby trajectories separate:

* :func:`lyapunov_benettin`, the maximal Lyapunov exponent of a system whose
  state can be restarted (a map, or a flow with a step function): a
  companion trajectory at distance ``d0`` is renormalised back to ``d0``
  every ``renorm_every`` steps and the logarithms of the growth factors are
  averaged (Benettin, Galgani, Giorgilli & Strelcyn 1980, Meccanica 15:9).
  Validated on the Hénon map (lambda_1 = 0.419) and the Lorenz flow
  (lambda_1 = 0.906) in the tests.
* :func:`finite_time_lyapunov`, for a transient that ends (a die that
  settles), from the distance ``d(t)`` between two trajectories started
  ``d(0)`` apart and never renormalised: ``ln(d(t)/d(0)) / t`` as a function
  of time, and the exponent fitted as the slope of ``ln d`` against ``t``
  over the range where ``d`` grows freely (after the first samples, before
  ``d`` saturates at the size of the attractor or the transient ends).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import numpy as np
from scipy import stats

__all__ = ["LyapunovEstimate", "FiniteTimeLyapunov", "lyapunov_benettin", "finite_time_lyapunov"]


@dataclasses.dataclass(frozen=True)
class LyapunovEstimate:
    """Maximal Lyapunov exponent (per unit of time, or per iteration for a map).

    ``stderr`` is the standard error of the mean of ``n_blocks`` block means
    of the local growth rates (the blocks are long compared with the
    correlation time of the rates).  ``running`` is the running estimate
    after each renormalisation.
    """

    exponent: float
    stderr: float
    n_blocks: int
    running: np.ndarray


def lyapunov_benettin(
    step: Callable[[np.ndarray], np.ndarray],
    x0,
    *,
    dt: float = 1.0,
    n_steps: int = 100_000,
    n_transient: int = 1000,
    d0: float = 1e-8,
    renorm_every: int = 1,
    n_blocks: int = 20,
    rng: np.random.Generator | int | None = 0,
) -> LyapunovEstimate:
    """Maximal Lyapunov exponent of ``x -> step(x)`` by Benettin's renormalised pair.

    Parameters
    ----------
    step : callable
        One step of the system, ``x_{n+1} = step(x_n)`` (a map, or an
        integrator step of a flow of length ``dt``).
    x0 : array_like
        Start; the first ``n_transient`` steps bring it onto the attractor.
    dt : float
        Time per step (1 for a map: the exponent is then per iteration).
    n_steps : int
        Steps after the transient.
    d0 : float
        Distance (Euclidean) of the companion, restored at each renormalisation.
    renorm_every : int
        Steps between renormalisations (1 for maps; a few for a flow).
    n_blocks : int
        Blocks of the error estimate.
    """
    x = np.asarray(x0, dtype=float).copy()
    if n_steps < n_blocks * renorm_every:
        raise ValueError(f"n_steps ({n_steps}) must hold n_blocks × renorm_every steps")
    for _ in range(int(n_transient)):
        x = step(x)
    u = np.random.default_rng(rng).standard_normal(x.shape)
    y = x + d0 * u / np.linalg.norm(u)
    n_ren = int(n_steps) // int(renorm_every)
    logs = np.empty(n_ren)
    for r in range(n_ren):
        for _ in range(int(renorm_every)):
            x = step(x)
            y = step(y)
        d = float(np.linalg.norm(y - x))
        if not (d > 0 and math.isfinite(d)):
            raise ValueError(f"the pair's distance became {d} at renormalisation {r}: d0 too small or the run diverged")
        logs[r] = math.log(d / d0)
        y = x + (y - x) * (d0 / d)
    rates = logs / (renorm_every * dt)
    blocks = rates[: (n_ren // n_blocks) * n_blocks].reshape(n_blocks, -1).mean(axis=1)
    running = np.cumsum(rates) / np.arange(1, n_ren + 1)
    return LyapunovEstimate(float(rates.mean()), float(blocks.std(ddof=1) / math.sqrt(n_blocks)), n_blocks, running)


@dataclasses.dataclass(frozen=True)
class FiniteTimeLyapunov:
    """Finite-time exponent of a pair of trajectories.

    Attributes
    ----------
    exponent, stderr : float
        Slope of ``ln d`` against ``t`` over the fitted range (1/time unit),
        and its regression standard error.
    t, ftle : numpy.ndarray
        Times and ``ln(d(t)/d(0)) / t`` (nan at t = 0).
    fit_range : (float, float)
        Times of the first and last samples of the fit.
    n_fit : int
    """

    exponent: float
    stderr: float
    t: np.ndarray
    ftle: np.ndarray
    fit_range: tuple[float, float]
    n_fit: int


def finite_time_lyapunov(t, d, *, saturation: float | None = None, t_min: float | None = None,
                         t_max: float | None = None) -> FiniteTimeLyapunov:
    """Finite-time Lyapunov exponent from the distance ``d(t)`` between two trajectories.

    Parameters
    ----------
    t, d : array_like
        Sample times (increasing) and distances, ``d[0] > 0`` the initial one.
    saturation : float, optional
        The fit stops at the first sample where ``d`` exceeds this (default:
        ``1e-2`` of the largest distance seen, far below saturation).
    t_min, t_max : float, optional
        Further limits of the fitted range (default: from the first sample
        after t = 0, to the end).
    """
    t = np.asarray(t, dtype=float)
    d = np.asarray(d, dtype=float)
    if t.shape != d.shape or t.ndim != 1 or len(t) < 3:
        raise ValueError("t and d must be 1-D arrays of the same length >= 3")
    if not d[0] > 0:
        raise ValueError(f"the initial distance must be > 0, got {d[0]}")
    if np.any(np.diff(t) <= 0):
        raise ValueError("t must increase")
    with np.errstate(divide="ignore", invalid="ignore"):
        ftle = np.where(t > t[0], np.log(d / d[0]) / (t - t[0]), np.nan)
    cap = 1e-2 * float(np.nanmax(d)) if saturation is None else float(saturation)
    over = np.flatnonzero(d > cap)
    end = over[0] if len(over) else len(d)
    sel = np.zeros(len(t), dtype=bool)
    sel[1:end] = True
    sel &= d > 0
    if t_min is not None:
        sel &= t >= t_min
    if t_max is not None:
        sel &= t <= t_max
    if sel.sum() < 3:
        raise ValueError("fewer than 3 samples in the fit range: lower d(0), raise saturation or widen t_min..t_max")
    fit = stats.linregress(t[sel], np.log(d[sel]))
    return FiniteTimeLyapunov(float(fit.slope), float(fit.stderr), t, ftle,
                              (float(t[sel][0]), float(t[sel][-1])), int(sel.sum()))
