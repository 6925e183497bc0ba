"""The triple-point law's measures (:mod:`dicetrace.analysis.triple_law`) on cases with known answers: the cube's face
triples, binomial limits, the spinning corner's roots, a synthetic spiral map read through the real circle bisection,
and a synthetic sample of known density and stretch; one slow check in the simulator (releases at a set spin)."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy import stats

from dicetrace.analysis.corner_slice import circle_sectors
from dicetrace.analysis.triple_law import (border_tracks, closure_table, cluster_boxes, fit_spiral, has_opposite_pair,
                                           binomial_limits, loglog_slope, pivot_friction, predicted_share,
                                           release_borders, share_curve, spinning_corner, spinning_roots,
                                           stretch_fit)
from dicetrace.params import make_config

LN10 = math.log(10.0)


def test_the_eight_corner_triples_are_the_only_ones_without_an_opposite_pair():
    """A die's opposite faces sum to 7; the faces around a corner take one of each pair (1|6, 2|5, 3|4): 8 of the
    20 triples, the other 12 hold an opposite pair."""
    triples = list(itertools.combinations(range(1, 7), 3))
    corners = {tuple(sorted(t)) for t in itertools.product((1, 6), (2, 5), (3, 4))}
    assert {t for t in triples if not has_opposite_pair(t)} == corners
    assert sum(has_opposite_pair(t) for t in triples) == 12
    assert not has_opposite_pair([1, 3, 5]) and not has_opposite_pair([1, 4, 5]) and not has_opposite_pair((1, 2, 4))
    assert has_opposite_pair([1, 3, 6]) and has_opposite_pair([3, 4, 6])


def test_clopper_pearson_limits_are_the_binomial_tails():
    lo, hi = binomial_limits(0, 10)
    assert lo == 0.0 and hi == pytest.approx(1 - 0.05 ** 0.1)  # 0 of 10: P(0 | hi) = 0.05
    assert stats.binom.pmf(0, 10, hi) == pytest.approx(0.05)
    lo, hi = binomial_limits(3, 20)
    assert stats.binom.cdf(3, 20, hi) == pytest.approx(0.025) and stats.binom.sf(2, 20, lo) == pytest.approx(0.025)
    assert math.isnan(binomial_limits(0, 0)[1])


def test_closure_table_counts_each_class():
    rows = [{"faces": [1, 3, 6], "status": "split"}, {"faces": [3, 4, 6], "status": "split"},
            {"faces": [1, 3, 5], "status": "vertex"}, {"faces": [1, 3, 5], "status": "split"},
            {"faces": [1, 4, 5], "status": "unresolved"}, {"faces": [2, 5, 6], "status": "max_depth"}]
    t = closure_table(rows)
    assert t["opposite"] == {**t["opposite"], "n": 3, "closed": 0, "split": 2, "unresolved": 1}
    assert t["opposite"]["hi95"] == pytest.approx(1 - 0.05 ** 0.5)
    assert t["adjacent"]["n"] == 3 and t["adjacent"]["closed"] == 1 and t["adjacent"]["split"] == 1
    assert t["adjacent"]["fraction"] == 0.5


def test_boxes_of_one_junction_chain_into_one_cluster():
    boxes = np.array([[10, 10], [11, 11], [12, 12], [30, 30], [11, 10]])
    faces = [(1, 3, 6)] * 3 + [(1, 3, 6), (1, 3, 5)]
    assert cluster_boxes(boxes, faces, reach=1) == [[0, 1, 2], [3], [4]]
    assert cluster_boxes(boxes, faces, reach=30) == [[0, 1, 2, 3], [4]]


# --------------------------------------------------------------------------- the spinning corner


def test_the_spinning_corner_reduces_to_the_balance_and_to_the_held_top():
    cfg = make_config("seed")
    inertia, d = cfg.preset.inertia, math.sqrt(3.0)
    lam0 = math.sqrt(8 * 980 * d / (inertia + 8 * d * d))
    # no spin: the held pivot's double rate 21.516 /s, no turn
    sc = spinning_corner(0.0, cfg=cfg)
    assert sc.lam == pytest.approx(lam0, rel=1e-12) == pytest.approx(21.5158, abs=1e-4)
    assert sc.winding == 0.0 and sc.slip_c == math.inf
    # the held top: roots i·CΩ/2A ± √(λ0² − (CΩ/2A)²), exactly
    for om in (1.0, 7.0, 30.0):
        wp = inertia * om / (2 * (inertia + 8 * d * d))
        r = spinning_roots(om, inertia=inertia, d=d, slip_c=math.inf)
        s = r[np.argmax(r.real)]
        assert s.imag == pytest.approx(wp, rel=1e-12) and s.real == pytest.approx(math.sqrt(lam0**2 - wp**2), rel=1e-12)
    # a stiff pivot friction tends to the held top; every root solves the cubic
    r_stiff = spinning_roots(10.0, inertia=inertia, d=d, slip_c=1e9)
    r_held = spinning_roots(10.0, inertia=inertia, d=d, slip_c=math.inf)
    assert max(r_stiff, key=lambda z: z.real) == pytest.approx(max(r_held, key=lambda z: z.real), rel=1e-6)
    c, om, m, g = 500.0, 10.0, 8.0, 980.0
    for s in spinning_roots(om, inertia=inertia, d=d, slip_c=c):
        val = (inertia * m * s**3 + ((inertia + m * d * d) * c - 1j * inertia * m * om) * s**2
               - (1j * inertia * c * om + m * m * g * d) * s - m * g * d * c)
        assert abs(val) < 1e-6 * m * g * d * c
    # the slipping pivot at Ω = 0 is the physical preset's cubic (docs/model.md §12: 23.127 /s)
    phys = make_config("physical")
    assert spinning_corner(0.0, cfg=phys).lam == pytest.approx(23.1267, abs=1e-4)


def test_seed_friction_of_a_spinning_die_is_set_by_the_spin():
    """σ, the spectral norm of the eight nodes' horizontal velocities of a die spinning at Ω about the vertical
    through its corner, is 2√2·Ω·half: computed here from the nodes' positions."""
    from dicetrace.analysis.corner import corner_orientation

    cfg = make_config("seed")
    rot = corner_orientation(0.0, 0.0)
    nodes = np.array(list(itertools.product((-1.0, 1.0), repeat=3)))
    pos = (rot @ nodes.T).T - rot @ np.array([-1.0, -1.0, -1.0])  # from the pivot (node 1)
    for om in (0.5, 3.0, 12.0):
        sigma = np.linalg.norm(np.cross([0.0, 0.0, om], pos)[:, :2], 2)
        assert sigma == pytest.approx(2 * math.sqrt(2) * om, rel=1e-12)
        assert pivot_friction(cfg, om) == pytest.approx(cfg.preset.mu * 8 * 980 / sigma, rel=1e-12)
    assert pivot_friction(cfg, 0.0) == math.inf
    phys = make_config("physical")
    assert pivot_friction(phys, 5.0) == pytest.approx(phys.preset.mu * 8 * 980 / phys.preset.v_reg_cm_s)


def test_the_three_readings_of_the_winding_differ():
    sc = spinning_corner(10.0, cfg=make_config("seed"))
    assert sc.winding == pytest.approx((10.0 - sc.omega_p) * LN10 / sc.lam)
    assert sc.winding_issue == pytest.approx(10.0 * LN10 / sc.lam)
    assert sc.winding < sc.winding_issue and sc.winding < sc.winding_held
    assert sc.lam > sc.lam_held  # the slipping pivot falls faster


@pytest.mark.slow
def test_releases_at_a_set_spin_wind_as_the_slipping_cubic_says():
    """In the simulator (seed, contact-adaptive 1e-9): rings of releases off the balance spinning at 3 rad/s, at tilts
    1e-5 … 1e-3: the borders turn by (Ω − ω_p)·ln10/λ per decade of tilt (0.26901 rad), not by the held pivot's
    0.2919 or the issue's Ω·ln10/λ 0.3019."""
    cfg = make_config("seed", integrator="contact-adaptive", tol=1e-9)
    circles = [release_borders(cfg, a, spin=3.0, n_phi=12, tol=1e-7) for a in (1e-5, 1e-4, 1e-3)]
    assert all(c["three_sectors"] and sorted(c["faces"]) == [4, 5, 6] for c in circles)
    radii, ang, pairs = border_tracks(circles, [4, 5, 6])
    fit = fit_spiral(radii, ang)
    sc = spinning_corner(3.0, cfg=cfg)
    assert fit.winding == pytest.approx(sc.winding, rel=2e-4)
    assert abs(fit.winding - sc.winding_held) > 0.02 and abs(fit.winding - sc.winding_issue) > 0.03


# --------------------------------------------------------------------------- the spiral fit on a synthetic map


def _spiral_map(centre, winding, m):
    """A classifier of a synthetic map: three faces in sectors of the phase arg(M z) + c·ln|M z| (z: the point less
    the centre, c = −winding/ln 10 for det M > 0), the borders turning counter-clockwise by ``winding`` per decade as
    the radius shrinks."""
    c = -winding / LN10 * math.copysign(1.0, np.linalg.det(m))

    def classify(pts):
        z = (np.asarray(pts, float) - centre) @ np.asarray(m).T
        ph = np.arctan2(z[:, 1], z[:, 0]) - c * np.log(np.hypot(z[:, 0], z[:, 1]))
        k = np.floor((ph % (2 * np.pi)) / (2 * np.pi / 3)).astype(np.int64) % 3
        return np.array([1, 3, 5])[k]

    return classify


@pytest.mark.slow  # each case bisects every border on a dozen circles: 0.5-1 s
@pytest.mark.parametrize("winding, m", [
    (0.27, [[1.0, 0.0], [0.0, 1.0]]),
    (0.75, [[1.0, 0.6], [-0.2, 0.4]]),      # sheared and squeezed: the borders' local rates differ
    (-1.2, [[1.0, 0.0], [0.3, 1.4]]),      # (a stronger distortion folds the phase of so fast a spiral)
    (0.5, [[0.0, 1.0], [1.0, 0.2]]),        # a reflection: the borders' order is reversed
])
def test_the_spiral_fit_reads_a_known_winding_through_the_circle_bisection(winding, m):
    centre = np.array([0.3, 0.7])
    classify = _spiral_map(centre, winding, np.array(m))
    radii = 10.0 ** -np.arange(2.0, 7.01, 0.5)
    circles = [{**circle_sectors(classify, centre, r, n=48, angle_tol=1e-9), "radius": r} for r in radii]
    assert all(c["three_sectors"] for c in circles)
    r, ang, pairs = border_tracks(circles, [1, 3, 5])
    assert len(r) == len(radii) and len(set(pairs)) == 3
    fit = fit_spiral(r, ang)
    assert fit.winding == pytest.approx(winding, abs=1e-6) and fit.rms < 1e-6
    assert fit.stderr < 1e-5


def test_the_naive_slope_is_biased_by_the_slice_distortion_and_the_fit_is_not():
    centre = np.array([0.0, 0.0])
    m = np.array([[1.0, 0.0], [0.0, 0.1]])  # a map ten times squeezed
    classify = _spiral_map(centre, 0.4, m)
    radii = 10.0 ** -np.arange(2.0, 5.01, 0.5)
    circles = [{**circle_sectors(classify, centre, r, n=96, angle_tol=1e-10), "radius": r} for r in radii]
    fit = fit_spiral(*border_tracks(circles, [1, 3, 5])[:2])
    assert fit.winding == pytest.approx(0.4, abs=1e-6)
    assert abs(fit.naive - 0.4) > 0.02


def test_too_few_circles_give_no_fit():
    f = fit_spiral([1e-3], [[0.1, 2.0, 4.0]])
    assert math.isnan(f.winding) and f.status == "too few"


# --------------------------------------------------------------------------- closest approach and its share


def test_stretch_fit_recovers_a_power_law():
    r = np.repeat(10.0 ** -np.arange(2, 8.0), 4)
    d = 3.0 * r**0.45 * np.exp(np.random.default_rng(1).normal(0, 0.01, r.size))
    f = stretch_fit(r, d)
    assert f["beta"] == pytest.approx(0.45, abs=0.005) and f["J"] == pytest.approx(3.0, rel=0.05)


@pytest.mark.parametrize("beta", [1.0, 0.5])
def test_the_share_near_points_of_known_density_and_stretch(beta):
    """Points of the unit square, 20 'triple points' at random places with D_min = J_i r^β near each (r: distance to
    the nearest); the share of uniform throws with D_min < D is Σ π (D/J_i)^(2/β) at small D, and its log-log slope
    2/β (2: the D² law)."""
    rng = np.random.default_rng(7)
    pts = rng.uniform(0.2, 0.8, (20, 2))
    J = rng.uniform(2.0, 6.0, 20)
    x = rng.uniform(0, 1, (200_000, 2))
    dist = np.linalg.norm(x[:, None, :] - pts[None, :, :], axis=2)
    dmin = np.min(J[None, :] * dist**beta, axis=1)
    D = np.geomspace(0.005, 0.1, 8) if beta == 1.0 else np.geomspace(0.05, 0.35, 8)
    sh = share_curve(dmin, D)
    pred = predicted_share(D, J, np.full(20, beta))
    ok = np.array(sh["count"]) >= 50
    for s, e, p in zip(np.array(sh["share"])[ok], np.array(sh["stderr"])[ok], pred[ok]):
        assert abs(s - p) < 4 * e + 1e-3 * p  # overlaps between the discs are negligible at these D
    sl = loglog_slope(D[ok], np.array(sh["count"])[ok])
    assert sl["slope"] == pytest.approx(2 / beta, abs=4 * sl["stderr"])
    assert sl["stderr"] < 0.2 * (2 / beta)
