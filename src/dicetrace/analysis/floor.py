"""The chaos floor: how much of an outcome map survives a relative perturbation δ of every initial condition.

``chaos_floor`` moves each IC by ``δ·|IC|·ξ`` (ξ a random unit vector of IC
space) and compares the outcomes with the unperturbed ones
(:func:`dicetrace.analysis.agreement.agreement`: fraction, Wilson interval,
Cohen's κ).  No integrator can be expected to agree with a converged
reference better than the floor at the size of its own error; read the other
way, a scheme whose agreement with the reference is at the floor of some δ
makes errors *equivalent* to an IC error of that size
(:func:`equivalent_perturbation`): its disagreements are then what chaos
does to any error that large, not a sign of a wrong model.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence

import numpy as np

from .agreement import Agreement, agreement

__all__ = ["FloorPoint", "perturb_ics", "chaos_floor", "equivalent_perturbation"]


@dataclasses.dataclass(frozen=True)
class FloorPoint:
    """The agreement of a map with itself under a relative IC perturbation ``delta``."""

    delta: float
    agreement: Agreement


def perturb_ics(ics, delta: float, rng: np.random.Generator) -> np.ndarray:
    """``IC + delta·|IC|·ξ``, ξ a random unit vector per IC (rows of ``ics``)."""
    ics = np.atleast_2d(np.asarray(ics, dtype=float))
    xi = rng.normal(size=ics.shape)
    xi /= np.linalg.norm(xi, axis=1, keepdims=True)
    return ics + float(delta) * np.linalg.norm(ics, axis=1, keepdims=True) * xi


def chaos_floor(classify: Callable[[np.ndarray], np.ndarray], ics, deltas: Sequence[float], *,
                rng: np.random.Generator | int = 0, labels=None, confidence: float = 0.95) -> list[FloorPoint]:
    """The chaos floor at each relative perturbation in ``deltas``.

    ``classify(ics (n, k)) -> labels (n,)`` labels raw ICs (e.g. a
    :func:`~dicetrace.analysis.simulator.classify_on_slice` over the identity
    slice); it is called once for the base ICs (unless ``labels`` is given) and
    once per δ.  Every δ gets its own random directions.
    """
    gen = np.random.default_rng(rng)
    ics = np.atleast_2d(np.asarray(ics, dtype=float))
    base = np.asarray(classify(ics) if labels is None else labels).ravel()
    out = []
    for d in deltas:
        moved = np.asarray(classify(perturb_ics(ics, d, gen))).ravel()
        out.append(FloorPoint(float(d), agreement(base, moved, confidence=confidence)))
    return out


def equivalent_perturbation(deltas, fractions, value: float) -> float:
    """The δ at which a floor curve (``fractions`` against ``deltas``) falls to ``value``, log-linear in δ.

    ``nan`` when ``value`` is above the whole curve (the scheme is better than
    every floor measured), ``inf`` when below it (worse than the largest δ).
    The curve is made non-increasing first (running minimum from small δ).
    """
    d = np.asarray(deltas, dtype=float)
    f = np.asarray(fractions, dtype=float)
    order = np.argsort(d)
    d, f = d[order], np.minimum.accumulate(f[order])
    if value > f[0]:
        return float("nan")
    if value < f[-1]:
        return float("inf")
    k = int(np.nonzero(f <= value)[0][0])
    if k == 0 or f[k] == f[k - 1]:
        return float(d[k])
    w = (f[k - 1] - value) / (f[k - 1] - f[k])
    return float(np.exp(np.log(d[k - 1]) + w * (np.log(d[k]) - np.log(d[k - 1]))))
