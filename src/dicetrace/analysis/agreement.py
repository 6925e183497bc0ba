"""Agreement between two labellings of the same points: the fraction equal, its Wilson interval, and Cohen's kappa.

Used to compare an outcome map with a reference (a converged integrator, a
tighter tolerance, a perturbed copy of itself).  The raw fraction of equal
labels is misleading when a few labels dominate: two unrelated maps with the
same face frequencies agree by chance on ``sum_j p_j q_j`` of the points.
Cohen's kappa (Cohen 1960, Educ. Psychol. Meas. 20:37) corrects for that,
``kappa = (p_o - p_e) / (1 - p_e)``: 1 for identical maps, 0 for chance.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .grouping import wilson_interval

__all__ = ["Agreement", "agreement"]


@dataclasses.dataclass(frozen=True)
class Agreement:
    """Agreement of two labellings.

    Attributes
    ----------
    fraction : float
        Fraction of points with equal labels.
    ci : (float, float)
        Its Wilson interval at ``confidence``.
    chance : float
        The agreement expected from the two label frequencies alone.
    kappa, kappa_stderr : float
        Cohen's kappa and its large-sample standard error
        (``sqrt(p_o (1 - p_o) / n) / (1 - p_e)``).
    n : int
    confidence : float
    """

    fraction: float
    ci: tuple[float, float]
    chance: float
    kappa: float
    kappa_stderr: float
    n: int
    confidence: float


def agreement(a, b, *, confidence: float = 0.95) -> Agreement:
    """Agreement of the labels ``a`` and ``b`` (same shape, any hashable labels)."""
    a = np.asarray(a).ravel()
    b = np.asarray(b).ravel()
    if a.shape != b.shape:
        raise ValueError(f"the labellings must have the same number of points, got {a.size} and {b.size}")
    n = a.size
    if n == 0:
        raise ValueError("no points to compare")
    same = int((a == b).sum())
    po = same / n
    labels, inv = np.unique(np.concatenate([a, b]), return_inverse=True)
    ca = np.bincount(inv[:n], minlength=len(labels)) / n
    cb = np.bincount(inv[n:], minlength=len(labels)) / n
    pe = float((ca * cb).sum())
    lo, hi = wilson_interval(same, n, confidence=confidence)
    if pe < 1:
        kappa = (po - pe) / (1 - pe)
        se = math.sqrt(po * (1 - po) / n) / (1 - pe)
    else:  # one label everywhere in both: identical, and chance agreement is total
        kappa, se = 1.0, 0.0
    return Agreement(po, (float(lo), float(hi)), pe, float(kappa), float(se), n, float(confidence))
