"""The accuracy study's rows read for a choice: the best setting within a budget, the cheapest at the target."""

from __future__ import annotations

import numpy as np
import pytest

from dicetrace.params import INTEGRATORS
from dicetrace.studies import study_accuracy as acc
from dicetrace.studies import study_accuracy_budgets as budgets


def _row(integ, ms, agree, flips=0, preset="physical"):
    return {"preset": preset, "integrator": integ, "cpu_ms_per_ic": ms, "outcome_agreement": agree,
            "own_floor_flips": flips, "dt_s": 1e-3, "tol": float("nan")}


def test_cheapest_at_target_and_ratio_to_the_baseline():
    base = acc.BASELINE_INTEGRATOR
    other = next(i for i in INTEGRATORS if i != base)
    rows = [_row(base, 0.8, 0.95), _row(base, 0.6, 0.94), _row(base, 0.4, 0.90),
            _row(other, 0.3, 0.93), _row(other, 0.1, 0.92), _row(base, 0.01, 1.0, preset="seed")]
    got = {c["integrator"]: c for c in budgets.cheapest_at_target(rows, "physical")}
    assert set(got) == {base, other}
    assert got[base]["run"]["cpu_ms_per_ic"] == 0.6 and got[base]["ratio"] == pytest.approx(1.0)
    assert got[other]["run"]["cpu_ms_per_ic"] == 0.3 and got[other]["ratio"] == pytest.approx(0.5)
    assert got[other]["target"] == acc.TARGET_AGREEMENT["physical"]
    none = {c["integrator"]: c for c in budgets.cheapest_at_target(rows, "physical", target=0.99)}
    assert none[base]["run"] is None and np.isnan(none[other]["ratio"])


def test_zero_floor_settings():
    rows = [_row("rk4", 1.0, 0.5, flips=0), _row("rk4", 2.0, 0.5, flips=3), _row("rk4", 1.0, 0.5, flips=0, preset="seed")]
    assert budgets.zero_floor_settings(rows, "physical") == [rows[0]]


def test_best_within_budget_prefers_the_cheaper_of_equals():
    """Of runs that agree equally, the cheaper one is the best for a budget, across integrators too
    (the summary once named a 1.06 ms run over a 0.62 ms one, both at agreement 1.000)."""
    rows = [
        {"preset": "seed", "integrator": "contact-substep", "cpu_ms_per_ic": 1.06, "outcome_agreement": 1.0},
        {"preset": "seed", "integrator": "contact-adaptive", "cpu_ms_per_ic": 0.62, "outcome_agreement": 1.0},
        {"preset": "seed", "integrator": "contact-adaptive", "cpu_ms_per_ic": 0.34, "outcome_agreement": 0.997},
        {"preset": "physical", "integrator": "contact-adaptive", "cpu_ms_per_ic": 0.1, "outcome_agreement": 1.0},
    ]
    assert budgets.best_within_budget(rows, "seed", None, 2.0)["cpu_ms_per_ic"] == 0.62
    assert budgets.best_within_budget(rows, "seed", "contact-substep", 2.0)["cpu_ms_per_ic"] == 1.06
    assert budgets.best_within_budget(rows, "seed", None, 0.5)["cpu_ms_per_ic"] == 0.34
    assert budgets.best_within_budget(rows, "seed", None, 0.2) is None
