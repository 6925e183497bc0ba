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
from scipy.stats import chi2_contingency

from .cells import block_fraction_stderr
from .grouping import basins_fractions_table, wilson_interval

__all__ = ["Agreement", "agreement", "face_stats", "settled_agreement", "compare_presets", "counts_chi2_p"]


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

    def as_dict(self) -> dict:
        """Its numbers for a results file (JSON): fraction, ci, chance, kappa, kappa_stderr, n."""
        return {"fraction": self.fraction, "ci": list(self.ci), "chance": self.chance, "kappa": self.kappa,
                "kappa_stderr": self.kappa_stderr, "n": self.n}


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


def face_stats(g: np.ndarray, ref: np.ndarray | None) -> dict:
    """Face fractions with block errors (as study a), and a χ² test of the face counts against ``ref``'s."""
    fr = {str(int(r.label)): {"fraction": float(r.fraction), "count": int(r.count),
                         "block_stderr": block_fraction_stderr(g, int(r.label))}
          for r in basins_fractions_table(g).itertuples() if r.label > 0}
    out = {"fractions": fr}
    if ref is not None:
        counts = np.array([[int((x == k).sum()) for k in range(1, 7)] for x in (g, ref)])
        counts = counts[:, counts.sum(axis=0) > 0]
        chi2, p, dof, _ = chi2_contingency(counts)
        out.update(chi2_vs_discrete=float(chi2), chi2_dof=int(dof), chi2_p_vs_discrete=float(p))
    return out


def settled_agreement(outcome, settled, ref_outcome, ref_settled) -> float:
    """Fraction of throws with the reference's outcome, both settled (a throw that did not settle disagrees)."""
    return float(np.mean(np.asarray(settled) & np.asarray(ref_settled)
                         & (np.asarray(outcome) == np.asarray(ref_outcome))))


def compare_presets(seed, phys) -> dict:
    """Outcomes, settle times and contact changes of the same throws run by two presets, ``seed`` and ``phys``
    (each with ``settled``, ``outcome``, ``t_settle_s``, ``n_changes``, ``t_first_contact_s`` per throw)."""
    both = seed.settled & phys.settled
    nan = float("nan")
    return {
        "same_outcome": float(np.mean(both & (seed.outcome == phys.outcome))),
        "outcome_counts_seed": {int(f): int(np.sum(seed.outcome == f)) for f in range(0, 7)},
        "outcome_counts_physical": {int(f): int(np.sum(phys.outcome == f)) for f in range(0, 7)},
        "mean_settle_time_seed_s": float(np.mean(seed.t_settle_s[both])) if both.any() else nan,
        "mean_settle_time_physical_s": float(np.mean(phys.t_settle_s[both])) if both.any() else nan,
        "median_settle_time_ratio": float(np.median(phys.t_settle_s[both] / seed.t_settle_s[both])) if both.any() else nan,
        "mean_contact_changes_seed": float(np.mean(seed.n_changes[both])) if both.any() else nan,
        "mean_contact_changes_physical": float(np.mean(phys.n_changes[both])) if both.any() else nan,
        "mean_first_contact_s": _mean(seed.t_first_contact_s[np.isfinite(seed.t_first_contact_s)]),
    }


def _mean(x) -> float:
    x = np.asarray(x, float)
    return float(np.mean(x)) if x.size else float("nan")


def counts_chi2_p(a, b) -> float:
    """p-value of the χ² test that the counts ``a`` and ``b`` (per category) come from one distribution; categories
    empty in both are left out."""
    table = np.vstack([a, b])
    table = table[:, table.sum(axis=0) > 0]
    return float(chi2_contingency(table)[1])
