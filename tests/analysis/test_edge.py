"""The edge saddle in the simulation (analysis.edge) against the rigid-body linearisation, and the pooled rate."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dicetrace.analysis import edge_balance_rate
from dicetrace.analysis.edge import edge_release_rate, pooled_rate


def test_converged_seed_die_leaves_its_edge_at_the_rigid_body_rate():
    # Known answer: λ = √(m g r / I_edge) = √(3g / (2√2 s)) = 22.80 /s for the model's inertia (1/6) m s²
    # (analysis.settle.edge_balance_rate). The seed preset integrated accurately (contact-substep RK4, dt 0.25 ms)
    # holds the pivot (its friction is Coulomb's, μ = 1.2) and sinks it by only 8e-3 cm: measured 22.74 /s;
    # tolerance 1 %, the size of the compliance and of the non-linearity up to 0.01 rad.
    r = edge_release_rate(preset="seed", integrator="contact-substep", dt_s=2.5e-4, tilt0=1e-4)
    assert r.rate == pytest.approx(edge_balance_rate(), rel=0.01)
    assert r.fit_range[1] > r.fit_range[0]


def test_physical_die_pivot_creeps():
    # The physical preset's per-node friction is viscous below v_reg = 10 cm/s, so the pivot creeps and the rate
    # lies between the held pivot (22.80 /s) and the frictionless floor √(6g/(√2 s)) = 45.6 /s (settle study);
    # measured 24.4 /s, independent of tilt0 in 1e-8…1e-4 to 0.1 %.
    a = edge_release_rate(preset="physical", tilt0=1e-6)
    b = edge_release_rate(preset="physical", tilt0=1e-4)
    free = math.sqrt(6 * 980 / (math.sqrt(2) * 2))
    assert edge_balance_rate() < a.rate < free
    assert a.rate == pytest.approx(b.rate, rel=2e-3)


def test_pooled_rate_of_a_normal_sample():
    # Known answer: the median of n normal draws has standard error √(π/2) σ/√n (asymptotic); n = 400, σ = 1:
    # 0.0627. The order-statistic interval's half-width / 1.96 estimates it; tolerance 20 % (its two order
    # statistics are themselves random at this n).
    x = np.random.default_rng(4).normal(23.0, 1.0, 400)
    p = pooled_rate(x, alternatives=[x + 0.3])
    assert p.median == pytest.approx(23.0, abs=4 * 0.0627)
    assert p.stat == pytest.approx(math.sqrt(math.pi / 2) / 20, rel=0.2)
    assert p.syst == pytest.approx(0.3, rel=1e-9)
    assert p.total == pytest.approx(math.hypot(p.stat, 0.3), rel=1e-12)
    assert p.n == 400 and p.q25 < p.median < p.q75


def test_jacobian_of_the_physical_saddle_matches_its_release():
    # The physical preset's force law is smooth at rest, so the finite-difference Jacobian of the 0.1 s map about
    # the balance has one unstable eigenvalue, the same at h and h/100 (measured 24.427 both, to 1e-7), and equal
    # to the release rate (24.42 /s) to 0.5 % (the release fit sees the nonlinearity up to 0.01 rad).
    from dicetrace.analysis.edge import edge_jacobian_rate

    j = edge_jacobian_rate(preset="physical")
    assert j.rate == pytest.approx(j.rate_fine, rel=1e-4)
    rel = edge_release_rate(preset="physical", tilt0=1e-6)
    assert j.rate == pytest.approx(rel.rate, rel=5e-3)
    assert edge_balance_rate() < j.rate
