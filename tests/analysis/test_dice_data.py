"""The measured data of real dice (dicetrace.analysis.dice_data): the Gazette note's Table 1 and what it implies."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from dicetrace.analysis.dice_data import GAZETTE_97_16, NOT_TRANSCRIBED, SOURCES, MeasuredCuboids


def test_the_table_has_fifteen_dice_in_order_of_shape():
    g = GAZETTE_97_16
    assert len(g) == 15
    assert np.all(np.diff(g.aspect) > 0)
    assert np.all((g.p > 0) & (g.p < 1)) and np.all(g.n > 0)
    assert int(g.n.sum()) == 9329


def test_every_printed_share_is_one_integer_count():
    """Each p is k/N rounded to 3 decimals for exactly one integer k: the counts are recovered without loss."""
    g = GAZETTE_97_16
    for p, n, k in zip(g.p, g.n, g.count):
        candidates = [c for c in range(n + 1) if round(c / n, 3) == round(float(p), 3)]
        assert candidates == [k]
    assert g.count.tolist() == [304, 620, 438, 367, 206, 204, 150, 82, 34, 24, 12, 19, 6, 2, 3]


def test_the_cube_lies_between_the_points_around_it():
    """A cube (x/y = 1) has p = 1/3: the measured shares fall through 1/3 between x/y = 0.97 and 1.16."""
    g = GAZETTE_97_16
    below, above = g.p[g.aspect < 1], g.p[g.aspect > 1]
    assert below.min() > 1 / 3 > above.max()


def test_the_arrays_are_read_only_and_checked():
    with pytest.raises(ValueError):
        GAZETTE_97_16.p[0] = 0.5
    with pytest.raises(ValueError, match="same length"):
        MeasuredCuboids(aspect=[1.0, 2.0], p=[0.3], n=[10], source="x")


def test_the_table_round_trips_through_a_parquet_file(tmp_path):
    frame = GAZETTE_97_16.as_frame()
    frame.to_parquet(tmp_path / "gazette.parquet")
    back = pd.read_parquet(tmp_path / "gazette.parquet")
    pd.testing.assert_frame_equal(back, frame)
    assert list(back.columns) == ["aspect", "p", "n", "count"]
    np.testing.assert_array_equal(back["count"], GAZETTE_97_16.count)


def test_sources_and_gaps_are_stated():
    assert "Table 1" in SOURCES["gazette"] and "97.16" in SOURCES["gazette"]
    assert "1302.3925" in SOURCES["riemer_stoyan_obreschkow"] and "1407.6307" in SOURCES["pender_uhrin"]
    assert set(NOT_TRANSCRIBED) >= {"riemer_stoyan_obreschkow", "pender_uhrin"}
