"""Agreement statistics (Cohen's kappa on a textbook table) and the convergence certificate of a map."""

from __future__ import annotations

import numpy as np
import pytest

from dicetrace.analysis import agreement


def test_cohens_kappa_of_the_textbook_table():
    """Cohen's 2x2 example (Wikipedia, "Cohen's kappa", example 1): 20 yes/yes, 5 yes/no, 10 no/yes,
    15 no/no of 50: p_o = 0.7, p_e = 0.5, kappa = 0.4."""
    a = np.array(["yes"] * 25 + ["no"] * 25)
    b = np.array(["yes"] * 20 + ["no"] * 5 + ["yes"] * 10 + ["no"] * 15)
    r = agreement(a, b)
    assert r.fraction == pytest.approx(0.7) and r.chance == pytest.approx(0.5) and r.kappa == pytest.approx(0.4)
    assert r.ci[0] < 0.7 < r.ci[1] and r.n == 50


def test_identical_maps_agree_fully_and_shuffled_ones_by_chance():
    rng = np.random.default_rng(0)
    g = rng.integers(1, 7, 20_000)
    assert agreement(g, g).kappa == 1.0 and agreement(g, g).fraction == 1.0
    r = agreement(g, rng.permutation(g))
    assert abs(r.kappa) < 3 * r.kappa_stderr and r.fraction == pytest.approx(r.chance, abs=0.01)
    assert agreement(np.ones(5), np.ones(5)).kappa == 1.0
    with pytest.raises(ValueError, match="same number"):
        agreement([1, 2], [1])


def test_the_programs_step_is_not_converged_and_the_adaptive_one_is():
    """Red-sea window, 20²: the program's dt = 1 ms against dt = 0.1 ms agrees at chance (kappa ~ 0,
    measured 0.21 of points at 30²), below the chaos floor at a tenth of the grid spacing (0.58):
    not converged; contact-adaptive at tol 1e-6 against 1e-7 agrees on 0.999: converged."""
    from dicetrace.analysis.transient import certify_map

    coarse = certify_map("red-sea", 20)
    assert not coarse.converged and coarse.tightened.kappa < 0.2
    assert coarse.tight_config.numerics.dt_s == pytest.approx(1e-4)
    fine = certify_map("red-sea", 20, integrator="contact-adaptive", tol=1e-6)
    assert fine.converged and fine.tightened.fraction > 0.98 and fine.tight_config.numerics.tol == pytest.approx(1e-7)
    assert fine.floor.fraction < fine.tightened.fraction
