"""Agreement statistics (Cohen's kappa on a textbook table) and the convergence certificate of a map."""

from __future__ import annotations

import json

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


@pytest.mark.slow  # a second or more (a fit, a subprocess): the quick loop skips it, CI runs it
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


def test_face_stats_chi2_tells_different_face_counts_apart():
    from dicetrace.analysis.agreement import face_stats

    rng = np.random.default_rng(0)
    a = rng.integers(1, 7, (60, 60))
    same = rng.integers(1, 7, (60, 60))
    skew = np.where(rng.random((60, 60)) < 0.3, 3, a)
    assert face_stats(same, a)["chi2_p_vs_discrete"] > 1e-3
    assert face_stats(skew, a)["chi2_p_vs_discrete"] < 1e-10
    fr = face_stats(a, None)["fractions"]
    assert sum(f["fraction"] for f in fr.values()) == pytest.approx(1.0)
    assert all(f["block_stderr"] > 0 for f in fr.values())


def test_counts_chi2_p_leaves_out_empty_categories():
    from dicetrace.analysis.agreement import counts_chi2_p

    assert counts_chi2_p([50, 50, 0], [49, 51, 0]) > 0.5  # the empty third category would make the test undefined
    assert counts_chi2_p([100, 20, 50, 50, 50, 30], [50] * 6) < 1e-4


def test_settled_agreement_counts_unsettled_as_disagreement():
    from dicetrace.analysis.agreement import settled_agreement

    assert settled_agreement([1, 2, 3], [True] * 3, [1, 2, 3], [True] * 3) == 1.0
    assert settled_agreement([1, 2, -1], [True, True, False], [1, 2, -1], [True] * 3) == pytest.approx(2 / 3)
    assert settled_agreement([1, 2, 4], [True] * 3, [1, 2, 3], [True, False, True]) == pytest.approx(1 / 3)


def test_compare_presets_on_the_same_throws():
    from types import SimpleNamespace

    from dicetrace.analysis.agreement import compare_presets

    def runs(outcome, settled, t, changes, first):
        return SimpleNamespace(outcome=np.array(outcome), settled=np.array(settled), t_settle_s=np.array(t),
                               n_changes=np.array(changes), t_first_contact_s=np.array(first))
    a = runs([1, 2, 3, 0], [True, True, True, False], [1.0, 2.0, 3.0, 9.0], [4, 6, 8, 0], [0.1, 0.2, np.inf, 0.3])
    b = runs([1, 5, 3, 3], [True, True, True, True], [2.0, 2.0, 6.0, 1.0], [2, 2, 2, 2], [0.1, 0.1, 0.1, 0.1])
    c = compare_presets(a, b)
    assert c["same_outcome"] == pytest.approx(0.5)
    assert c["outcome_counts_seed"][0] == 1 and c["outcome_counts_physical"][3] == 2
    assert c["mean_settle_time_seed_s"] == pytest.approx(2.0) and c["mean_settle_time_physical_s"] == pytest.approx(10 / 3)
    assert c["median_settle_time_ratio"] == pytest.approx(2.0)
    assert c["mean_contact_changes_seed"] == pytest.approx(6.0)
    assert c["mean_first_contact_s"] == pytest.approx(0.2)  # finite first contacts only


def test_as_dict_gives_the_numbers_a_results_file_keeps():
    a = agreement([1, 2, 3, 1, 2, 3, 1, 1], [1, 2, 3, 1, 2, 1, 1, 2])
    d = a.as_dict()
    assert d == {"fraction": 0.75, "ci": list(a.ci), "chance": a.chance, "kappa": a.kappa,
                 "kappa_stderr": a.kappa_stderr, "n": 8}
    assert json.loads(json.dumps(d)) == d
