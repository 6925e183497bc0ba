"""The explorer's maps of any die (``die=X,Y,Z``, ``load=W@X,Y,Z``; ``dicetrace explore --die/--load``): the view,
the maps, a hover, a saved scan and the viewer's throw are of that die, and the page says which die it shows."""

from __future__ import annotations

import numpy as np
import pytest

from dicetrace.explore.view import View, ViewError, view_from_query
from dicetrace.params import make_config

from explore_helpers import png_outcomes, scan_outcomes, wait_ready

#: A box 2 × 2 × 3 cm on a small grid of the home window (physical: a box runs on contact-tsit5).
BOX = {"window": "0,0.1,0,0.1", "res": "5", "preset": "physical", "die": "2,2,3"}
BOX_CFG = make_config("physical", half_extents_cm=(1.0, 1.0, 1.5))


def test_the_die_and_load_round_trip_through_the_query_and_reach_the_config():
    v = view_from_query({**BOX, "load": "0.25@0,0,-1"})
    assert v.die == (2.0, 2.0, 3.0) and v.load == (0.25, 0.0, 0.0, -1.0)
    assert view_from_query(v.to_query()) == v and v.to_query()["die"] == "2,2,3"
    assert v.to_query()["load"] == "0.25@0,0,-1"
    p = v.config().preset
    assert p.half_extents_cm == (1.0, 1.0, 1.5) and p.load_fraction == 0.25 and p.load_cm == (0.0, 0.0, -1.0)
    assert v.key() != view_from_query(BOX).key()  # another die, another map in the cache
    # the preset's own cube, given by its sides, is the cube (as a scan writes it)
    assert view_from_query({**BOX, "die": "2,2,2"}).config() == make_config("physical")
    assert View(preset="physical", die=(2, 2, 3)) == View(preset="physical", die="2,2,3")


@pytest.mark.parametrize("query, param, words", [
    ({"die": "2,2"}, "die", "needs three sides in cm"),
    ({"die": "2,0,2"}, "die", "needs three sides > 0 cm"),
    ({"load": "0.3"}, "load", "needs W@X,Y,Z"),
    ({"load": "0.3@4,0,0"}, "load", "lies outside the box"),
    ({"preset": "seed"}, "integrator", "is no uniform cube"),
])
def test_a_bad_die_names_its_parameter(query, param, words):
    with pytest.raises(ViewError) as ei:
        view_from_query({**BOX, **query})
    assert ei.value.param == param and words in str(ei.value)


@pytest.mark.slow
def test_the_map_of_a_box_is_its_scan_and_not_the_cube_s(client, tmp_path):
    from dicetrace.scan import scan_definition

    expected = scan_outcomes(tmp_path, BOX["window"], 5, config=BOX_CFG)
    got = png_outcomes(client.get("/api/map.png", params=BOX).content)
    np.testing.assert_array_equal(got, expected)
    cube = png_outcomes(client.get("/api/map.png", params={**BOX, "die": ""}).content)
    assert not np.array_equal(cube, got)
    j = client.get("/api/view", params=BOX).json()
    assert j["die"] == "box 2 × 2 × 3 cm" and j["query"]["die"] == "2,2,3"
    assert client.get("/api/view", params={**BOX, "die": "2,2,2", "load": "0.3@0,0,0.5"}).json()["die"] == \
        "cube 2 × 2 × 2 cm, load 0.3 of its mass at (0, 0, 0.5) cm"
    r = client.get("/api/view", params={**BOX, "die": "2,x,3"})
    assert r.status_code == 400 and r.json()["param"] == "die"
    # a hover is that die's throw, and a saved view a scan of that die
    from dicetrace.explore.compute import point_ic
    from dicetrace.simulate import simulate

    h = client.get("/api/hover", params={**BOX, "i": 2, "j": 3}).json()
    _, ic = point_ic(view_from_query(BOX), 2, 3)
    roll = simulate(ic, config=BOX_CFG)
    assert (h["outcome"], h["steps"], h["contact_sequence"], h["die"]) == (
        roll.outcome, roll.steps, roll.contact_sequence, "box 2 × 2 × 3 cm")
    assert h["outcome"] == expected[2, 3]
    r = client.post("/api/save", params={**BOX, "name": "box"})
    assert r.status_code == 200, r.text
    assert scan_definition(tmp_path / "saved" / "box").config == BOX_CFG


@pytest.mark.slow
def test_the_viewer_s_throw_is_recorded_with_the_box(client):
    from dicetrace.sinks.rerun import read_rrd_metadata

    r = client.get("/api/throw.rrd", params={**BOX, "i": 1, "j": 1, "download": 1})
    assert r.status_code == 200
    assert "die2x2x3" in r.headers["content-disposition"]
    import tempfile

    with tempfile.NamedTemporaryFile(suffix=".rrd") as f:
        f.write(r.content)
        f.flush()
        assert read_rrd_metadata(f.name)["config"]["preset"]["half_extents_cm"] == [1.0, 1.0, 1.5]


@pytest.mark.slow
def test_the_page_says_which_die_it_shows(browser, tmp_path):
    from dicetrace.explore import Explorer

    with Explorer(window="0,0.1,0,0.1", res=4, preset="physical", die="2,2,3", load="0.2@0,0,-1") as ex:
        page = browser.new_page(viewport={"width": 1300, "height": 900})
        page.goto(ex.url)
        wait_ready(page)
        assert page.inner_text("#dieshown") == "die: box 2 × 2 × 3 cm, load 0.2 of its mass at (0, 0, -1) cm;"
        assert page.input_value("#die") == "2,2,3" and page.input_value("#load") == "0.2@0,0,-1"
        # another die typed in and applied: the header and the URL follow
        page.fill("#die", "2,3,2")
        page.fill("#load", "")
        page.click("#apply")
        page.wait_for_function("document.getElementById('dieshown').textContent.includes('2 × 3 × 2')")
        wait_ready(page)
        assert page.inner_text("#dieshown") == "die: box 2 × 3 × 2 cm;"
        assert "die=2%2C3%2C2" in page.url and "load=" not in page.url
