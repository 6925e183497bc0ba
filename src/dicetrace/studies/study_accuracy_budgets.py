"""The accuracy study's results read for a choice: the best setting within a CPU budget, the cheapest at the target.

Functions of a finished study's rows (:class:`~dicetrace.studies.study_accuracy.StudyResult`
``rows``: one per preset × integrator × step or tolerance, with its CPU time per IC and
its agreement with the reference), as the summary's budget and target tables use them.
"""

from __future__ import annotations

import numpy as np

from dicetrace.params import INTEGRATORS
from dicetrace.studies.study_accuracy import BASELINE_INTEGRATOR, PRESETS, TARGET_AGREEMENT, StudyResult


def best_within_budget(rows: list[dict], preset: str, integrator: str | None, budget_ms: float) -> dict | None:
    """The most accurate run (highest agreement; of equals, the cheapest) that costs ≤ budget_ms per IC,
    of one integrator or (``integrator=None``) of all."""
    cand = [
        r
        for r in rows
        if r["preset"] == preset and integrator in (None, r["integrator"]) and r["cpu_ms_per_ic"] <= budget_ms
    ]
    if not cand:
        return None
    return max(cand, key=lambda r: (r["outcome_agreement"], -r["cpu_ms_per_ic"]))


def budget_table(res: StudyResult, factors=(1.0, 10.0)) -> list[dict]:
    """For each preset × integrator × budget (factor × the seed's cost): the best run within it."""
    out = []
    base = res.seed_cost_ms
    if not np.isfinite(base):
        return out
    presets = sorted({r["preset"] for r in res.rows}, key=list(PRESETS).index)
    integs = [i for i in INTEGRATORS if any(r["integrator"] == i for r in res.rows)]
    for preset in presets:
        ref = next(x for x in res.references if x["preset"] == preset)
        for f in factors:
            for integ in integs:
                b = best_within_budget(res.rows, preset, integ, f * base)
                out.append(
                    {
                        "preset": preset,
                        "budget": f"{f:g}x seed ({f * base:.3g} ms)",
                        "integrator": integ,
                        "dt_s": b["dt_s"] if b else float("nan"),
                        "tol": b.get("tol", float("nan")) if b else float("nan"),
                        "tol_growth": b.get("tol_growth", float("nan")) if b else float("nan"),
                        "cpu_ms_per_ic": b["cpu_ms_per_ic"] if b else float("nan"),
                        "outcome_agreement": b["outcome_agreement"] if b else float("nan"),
                        "settle_time_bias_s": b["settle_time_bias_s"] if b else float("nan"),
                        "own_floor_flips": b["own_floor_flips"] if b else None,
                        "chaos_floor_1e-12": ref["chaos_floor_1e-12"],
                        "chaos_floor_1e-09": ref["chaos_floor_1e-09"],
                    }
                )
    return out


def cheapest_at_target(rows: list[dict], preset: str, target: float | None = None) -> list[dict]:
    """Per integrator, its cheapest run reaching ``target`` agreement (default TARGET_AGREEMENT[preset]).

    Each entry: the integrator, its run (None when no run reaches the target)
    and ``ratio``, its CPU time over the cheapest such run of
    BASELINE_INTEGRATOR (NaN when either is missing).
    """
    target = TARGET_AGREEMENT[preset] if target is None else target
    integs = [i for i in INTEGRATORS if any(r["integrator"] == i and r["preset"] == preset for r in rows)]
    best = {}
    for integ in integs:
        ok = [r for r in rows if r["preset"] == preset and r["integrator"] == integ and r["outcome_agreement"] >= target]
        best[integ] = min(ok, key=lambda r: r["cpu_ms_per_ic"]) if ok else None
    base = best.get(BASELINE_INTEGRATOR)
    out = []
    for integ in integs:
        b = best[integ]
        ratio = b["cpu_ms_per_ic"] / base["cpu_ms_per_ic"] if b and base else float("nan")
        out.append({"integrator": integ, "run": b, "ratio": ratio, "target": target})
    return out


def zero_floor_settings(rows: list[dict], preset: str) -> list[dict]:
    """The runs of ``preset`` whose own floor is 0 (no outcome flips at FLOOR_REL)."""
    return [r for r in rows if r["preset"] == preset and r.get("own_floor_flips") == 0]
