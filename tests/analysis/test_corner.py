"""The corner balance: its analytic rates, the simulator's, the faces around it, and the triple-point tools."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dicetrace.analysis.corner import (EDGE_AZIMUTHS, corner_balance, corner_orientation, corner_release,
                                       corner_release_rate, corner_tilt, face_map, sector_boundaries)
from dicetrace.analysis.corner_slice import arcs, circle_sectors, clean_junctions, corner_distance, refine_triple
from dicetrace.analysis.junctions import strip_map, three_sector_map
from dicetrace.params import make_config

TIGHT = {"integrator": "contact-tsit5", "tol": 1e-10, "tol_growth": 0.0}


def test_rigid_pivot_rate_is_the_formula_and_seed_keeps_it():
    b = corner_balance(preset="seed")
    d, inertia = math.sqrt(3.0), 16.0 / 3.0
    assert b.d == pytest.approx(d) and b.inertia_pivot == pytest.approx(inertia + 8 * d * d)
    assert b.rate_rigid == pytest.approx(math.sqrt(8 * 980 * d / (inertia + 8 * d * d)), rel=1e-12)
    assert b.rate_rigid == pytest.approx(21.5158, abs=1e-4)
    assert b.rate == b.rate_rigid and b.rate_change == 0.0  # degree-0 friction: no slip at first order
    assert b.depth_eq == pytest.approx(8 * 980 / 5e5) and b.z_cm == pytest.approx(d - 8 * 980 / 5e5)
    assert all(v.real < 0 for v in b.vertical)  # the ground spring's mode is stable and decoupled


def test_physical_slip_raises_the_rate_and_vanishes_without_slip():
    b = corner_balance(preset="physical")
    s = b.rate
    poly = (b.inertia * 8 * s**3 + b.inertia_pivot * b.slip_c * s**2 - 64 * 980 * b.d * s - 8 * 980 * b.d * b.slip_c)
    assert abs(poly) < 1e-6 * 8 * 980 * b.d * b.slip_c
    assert b.rate == pytest.approx(23.1267, abs=1e-4) and b.rate_change == pytest.approx(0.0749, abs=1e-3)
    stiff = corner_balance(preset="physical", v_reg_cm_s=1e-6)  # c -> infinity: the rigid pivot
    assert stiff.rate == pytest.approx(stiff.rate_rigid, rel=1e-6)


def test_orientation_puts_node_1_below_the_centre_and_tilts_toward_phi():
    cfg = make_config("physical")
    off = cfg.initial_offsets(corner_orientation())
    assert off[0] == pytest.approx([0.0, 0.0, -math.sqrt(3.0)], abs=1e-12)
    edge = off[4] - off[0]  # node 1 -> node 5 at azimuth 0
    assert math.atan2(edge[1], edge[0]) == pytest.approx(0.0, abs=1e-12)
    tilt, az = corner_tilt(cfg.initial_offsets(corner_orientation(1e-3, 2.0))[None])
    assert tilt[0] == pytest.approx(1e-3, rel=1e-9) and az[0] == pytest.approx(2.0, abs=1e-9)


def test_simulated_rate_matches_the_slipping_pivot_not_the_rigid_one():
    b = corner_balance(preset="physical")
    r = corner_release_rate(preset="physical", tilt0=1e-10, start=1e4, saturation=1e-3, phi=1.0, **TIGHT)
    assert r.status == "settled"
    assert abs(r.rate - b.rate) < 1e-6 * b.rate  # measured: 1.5e-9 of it
    assert abs(r.rate - b.rate_rigid) > 1.0
    assert r.drift < 1e-6  # two equal rates: the tilt keeps its direction


def test_physical_release_map_has_three_sectors_split_on_the_edges():
    cfg = make_config("physical", **TIGHT)
    phis = np.linspace(0.0, 2 * math.pi, 12, endpoint=False) + 0.1
    labels = face_map(cfg, [1e-6], phis)[0]
    assert sorted(set(labels.tolist())) == [4, 5, 6]
    rows = sector_boundaries(cfg, 1e-6, tol=1e-7, phis=phis, labels=labels.tolist())
    assert len(rows) == 3
    nearest = set()
    for row in rows:
        dist = [abs(math.remainder(row["phi"] - e, 2 * math.pi)) for e in EDGE_AZIMUTHS]
        assert min(dist) < 1e-6 and row["error"] <= 1e-7
        nearest.add(int(np.argmin(dist)))
    assert nearest == {0, 1, 2}


def test_release_at_rest_is_at_the_balance_and_corner_distance_sees_it():
    from dicetrace.simulate import Record

    cfg = make_config("physical", **TIGHT)
    roll = corner_release(cfg, 1e-6, 0.5, t_max_s=0.3, record=Record(states=True))
    b = corner_balance(config=cfg)
    near = corner_distance(roll.trace, b.rate, b.d, b.inertia)
    assert near["d_min"] < 2e-6 and near["t_min"] < 0.01 and near["node"] == 1
    far = corner_distance(corner_release(cfg, 0.3, 0.5, record=Record(states=True)).trace, b.rate, b.d, b.inertia)
    assert far["d_min"] > 0.25


def _sector_classifier(centre=(0.3, 0.6), angles=(0.2, 2.3, 4.1)):
    def classify(pts):
        pts = np.atleast_2d(pts)
        phi = np.mod(np.arctan2(pts[:, 1] - centre[1], pts[:, 0] - centre[0]) - angles[0], 2 * np.pi)
        edges = np.mod(np.asarray(angles) - angles[0], 2 * np.pi)
        return np.array([1, 2, 3])[np.searchsorted(edges, phi, side="right") - 1]
    return classify


def test_arcs_are_cyclic_runs():
    assert arcs([1, 1, 2, 2, 3, 1]) == [(2, 2, 3), (3, 4, 4), (1, 5, 1)]
    assert arcs([4, 4, 4]) == [(4, 0, 2)]


def test_circle_sectors_find_three_sectors_and_their_borders():
    classify = _sector_classifier()
    c = circle_sectors(classify, (0.3, 0.6), 1e-5, n=24, angle_tol=1e-9)
    assert c["three_sectors"] and c["n_arcs"] == 3
    assert sorted(round(b["angle"], 6) for b in c["borders"]) == [0.2, 2.3, 4.1]
    off = circle_sectors(classify, (0.5, 0.6), 1e-3, n=24)  # away from the point: one face
    assert not off["three_sectors"] and off["n_arcs"] == 1


def test_clean_junctions_and_refinement_find_the_control_point():
    g = three_sector_map(65)
    cand = clean_junctions(g)
    assert len(cand) >= 1
    ax = np.linspace(0.0, 1.0, 65)
    centre = (0.5 + 1 / (2 * math.pi), 0.5 - 1 / (3 * math.e))
    i, j = cand[0]
    assert abs(ax[i] - centre[0]) < 2 / 64 and abs(ax[j] - centre[1]) < 2 / 64
    assert len(clean_junctions(strip_map(65))) == 0  # three faces, no point where they meet
    r = refine_triple(_sector_classifier(centre), (ax[i], ax[j]), 1.5 / 64, tol=1e-9)
    assert r["status"] == "vertex" and r["labels"] == [1, 2, 3]
    assert abs(r["x"] - centre[0]) < 1e-8 and abs(r["y"] - centre[1]) < 1e-8
