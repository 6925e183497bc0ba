"""One cell or many (analysis.onecell) and the prefix entropy of contact sequences (analysis.prefixes)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from analysis_synthetic import lattice_grid

from dicetrace.analysis.onecell import join_fraction, resolution_verdict, shift_overlap, shift_overlap_test
from dicetrace.analysis.prefixes import coarse_grain, prefix_counts, prefix_entropy


def test_a_true_period_beats_the_null():
    # Known answer: a map periodic under the lattice (20, 3), (−4, 17) maps every cell onto a copy of itself at
    # the period (overlap 1), while random directions of the same length do not (p = 1/(n_null+1), the smallest
    # a permutation test can give).
    g = lattice_grid((200, 200), (20, 3), (-4, 17))
    t = shift_overlap_test(g, (20, 3), n_null=19, rng=1)
    assert t.overlap == pytest.approx(1.0)
    assert t.null_median < 0.9
    assert t.p_value == pytest.approx(1 / 20)


def test_a_random_shift_of_random_blobs_is_not_a_period():
    # Null case: smoothed noise has no period; the overlap at an arbitrary shift is a draw from the null, so the
    # p-value is not small (> 0.05 for this seed; uniform in general).
    from scipy import ndimage

    f = ndimage.gaussian_filter(np.random.default_rng(2).normal(size=(160, 160)), 4)
    g = np.digitize(f, np.quantile(f, [0.33, 0.66])) + 1
    t = shift_overlap_test(g, (23, 9), n_null=19, rng=3)
    assert t.p_value > 0.05
    assert math.isfinite(shift_overlap(g, (23, 9)))


def test_join_fraction_of_two_columns_joined_by_a_bridge():
    # Known answer: slice z=0 has two separate cells of label 1 (and the rest label 2); at z=1 a bridge joins
    # them: both 2-D cells of label 1 share one 3-D cell, the label-2 cell is alone → 2 of 3 cells joined.
    g = np.full((9, 9, 2), 2)
    g[1:3, 1:8, :] = 1
    g[6:8, 1:8, :] = 1
    g[3:6, 4, 1] = 1
    assert join_fraction(g, min_cell=5) == pytest.approx(2 / 3)


def test_resolution_verdict():
    assert resolution_verdict([0.1, 0.25, 0.42], [300, 1200, 5000]) == "undetermined"
    assert resolution_verdict([0.41, 0.41, 0.42], [300, 1200, 5000]) == "converged"
    # a slow drift: each step within 2σ of the last, but 0.37 → 0.49 over three is 2.4σ (the red-sea series)
    assert resolution_verdict([0.371, 0.416, 0.489], [132, 238, 403]) == "undetermined"
    assert resolution_verdict([0.4, 0.5], [100, 100]) == "undetermined"  # two points are no series


def test_coarse_grain_drops_micro_bounces():
    # sets: air (0), node 6 (32) for 5 steps, air for 1 step (a micro-bounce), node 6 again 20 steps, 6+8 ...
    sets = [0, 32, 0, 32, 160, 128]
    steps = [0, 100, 105, 106, 126, 140]
    assert coarse_grain(sets, steps, 200, min_steps=1) == (0, 32, 0, 32, 160, 128)
    assert coarse_grain(sets, steps, 200, min_steps=3) == (0, 32, 160, 128)  # the 1-step air gap goes, 32s merge


def test_coarse_grain_of_exact_event_times_keeps_sub_step_durations():
    """Exact contact events carry times in seconds: a set of 0.4 µs is shorter than 1 µs, one of 1.5 µs is not,
    although both begin and end inside one 1 ms output step."""
    sets = [0, 32, 0, 32, 160, 128]
    times = [0.0, 0.1000000, 0.1000004, 0.1000010, 0.1000025, 0.2]
    assert coarse_grain(sets, times, 0.3, min_steps=1e-6) == (0, 32, 160, 128)
    assert coarse_grain(sets, times, 0.3, min_steps=1e-7) == (0, 32, 0, 32, 160, 128)


@pytest.mark.slow  # seconds (a subprocess or a long fit): the quick loop skips it, CI runs it
def test_prefix_entropy_of_the_golden_mean_shift():
    # Known answer: binary sequences with no two consecutive 1s have φ^n words of length n asymptotically:
    # topological entropy ln φ = 0.4812 nats/symbol (Lind & Marcus 1995, ex. 4.1.4). 40 000 Markov samples with
    # full support (P(0→1) = 1/2); fit where N(n) ≤ 10 % of the sample; tolerance 5 % (finite-n prefactor).
    rng = np.random.default_rng(0)
    seqs = []
    for _ in range(40000):
        s, prev = [], 0
        for _ in range(30):
            prev = 0 if prev == 1 else int(rng.random() < 0.5)
            s.append(prev)
        seqs.append(s)
    e = prefix_entropy(seqs, max_len=30)
    assert e.h == pytest.approx(math.log((1 + 5**0.5) / 2), rel=0.05)
    assert e.h_half == pytest.approx(e.h, rel=0.1)


def test_prefix_counts_of_a_full_shift():
    # all 2^n binary words of length 10 present once: N(n) = 2^n exactly
    words = [[(i >> b) & 1 for b in range(10)] for i in range(1024)]
    assert prefix_counts(words, 10).tolist() == [2**n for n in range(1, 11)]


@pytest.mark.slow  # a second or more (a fit, a subprocess): the quick loop skips it, CI runs it
def test_prefix_entropy_ignores_the_fall_of_counts_when_sequences_end():
    # Known answer: a full binary shift (h = ln 2) whose sequences end at random lengths 6…30. N(n) falls once
    # sequences end; the fit keeps to lengths where at least half of them still run and N(n) ≤ 10 % of those,
    # so it still gives ln 2 (tolerance 5 %: finite-n prefactor, measured here).
    rng = np.random.default_rng(5)
    seqs = [rng.integers(0, 2, rng.integers(6, 31)).tolist() for _ in range(40000)]
    e = prefix_entropy(seqs, max_len=30)
    assert e.h == pytest.approx(math.log(2), rel=0.05)
    assert e.n_range[1] <= 12  # 2^n ≤ 4000 and most sequences still running


# -- the contact-sequence measures of study d -------------------------------------------------------------


def test_simpson_is_the_chance_that_two_throws_share_a_label():
    from dicetrace.analysis.prefixes import simpson

    assert simpson(np.array([10])) == 1.0
    assert simpson(np.array([1, 1])) == 0.0
    assert simpson(np.array([2, 2])) == pytest.approx(2 * 2 / 12)
    assert np.isnan(simpson(np.array([1])))


def test_prefix_codes_group_equal_prefixes():
    from dicetrace.analysis.prefixes import prefix_codes

    seqs = np.array(["1-12-2", "1-12-3", "1-2", "4"])
    c1, c2, c3 = prefix_codes(seqs, 3)
    assert c1[0] == c1[1] == c1[2] != c1[3]
    assert c2[0] == c2[1] != c2[2]
    assert len(set(c3.tolist())) == 4  # every whole sequence differs


def test_fast_components_match_label_cells_inside_the_mask():
    from dicetrace.analysis import label_cells
    from dicetrace.analysis.prefixes import fast_components

    rng = np.random.default_rng(0)
    codes = rng.integers(0, 3, (30, 30))
    mask = rng.random((30, 30)) < 0.8
    ids, n = fast_components(codes, mask)
    ref, _ = label_cells(np.where(mask, codes, -1), exclude=(-1,))
    assert n == len(np.unique(ref[mask])) and (ids[~mask] == 0).all()
    # the same partition: a bijection between the two labellings on the mask
    pairs = set(zip(ids[mask].tolist(), ref[mask].tolist()))
    assert len(pairs) == n
