"""Chaos-measure table across a parameter sweep."""

from __future__ import annotations

import math

import numpy as np
import pytest

from analysis_synthetic import line_classify, newton_classify, sample_grid
from dicetrace.analysis import chaos_sweep


def test_chaos_sweep_orders_smooth_and_fractal():
    # stand-ins for "high damping" (a straight border) and "low damping"
    # (a fractal Wada border): the table must rank them, with finite error bars.
    smooth = sample_grid(line_classify, [(0, 1), (0, 1)], (200, 200))
    fractal = sample_grid(newton_classify, [(-0.5, 0.5), (-0.5, 0.5)], (200, 200))
    rng = np.random.default_rng(3)
    pts = rng.uniform(0, 1, (5000, 2))
    table = chaos_sweep(
        {0.01: smooth, 0.005: fractal},
        classifiers={0.01: line_classify},
        points=pts,
        eps_list=np.geomspace(1e-3, 1e-1, 6),
        rng=rng,
        param_name="gamma_s_cm",
        n_boot=50,
    )
    assert table["gamma_s_cm"].tolist() == [0.005, 0.01]
    fr, sm = table.iloc[0], table.iloc[1]
    assert fr.boundary_fraction > sm.boundary_fraction
    assert fr.alpha < sm.alpha
    assert fr.Sbb > sm.Sbb and not sm.fractal_boundary
    assert table.fractal_boundary.tolist() == (table.Sbb > math.log(2)).tolist()
    # the straight border: alpha = 1 (tolerance 0.05, ~ 5 x its stderr at 200^2)
    assert sm.alpha == pytest.approx(1.0, abs=0.05)
    assert sm.alpha_perturbation == pytest.approx(1.0, abs=0.1)
    assert math.isnan(fr.alpha_perturbation)
    for col in ("boundary_fraction_block_stderr", "alpha_stderr", "alpha_block_stderr", "Sb_stderr", "Sbb_stderr"):
        assert np.isfinite(table[col]).all() and (table[col] >= 0).all()


def test_a_map_without_borders_has_no_alpha():
    """A map of one outcome has no uncertain box and no uncertain pair: α is undefined (NaN),
    the boundary fraction 0, and the sweep goes on to the other maps."""
    one = np.full((41, 41), 3)
    half = np.where(np.arange(41)[None, :] < 20, 1, 2).repeat(41, axis=0)
    pts = np.random.default_rng(0).random((200, 2))
    table = chaos_sweep(
        {"one": one, "half": half},
        classifiers={"one": lambda p: np.full(len(p), 3), "half": lambda p: np.where(p[:, 0] < 0.5, 1, 2)},
        points=pts, eps_list=[1e-3, 1e-2, 1e-1], rng=np.random.default_rng(1), param_name="map", n_boot=10,
    ).set_index("map")
    assert table.loc["one", "boundary_fraction"] == 0.0
    assert np.isnan(table.loc["one", "alpha"]) and np.isnan(table.loc["one", "alpha_perturbation"])
    assert np.isfinite(table.loc["half", "alpha"])
    assert np.isfinite(table.loc["half", "alpha_perturbation"]) and table.loc["half", "boundary_fraction"] > 0


def test_map_measures_of_a_smooth_and_a_fractal_map():
    """Study b's set of measures (without perturbation): a straight border against Newton's fractal basins."""
    from types import SimpleNamespace

    from dicetrace.analysis.sweep import map_measures

    def sample(classify, ranges, n):
        g = sample_grid(classify, ranges, (n, n))
        return SimpleNamespace(labels=g, spacing=((ranges[0][1] - ranges[0][0]) / (n - 1),) * 2, window=ranges,
                               extent=ranges)

    smooth = map_measures("line", sample(line_classify, [(0, 1), (0, 1)], 81), None, np.random.default_rng(0),
                          perturb=False)
    fractal = map_measures("newton", sample(newton_classify, [(-0.5, 0.5), (-0.5, 0.5)], 81), None,
                           np.random.default_rng(0), perturb=False)
    assert smooth["window"] == "line" and smooth["res"] == 81 and smooth["n_outcomes"] == 2
    assert "wada_merge_r" not in smooth and "alpha_pert" not in smooth  # two outcomes; no perturbation asked
    assert fractal["n_outcomes"] == 3 and "wada_merge_r" in fractal
    # a line's border: dimension ≈ 1 (the mask method reads 1.17 on 81² nodes), α ≈ 1; the fractal's: more, less
    assert 0.9 < smooth["dim_mask"] < 1.25 and fractal["dim_mask"] > smooth["dim_mask"] + 0.2
    assert smooth["alpha_res"] == pytest.approx(1.0, abs=0.1) and fractal["alpha_res"] < smooth["alpha_res"] - 0.3


def test_map_measures_perturbation_uses_the_classifier():
    from types import SimpleNamespace

    from dicetrace.analysis.sweep import map_measures

    g = sample_grid(line_classify, [(0, 1), (0, 1)], (41, 41))
    s = SimpleNamespace(labels=g, spacing=(0.025, 0.025), window=[(0, 1), (0, 1)], extent=[(0, 1), (0, 1)])
    r = map_measures("line", s, line_classify, np.random.default_rng(1), perturb=True, n_points=4000,
                     eps_rel=np.logspace(-3, -1, 3))
    assert r["pert_n"] == 4000 and len(r["pert_f"]) == 3 and r["pert_eps"] == pytest.approx(np.logspace(-3, -1, 3))
    assert r["alpha_pert"] == pytest.approx(1.0, abs=0.25)  # a smooth border: f ∝ ε (4000 points: ± 0.2)
    assert "wada_grid_G" not in r  # two outcomes: no Wada test
