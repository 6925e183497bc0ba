"""Neighbouring throws and the FTLE field of a window (dicetrace.analysis.transient)."""

from __future__ import annotations

import numpy as np
import pytest


# -- divergence of neighbouring throws and their finite-time Lyapunov exponent ------------------------


def test_divergence_in_free_flight_is_the_exact_shear():
    """A pure vz offset dv: before the first contact every node is dv·t higher, the centre's velocity
    differs by dv and ω not at all, so d(t) = dv·sqrt(8 t² + tau²) exactly (tau the time scale)."""
    from dicetrace.analysis.transient import DIVERGENCE_TIME_SCALE_S as TAU
    from dicetrace.analysis.transient import throw_divergence
    from dicetrace.ics import seed_slice

    ic = seed_slice(1.65, 3.9)
    delta = 1e-7
    t, d, t_contact = throw_divergence(ic, delta=delta, direction=[0, 0, 1, 0, 0, 0])
    dv = delta * np.linalg.norm(ic)
    free = t < t_contact - 1e-12
    assert free.sum() > 150 and t_contact == pytest.approx(0.176)
    np.testing.assert_allclose(d[free], dv * np.sqrt(8 * t[free] ** 2 + TAU**2), rtol=1e-6)


def test_finite_time_lyapunov_of_a_throw_is_a_property_of_the_dynamics():
    """In the linear regime the fitted exponent does not depend on the size of the perturbation
    (measured 15.16 /s over the whole red-sea throw for delta = 1e-11 .. 1e-7, and 14.5 /s over its
    bouncing phase, which starts at the first contact)."""
    from dicetrace.analysis.transient import throw_lyapunov
    from dicetrace.ics import seed_slice

    ic = seed_slice(1.65, 3.9)
    for phase in ("whole", "bouncing"):
        fits = [throw_lyapunov(ic, delta=dl, rng=1, phase=phase) for dl in (1e-11, 1e-9)]
        assert fits[0].exponent == pytest.approx(fits[1].exponent, rel=1e-3) and 10 < fits[0].exponent < 30
        assert fits[0].fit_range[0] == pytest.approx(0.001 if phase == "whole" else 0.176)
    with pytest.raises(ValueError, match="direction"):
        throw_lyapunov(ic, direction=np.zeros(6))


@pytest.mark.slow
def test_the_ftle_field_is_higher_on_cell_borders():
    """Red-sea window, 30²: the throws at border nodes (outcome differs from a neighbour) part faster
    than those inside cells (measured mean 18.8 vs 16.5 /s, one-sided Mann-Whitney p = 4e-9)."""
    from scipy import stats

    from dicetrace.analysis import boundary_mask
    from dicetrace.analysis.transient import ftle_on_slice

    m = ftle_on_slice("red-sea", 30)
    assert m.ftle.shape == m.outcome.shape == (30, 30) and np.isfinite(m.ftle).all()
    border = boundary_mask(m.outcome)
    assert 0.5 < border.mean() < 0.95
    test = stats.mannwhitneyu(m.ftle[border], m.ftle[~border], alternative="greater")
    assert test.pvalue < 1e-4 and np.median(m.ftle) > 0


# -- the certificate of a map and its verdict --------------------------------------------------------


def _cert(base, tight, near):
    from dicetrace.analysis import agreement
    from dicetrace.analysis.transient import MapCertificate

    a_t, a_f = agreement(base, tight), agreement(base, near)
    return MapCertificate(a_t, a_f, bool(a_t.ci[1] >= a_f.ci[0]), np.asarray(base), None)


def test_verdict_needs_the_floor_and_more_than_chance():
    from dicetrace.analysis.transient import converged_verdict

    rng = np.random.default_rng(1)
    base = rng.integers(1, 7, 4000)
    other = rng.integers(1, 7, 4000)
    copy = base.copy()
    copy[:40] = other[:40]  # 99 % agreement
    assert converged_verdict(_cert(base, copy, copy))
    # below a floor of 99 %: not converged
    half = base.copy()
    half[:2000] = other[:2000]
    assert not converged_verdict(_cert(base, half, copy))
    # the floor at chance and the certificate at chance too: certify_map's rule passes it, the verdict does not
    c = _cert(base, other, rng.integers(1, 7, 4000))
    assert c.converged or c.tightened.ci[1] < c.floor.ci[0]
    assert not converged_verdict(c)


def test_certify_map_reuses_a_given_base_map():
    from dicetrace.analysis.simulator import sample_window
    from dicetrace.analysis.transient import certify_map
    from dicetrace.params import make_config

    cfg = make_config("seed")
    s = sample_window("home", 5, config=cfg)
    a = certify_map("home", 5, config=cfg)
    b = certify_map("home", 5, config=cfg, base=s.labels)
    assert np.array_equal(a.labels, b.labels)
    assert a.tightened == b.tightened and a.floor == b.floor
    with pytest.raises(ValueError, match="base has"):
        certify_map("home", 5, config=cfg, base=s.labels[:2])
