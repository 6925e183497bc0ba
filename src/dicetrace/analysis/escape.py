"""Escape rates of transient chaos: the survival function of lifetimes and its exponential tail.

In transient chaos the probability that a trajectory has not yet left (a
die has not yet settled) decays as ``P(T > t) ~ exp(-kappa t)`` once the
trajectories have reached the chaotic saddle (Kantz & Grassberger 1985,
Physica D 17:75; Tél & Lai 2008, Phys. Rep. 460:245).  :func:`escape_rate`
estimates ``kappa`` by maximum likelihood on the tail: lifetimes beyond
``t0`` are, for an exponential tail, exponential with mean ``1/kappa``
after ``t0``, so ``kappa = n / sum(T_i - t0)`` with standard error
``kappa / sqrt(n)``.  The default range starts where half the sample has
escaped (past the transient onto the saddle) and ends where fewer than
``min_tail`` lifetimes remain (beyond that the counting noise dominates).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

__all__ = ["EscapeRate", "survival_function", "escape_rate"]


def survival_function(lifetimes) -> tuple[np.ndarray, np.ndarray]:
    """Sorted lifetimes ``t`` and the empirical ``P(T > t)`` just after each (``(n - i - 1) / n``)."""
    t = np.sort(np.asarray(lifetimes, dtype=float).ravel())
    if len(t) == 0 or not np.all(np.isfinite(t)):
        raise ValueError("lifetimes must be a non-empty array of finite numbers (drop the throws that never ended)")
    n = len(t)
    return t, (n - 1 - np.arange(n)) / n


@dataclasses.dataclass(frozen=True)
class EscapeRate:
    """Escape rate ``kappa`` (1/time unit) with its standard error and the fitted range.

    ``t0``/``t1``: the tail's start and the last lifetime used; ``n_tail``:
    lifetimes in the fit; ``n``: the sample; ``censored``: lifetimes beyond
    ``t1`` (treated as surviving to ``t1``: right-censored).
    """

    kappa: float
    stderr: float
    t0: float
    t1: float
    n_tail: int
    n: int
    censored: int


def escape_rate(lifetimes, *, t0: float | None = None, t1: float | None = None, min_tail: int = 50,
                censored_at: float | None = None, discrete: bool = False) -> EscapeRate:
    """Escape rate from lifetimes (settle times, escape iterations) by maximum likelihood on the tail.

    Parameters
    ----------
    lifetimes : array_like
        One lifetime per trajectory (finite).
    t0 : float, optional
        Start of the exponential tail (default: the median lifetime).
    t1 : float, optional
        End of the range: lifetimes beyond it count as censored at ``t1``
        (default: the lifetime with ``min_tail`` beyond it).
    min_tail : int
        Lifetimes that must lie beyond ``t1`` by default, and in the tail.
    censored_at : float, optional
        A cap that ended the runs still alive (a time cap): lifetimes equal
        to it are censored there, never counted as escapes.
    discrete : bool
        Lifetimes are whole numbers of iterations (a map, or steps): the
        tail is geometric, ``P(T > t0 + k) = q**k``, and ``kappa = -ln q``
        per iteration with ``1 - q = n / sum(T_i - t0)`` (its maximum
        likelihood); the continuous estimator would be biased by ``kappa/2``
        and more.
    """
    t = np.sort(np.asarray(lifetimes, dtype=float).ravel())
    if len(t) == 0 or not np.all(np.isfinite(t)):
        raise ValueError("lifetimes must be a non-empty array of finite numbers")
    n = len(t)
    t0 = float(np.median(t)) if t0 is None else float(t0)
    if t1 is None:
        t1 = float(t[-min_tail]) if n > min_tail else float(t[-1])
    t1 = float(t1) if censored_at is None else min(float(t1), float(censored_at))
    if not t1 > t0:
        raise ValueError(f"the fit range is empty: t1 = {t1} <= t0 = {t0}")
    tail = t[t > t0]
    escaped = tail[tail <= t1]
    if censored_at is not None:
        escaped = escaped[escaped < float(censored_at)]
    censored = len(tail) - len(escaped)
    if len(escaped) < min(min_tail, 10):
        raise ValueError(f"only {len(escaped)} lifetimes escape between t0 = {t0:g} and t1 = {t1:g}: too few for a rate")
    exposure = float((escaped - t0).sum() + censored * (t1 - t0))
    m = len(escaped)
    if not discrete:
        kappa = m / exposure
        return EscapeRate(kappa, kappa / math.sqrt(m), t0, t1, m, n, censored)
    p = m / exposure  # the per-iteration escape probability
    if not p < 1:
        raise ValueError("every tail lifetime escapes at its first iteration: no geometric tail to fit")
    kappa = -math.log1p(-p)
    return EscapeRate(kappa, p / math.sqrt(m * (1 - p)), t0, t1, m, n, censored)
