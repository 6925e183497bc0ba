"""Smoke tests: every figure is written as a non-empty PNG / GIF (Agg backend)."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from analysis_synthetic import lattice_grid, newton_classify, sample_grid

PNG = b"\x89PNG\r\n\x1a\n"


def _is_png(path):
    data = path.read_bytes()
    return len(data) > 1000 and data[:8] == PNG


@pytest.mark.slow  # a second or more (a fit, a subprocess): the quick loop skips it, CI runs it
def test_import_does_not_pull_matplotlib():
    import subprocess

    code = "import sys, dicetrace.analysis, dicetrace.analysis.plot; print('matplotlib' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


@pytest.fixture(scope="module")
def outcome_grid():
    g = sample_grid(newton_classify, [(-1, 1), (-1, 1)], (80, 80)) * 2 - 1  # labels 1, 3, 5
    g[:5, :5] = 0
    g[-3:, -3:] = -1
    return g


def test_outcome_map_and_zoom_series(tmp_path, mpl_agg, outcome_grid):
    from dicetrace.analysis.plot import plot_outcome_map, plot_zoom_series

    fig = plot_outcome_map(outcome_grid, extent=[(-1, 1), (-1, 1)], title="home", path=tmp_path / "map.png")
    assert _is_png(tmp_path / "map.png")
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert labels == ["did not settle", "undefined", "1", "3", "5"]
    exts = [[(-1, 1), (-1, 1)], [(-0.5, 0.0), (-0.3, 0.2)], [(-0.3, -0.2), (-0.1, 0.0)]]
    grids = [sample_grid(newton_classify, e, (60, 60)) for e in exts]
    fig = plot_zoom_series(grids, exts, titles=["a", "b", "c"], path=tmp_path / "zoom.png")
    assert _is_png(tmp_path / "zoom.png")
    rects = [p for p in fig.axes[0].patches]
    assert len(rects) == 1 and rects[0].get_edgecolor()[:3] == (1.0, 1.0, 1.0)
    assert rects[0].get_xy() == (-0.5, -0.3)


def test_settle_map(tmp_path, mpl_agg, outcome_grid):
    from dicetrace.analysis.plot import plot_settle_map

    t = np.random.default_rng(0).uniform(0.5, 20.0, outcome_grid.shape)
    plot_settle_map(outcome_grid, t, extent=[(0, 1), (0, 1)], path=tmp_path / "settle.png")
    assert _is_png(tmp_path / "settle.png")


@pytest.mark.slow  # about 0.7 s
def test_slice_animation_gif(tmp_path, mpl_agg):
    from PIL import Image

    from dicetrace.analysis.plot import animate_slices

    g3 = np.stack([np.roll(lattice_grid((40, 40), (8, 0), (3, 9)), k, axis=0) for k in range(4)], axis=2)
    animate_slices(g3, tmp_path / "stack.gif", extent=[(0, 1), (0, 1)], z_values=[0.0, 0.1, 0.2, 0.3])
    path = tmp_path / "stack.gif"
    assert path.stat().st_size > 1000
    with Image.open(path) as im:
        assert im.format == "GIF" and im.n_frames == 4


def test_contact_tree(tmp_path, mpl_agg):
    from dicetrace.analysis.plot import plot_contact_tree

    seqs = ["0-6-68-8-0-3", "0-6-68-8-0-3", "0-6-68-6-0-3", "0-1-12-2", np.array([0, 1, 3, 2], dtype=np.uint8)]
    fig = plot_contact_tree(seqs, path=tmp_path / "tree.png")
    assert _is_png(tmp_path / "tree.png")
    texts = [t.get_text() for t in fig.axes[0].texts]
    assert "68" in texts and "×2" in texts and "×1" in texts
    assert texts.count("0") == 3  # root + the two "0" after "8" and "6"


def test_ball_hill_portrait(tmp_path, mpl_agg):
    from dicetrace.analysis.plot import plot_ball_hill_phase_portrait

    fig = plot_ball_hill_phase_portrait(path=tmp_path / "ballhill.png")
    assert _is_png(tmp_path / "ballhill.png")
    assert len(fig.axes[0].lines) == 5  # four separatrices and the saddle
