"""Fixtures for the analysis tests (synthetic basins with known answers)."""

from __future__ import annotations

import os
import sys

import pytest

sys.path.insert(0, os.path.dirname(__file__))

from analysis_synthetic import newton_classify, sample_grid  # noqa: E402

NEWTON_EXTENT = [(-1.0, 1.0), (-1.0, 1.0)]


@pytest.fixture(scope="session")
def newton_grid():
    """Newton z**3 - 1 basins on [-1, 1]**2, 300 x 300 (the Attractors.jl test grid)."""
    return sample_grid(newton_classify, NEWTON_EXTENT, (300, 300))


@pytest.fixture(scope="session")
def mpl_agg():
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    yield plt
    plt.close("all")
