"""The explorer's view: URL parameters in, a validated View out, and back."""

from __future__ import annotations

import math

import pytest

from dicetrace.explore.view import MAX_RES, View, ViewError, view_from_query
from dicetrace.ics import WINDOWS


def test_query_round_trip_keeps_every_field_exactly():
    v = view_from_query({"window": "0.1,0.30000000000000004,1,2", "res": "40,30", "gamma": "0.01", "dt": "0.0005",
                         "integrator": "rk4"})
    assert v.window == ((0.1, 0.30000000000000004), (1.0, 2.0))
    assert v.res == (40, 30) and v.gamma == 0.01 and v.dt == 0.0005 and v.integrator == "rk4"
    assert view_from_query(v.to_query()) == v
    cfg = v.config()
    assert cfg.preset.gamma == 0.01 and cfg.numerics.dt_s == 0.0005 and cfg.numerics.integrator == "rk4"


def test_named_window_and_defaults():
    v = view_from_query({"window": "party"})
    assert v.window == WINDOWS["party"] and v.slice == "seed" and v.z is None
    g = v.grid()
    assert g.res == v.res and g.window == WINDOWS["party"]


def test_seed3_gets_its_z_and_a_flat_grid():
    v = view_from_query({"slice": "seed3", "window": "home", "z": "0.02", "res": "8"})
    g = v.grid()
    assert g.res == (8, 8, 1) and g.window[2] == (0.02, 0.02)
    assert view_from_query({"slice": "seed3", "window": "home"}).z == 0.0


@pytest.mark.parametrize(
    "query, param, words",
    [
        ({"res": "abc"}, "res", "whole numbers"),
        ({"res": "100000"}, "res", f"between 2 and {MAX_RES}"),
        ({"res": "1"}, "res", "between 2"),
        ({"res": "3,4,5"}, "res", "NX,NY"),
        # the window's messages are dicetrace.windows.get_window's, the one window parser, under param "window"
        ({"window": "1,1,2,3"}, "window", "x1 > x0 (zero width)"),
        ({"window": "2,1,2,3"}, "window", "x1 > x0 (negative width)"),
        ({"window": "1,2,3"}, "window", "needs 2, 4 or 6 numbers"),
        ({"window": "1,2,3,4,5,6"}, "window", "needs 2 (lo, hi) ranges for a 2-D slice"),
        ({"window": "1,2,nan,4"}, "window", "non-finite"),
        ({"window": "1,2,x,4"}, "window", "unknown window '1,2,x,4'"),
        ({"window": "nowhere"}, "window", "a name"),
        ({"window": "1e7,2e7,3,4"}, "window", "within ±1e+06"),
        ({"window": "1.5,1.5000000000000004,3,4"}, "window", "float64 limit"),
        ({"slice": "cube"}, "slice", "unknown slice"),
        ({"preset": "wood"}, "preset", "unknown preset"),
        ({"integrator": "leapfrog"}, "integrator", "unknown integrator"),
        ({"integrator": "contact-rosenbrock"}, "integrator", "'contact-rosenbrock': it was removed"),
        ({"gamma": "-1"}, "gamma", "damping"),
        ({"dt": "1"}, "dt", "time step"),
        ({"dt": "inf"}, "dt", "finite"),
        ({"z": "0.1"}, "z", "2-D"),
    ],
)
def test_bad_parameters_name_themselves(query, param, words):
    with pytest.raises(ViewError) as ei:
        view_from_query(query)
    assert ei.value.param == param
    assert words in str(ei.value)


def test_zoom_limit_is_where_pixels_stay_distinct():
    x = 1.5
    ulp = math.ulp(x)
    ok = View(window=((x, x + 8 * ulp * 15), (3.0, 4.0)), res=(16, 16))
    xs = ok.grid().axes()[0]
    assert len(set(xs.tolist())) == 16  # every pixel its own coordinate
    with pytest.raises(ViewError, match="float64 limit"):
        View(window=((x, x + 7 * ulp * 15), (3.0, 4.0)), res=(16, 16))


def test_pixel_is_the_nearest_grid_point():
    v = View(window=((0.0, 1.0), (0.0, 2.0)), res=(11, 5))
    assert v.pixel(0.0, 0.0) == (0, 0)
    assert v.pixel(0.31, 1.6) == (3, 3)
    assert v.pixel(1.0, 2.0) == (10, 4)


def test_a_view_holds_its_config_built_once(monkeypatch):
    """The Config is built with the view (make_config, the one validator), not again each time it is asked for."""
    import dicetrace.params as params

    calls = []
    real, start = params.make_config, View()
    monkeypatch.setattr(params, "make_config", lambda *a, **k: calls.append(1) or real(*a, **k))
    v = view_from_query({"window": "home", "res": "8", "preset": "physical", "gamma": "0.01"}, start)
    assert len(calls) == 1
    assert v.config() is v.config() and len(calls) == 1
    assert v.config() == real("physical", gamma=0.01)
    assert v == View(window=((0.0, 0.1), (0.0, 0.1)), res=(8, 8), preset="physical", gamma=0.01)  # read: name, "N"
