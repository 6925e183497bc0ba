"""Study l (converged): which measures of a window change between two models, by how many standard errors.

Each judged measure has a getter that reads its value and standard error
from a model's row (``MEASURES_WITH_ERRORS``); :func:`changes` compares two
rows measure by measure and calls a difference beyond ``CHANGE_SIGMA``
standard errors a change (the face counts by their χ² test).
"""

from __future__ import annotations

import math

#: A difference between two models counts as a change beyond this many standard errors.
CHANGE_SIGMA = 3.0


def changes(rows: dict, a: str = "discrete", b: str = "converged", sigma: float = CHANGE_SIGMA) -> list[dict]:
    """The measures of one window that differ between models ``a`` and ``b`` by more than ``sigma`` standard errors.

    Each entry: measure, the two values, their difference in standard errors
    (``z``), and ``changed``. Only measures with an error bar are judged; the
    face counts by their χ² test (changed when p < 0.001).
    """
    ra, rb = rows[a], rows[b]
    out = []
    for key, label, get in MEASURES_WITH_ERRORS:
        va, ea = get(ra)
        vb, eb = get(rb)
        if va is None or vb is None or not (math.isfinite(va) and math.isfinite(vb)):
            continue
        if not (ea and eb and math.isfinite(ea) and math.isfinite(eb)):
            continue  # no error bar on one side: not judged
        z = abs(vb - va) / math.hypot(ea, eb)
        out.append({"key": key, "measure": label, a: va, b: vb, "z": z, "changed": bool(z > sigma)})
    p = rb.get("chi2_p_vs_discrete") if a == "discrete" else None
    if p is not None:
        out.append({"key": "faces", "measure": "face counts (χ² p)", a: None, b: p, "z": None,
                    "changed": bool(p < 1e-3)})
    return out


def _pair(key, *errs):
    """Getter of ``r[key]`` and the first of the error keys ``errs`` that is finite and > 0."""
    def get(r):
        v = r.get(key)
        es = [r.get(e) for e in errs]
        e = next((float(x) for x in es if x is not None and math.isfinite(x) and x > 0), None)
        return (None if v is None else float(v)), e
    return get


def _nested(section, key, err=None):
    def get(r):
        d = r.get(section) or {}
        v = d.get(key)
        return (None if v is None else float(v)), (None if err is None or d.get(err) is None else float(d[err]))
    return get


#: (key, label, getter -> (value, stderr)) of the measures judged by :func:`changes`.
MEASURES_WITH_ERRORS = (
    ("boundary_fraction", "boundary fraction", _pair("boundary_fraction", "boundary_fraction_block_stderr")),
    ("alpha_box", "α boxes", _pair("alpha", "alpha_block_stderr", "alpha_stderr")),
    ("alpha_pert", "α perturbation", _pair("alpha_pert", "alpha_pert_stderr")),
    ("dim_mask", "D boundary mask", _pair("dim_mask", "dim_mask_stderr")),
    ("Sb", "Sb", _pair("Sb", "Sb_stderr")),
    ("Sbb", "Sbb", _pair("Sbb", "Sbb_stderr")),
    ("settle_mean", "mean settle time (s)", _nested("settle", "mean", "mean_stderr")),
    ("kappa", "escape rate κ (1/s)", _nested("settle", "kappa", "kappa_stderr")),
    ("lambda", "settle-time divergence λ, all fits (1/s)", _nested("divergence", "mean", "mean_stderr")),
)

#: The same getters by key.
MEASURES = {k: get for k, _, get in MEASURES_WITH_ERRORS}
