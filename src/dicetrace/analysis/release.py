"""The growth rate of the tilt of a die released from a balance (an edge or a corner), fitted over its linear range.

:func:`dicetrace.analysis.edge.edge_release_rate` and
:func:`dicetrace.analysis.corner.corner_release_rate` set the die near an
unstable balance and let it go; the tilt grows like ``exp(λ t)`` once the
stable directions have decayed.  :func:`fit_release` fits that growth the
same way for both (from ``start·tilt0`` to ``saturation`` rad, with
:func:`~dicetrace.analysis.lyapunov.finite_time_lyapunov`), and
:class:`Release` holds what both report of it.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .lyapunov import FiniteTimeLyapunov, finite_time_lyapunov

__all__ = ["Release", "fit_release", "never_reached"]


@dataclasses.dataclass(frozen=True)
class Release:
    """The die released from a balance: the fitted rate (1/s) and its stderr, the fit range (s), the run's status."""

    rate: float
    stderr: float
    fit_range: tuple[float, float]
    status: str


def never_reached(roll, tilt0: float, saturation: float) -> ValueError:
    """The error of a release whose tilt never grew into the fit range, naming the run's status and steps."""
    return ValueError(f"the die released at tilt {tilt0:g} never reached {saturation:g} rad "
                      f"(status {roll.status.label} after {roll.steps} steps)")


def fit_release(roll, t: np.ndarray, tilt: np.ndarray, *, tilt0: float, start: float,
                saturation: float) -> FiniteTimeLyapunov:
    """The growth of ``tilt`` (rad) at times ``t`` (s) of the run ``roll``, fitted from the first sample above
    ``start·tilt0`` to ``saturation``; ValueError (:func:`never_reached`) when the tilt never exceeds ``saturation``."""
    if not (tilt > saturation).any():
        raise never_reached(roll, tilt0, saturation)
    t_min = t[np.argmax(tilt > start * tilt0)]
    return finite_time_lyapunov(t, tilt, saturation=saturation, t_min=t_min)
