"""The explorer in a real headless browser (Debian's chromium through Playwright).

Skipped, with the reason, where Playwright or a chromium is missing.  With
``DICETRACE_SCREENSHOT=PATH`` the zoomed view with two throws compared beside it is also
saved there (the README's screenshot, docs/explore.png)::

    DICETRACE_SCREENSHOT=docs/explore.png pytest tests/explore/test_browser.py -k test_page_map_zoom_and_throw
"""

from __future__ import annotations

import json
import os
from urllib.parse import parse_qs, urlparse

import numpy as np
import pytest

from explore_helpers import RES as TEST_RES, WINDOW as TEST_WINDOW
from explore_helpers import page_outcomes, scan_outcomes, shift_click, wait_ready

pytestmark = pytest.mark.slow

#: The map's resolution: the tests' small one, or a larger one for the README's screenshot.
SHOT = os.environ.get("DICETRACE_SCREENSHOT")
RES = 128 if SHOT else TEST_RES
#: The start window: the tests' small one, or all of red sea for the screenshot.
WINDOW = "1.0,2.0,3.5,4.5" if SHOT else TEST_WINDOW

@pytest.fixture
def explorer(tmp_path):
    from dicetrace.explore import Explorer

    with Explorer(window=WINDOW, res=RES, out=tmp_path / "saved") as ex:
        yield ex


def _window_of(page) -> str:
    return parse_qs(urlparse(page.url).query)["window"][0]


def test_page_map_zoom_and_throw(browser, explorer, tmp_path, monkeypatch):
    from dicetrace.explore import outcome_map

    monkeypatch.setattr(outcome_map, "BLOCK", 4 * RES)  # the refined pass in strips of four rows
    page = browser.new_page(viewport={"width": 1300, "height": 900})
    errors = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(explorer.url)
    wait_ready(page)
    np.testing.assert_array_equal(page_outcomes(page), scan_outcomes(tmp_path, WINDOW, RES))
    # the refined map was drawn strip by strip, top first
    assert page.evaluate("document.body.dataset.strips") == ",".join(str(r) for r in range(4, RES + 1, 4))

    # drag a box over the middle of the map: the view zooms and the map is the new window's
    box = page.locator("#mapbox").bounding_box()
    before = page.url
    page.mouse.move(box["x"] + box["width"] * 0.25, box["y"] + box["height"] * 0.25)
    page.mouse.down()
    page.mouse.move(box["x"] + box["width"] * 0.5, box["y"] + box["height"] * 0.5, steps=5)
    page.mouse.move(box["x"] + box["width"] * 0.75, box["y"] + box["height"] * 0.75, steps=5)
    page.mouse.up()
    page.wait_for_function(f"location.href !== {before!r} && document.body.dataset.state !== 'computing'",
                           timeout=120_000)
    wait_ready(page)
    zoom = _window_of(page)
    x0, x1, y0, y1 = map(float, zoom.split(","))
    a0, a1, b0, b1 = map(float, WINDOW.split(","))
    assert a0 < x0 < x1 < a1 and b0 < y0 < y1 < b1
    assert abs((x1 - x0) / (a1 - a0) - 0.5) < 0.05 and abs((y1 - y0) / (b1 - b0) - 0.5) < 0.05  # the box dragged
    np.testing.assert_array_equal(page_outcomes(page), scan_outcomes(tmp_path, zoom, RES, name="zoom"))

    # hover, then click: the throw's details, and Rerun's viewer draws the die
    page.mouse.move(box["x"] + box["width"] * 0.4, box["y"] + box["height"] * 0.6)
    page.wait_for_function("document.getElementById('hover').textContent.startsWith('hover')", timeout=30_000)
    page.mouse.click(box["x"] + box["width"] * 0.4, box["y"] + box["height"] * 0.6)
    page.wait_for_function("document.getElementById('info').dataset.throws", timeout=60_000)
    info = page.evaluate("JSON.parse(document.getElementById('info').dataset.throws)[0]")
    assert page.inner_text("#info").startswith("throw 1: ") and f"outcome {info['outcome']}" in page.inner_text("#info")
    page.wait_for_selector("#viewerbox canvas", timeout=120_000)
    page.wait_for_timeout(8000)  # the wasm viewer loads and draws the recording
    from PIL import Image
    import io

    img = np.asarray(Image.open(io.BytesIO(page.locator("#viewerbox").screenshot())).convert("RGB")).astype(float)
    assert img.std() > 10, "the embedded Rerun viewer is blank"
    assert len(np.unique(img.reshape(-1, 3), axis=0)) > 50
    # the viewer lays the throw out as `dicetrace record`'s blueprint does: its 3-D view (background
    # 250,250,250 in sinks.rerun.default_blueprint) fills the left 3/5 (Rerun's own layout has no such view:
    # 0.00001 of the left half without the active blueprint; 0.24-0.4 with it, the rest being the ground)
    share = (img[:, : img.shape[1] // 2] == 250).all(axis=-1).mean()
    assert share > 0.1, f"record's blueprint is not the viewer's layout ({share:.3f} of the left half is its 3-D view)"
    # shift-click a second point: both throws listed, with their divergence (the viewer: test_shift_click_...)
    two = shift_click(page, box, 0.7, 0.3)
    assert two[0] == info and two[1]["ic"] != info["ic"]
    text = page.inner_text("#info")
    assert "throw 2:" in text and "divergence: |ΔIC|" in text and f"outcomes {info['outcome']} vs {two[1]['outcome']}" in text
    if SHOT:  # once the viewer has drawn the comparison, both dice still
        from dicetrace.sinks.rerun_compare import throw_color

        page.wait_for_function("document.body.dataset.viewerRecording", timeout=120_000)
        page.wait_for_timeout(3000)
        _viewer_dice(page, {"throw 1": throw_color(0), "throw 2": throw_color(1)}, "the README's screenshot")
        page.screenshot(path=SHOT, full_page=True)
    assert not [e for e in errors if "rerun" not in e.lower()], errors


def test_malformed_url_parameter_shows_an_error(browser, explorer):
    page = browser.new_page()
    page.goto(explorer.url.split("?")[0] + "?res=abc")
    _ready_or_error = page.wait_for_function("document.body.dataset.state === 'error'", timeout=60_000)
    assert _ready_or_error
    text = page.inner_text("#error")
    assert "res" in text and "whole numbers" in text


def test_back_and_reset_walk_the_history_of_views(browser, explorer, tmp_path):
    page = browser.new_page(viewport={"width": 1300, "height": 900})
    page.goto(explorer.url)
    wait_ready(page)
    start = _window_of(page)
    first = page_outcomes(page)
    box = page.locator("#mapbox").bounding_box()
    for _ in range(2):  # two wheel zooms (×1/2 each) at the map's centre
        before = page.url
        page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
        page.mouse.wheel(0, -100)
        page.wait_for_function(f"location.href !== {before!r} && document.body.dataset.state !== 'computing'",
                               timeout=120_000)
        wait_ready(page)
    x0, x1, y0, y1 = map(float, _window_of(page).split(","))
    a0, a1, b0, b1 = map(float, start.split(","))
    assert abs((x1 - x0) / (a1 - a0) - 0.25) < 1e-9 and abs((y1 - y0) / (b1 - b0) - 0.25) < 1e-9
    zoomed = _window_of(page)
    np.testing.assert_array_equal(page_outcomes(page), scan_outcomes(tmp_path, zoomed, RES, name="wheel"))
    # back: the URL changes at once, the view is asked for after; while that answer is held
    # back the page must not still say "ready" (a test waiting on it would read the old map)
    held = []
    page.route("**/api/view?*", lambda route: held.append(route))
    page.click("#back")
    for _ in range(600):
        if held:
            break
        page.wait_for_timeout(50)
    assert held, "going back asked for no view"
    assert page.evaluate("document.body.dataset.state") == "computing"
    for route in held:
        route.continue_()
    page.unroute("**/api/view?*")
    wait_ready(page)
    back = _window_of(page)
    x0b, x1b, _, _ = map(float, back.split(","))
    assert abs((x1b - x0b) / (a1 - a0) - 0.5) < 1e-9  # one zoom back
    np.testing.assert_array_equal(page_outcomes(page), scan_outcomes(tmp_path, back, RES, name="back"))
    before = page.url
    page.click("#reset")
    page.wait_for_function(f"location.href !== {before!r} && document.body.dataset.state !== 'computing'",
                           timeout=120_000)
    wait_ready(page)
    assert tuple(map(float, _window_of(page).split(","))) == (a0, a1, b0, b1)
    np.testing.assert_array_equal(page_outcomes(page), first)


def _ticks(page, axis):
    """The tick labels of an axis ("x" or "y"): [(text, centre in page px along the axis)], its step and base."""
    return page.evaluate("""(axis) => {
        const box = document.getElementById(axis + 'axis');
        return {step: Number(box.dataset.step), base: box.dataset.base,
                ticks: Array.from(box.querySelectorAll('.tick')).map((el) => {
                    const r = el.getBoundingClientRect();
                    return [el.textContent, axis === 'x' ? r.left + r.width / 2 : r.top + r.height / 2];
                })};
    }""", axis)


def _check_ticks(page, box):
    """Ticks at round values (1, 2 or 5 × 10^e), labelled with no more decimals than their step needs, placed where
    their value is on the map; on a deep zoom, whole multiples of 10^e from a base given under the map."""
    import math

    x0, x1, y0, y1 = map(float, _window_of(page).split(","))
    for axis, lo, hi in (("x", x0, x1), ("y", y0, y1)):
        t = _ticks(page, axis)
        labels = [text for text, _ in t["ticks"]]
        assert 3 <= len(labels) <= 12, (axis, labels)
        step = t["step"]
        e = math.floor(math.log10(step) + 1e-9)
        assert round(step / 10**e, 9) in (1, 2, 5), (axis, step)
        for text in labels:
            assert len(text) <= 9, f"{axis} tick label {text!r} is too long"
        if t["base"]:
            values = [float(t["base"]) + int(text) * 10**e for text in labels]
            assert [int(text) for text in labels] == [k * round(step / 10**e) for k in range(len(labels))], labels
            assert t["base"] in page.inner_text("#axisnote")
        else:
            needed = max(0, -e)
            for text in labels:
                decimals = len(text.split(".")[1]) if "." in text else 0
                assert decimals <= needed, f"{axis} tick label {text!r} has {decimals} decimals; its step {step} needs {needed}"
            values = [float(text) for text in labels]
            for v in values:
                assert abs(v / step - round(v / step)) < 1e-6, (axis, v, step)
            assert all(abs(b - a - step) <= 1e-9 * max(1.0, abs(b)) for a, b in zip(values, values[1:])), values
        width = hi - lo
        for v, (_, centre) in zip(values, t["ticks"]):
            assert lo - 1e-12 * width <= v <= hi + 1e-12 * width
            f = (v - lo) / width
            want = box["x"] + 1 + f * 512 if axis == "x" else box["y"] + 1 + (1 - f) * 512
            assert abs(centre - want) < 1.5, f"{axis} tick {v} drawn at {centre:.1f} px, its place is {want:.1f}"


def test_zooming_keeps_the_map_in_place_with_round_ticks(browser, explorer):
    """Issue 35 item 8: after zooms the map does not move (a click lands where it was aimed) and the ticks stay short."""
    page = browser.new_page(viewport={"width": 1300, "height": 900})
    page.goto(explorer.url)
    wait_ready(page)
    box = page.locator("#mapbox").bounding_box()
    _check_ticks(page, box)
    for fx, fy in ((0.37, 0.61), (0.23, 0.71), (0.81, 0.13), (0.55, 0.47), (0.31, 0.29)):  # wheel zooms off centre
        before = page.url
        page.mouse.move(box["x"] + box["width"] * fx, box["y"] + box["height"] * fy)
        page.mouse.wheel(0, -100)
        page.wait_for_function(f"location.href !== {before!r} && document.body.dataset.state !== 'computing'",
                               timeout=120_000)
        wait_ready(page)
        assert page.locator("#mapbox").bounding_box() == box, f"the map moved after a zoom to {_window_of(page)}"
        _check_ticks(page, box)
    # a deep zoom (1e-9 wide): the labels would need 10 decimals, so they count from a base given under the map
    page.goto(explorer.url.split("?")[0] + "?window=1.4123456789,1.4123456799,4.1000194552,4.1000194562")
    wait_ready(page)
    assert page.locator("#mapbox").bounding_box() == box
    _check_ticks(page, box)
    assert _ticks(page, "x")["base"] and _ticks(page, "y")["base"]


def test_info_panel_shows_long_lines_whole(browser, explorer):
    """Issue 35 item 10: the IC line and a long contact sequence wrap inside the info panel instead of being clipped."""
    page = browser.new_page(viewport={"width": 1300, "height": 900})
    page.goto(explorer.url)
    wait_ready(page)
    # the throw with the longest contact sequence among a 4×4 sample of the map's grid points
    n = RES
    best = page.evaluate("""async ([n, q]) => {
        let best = null;
        for (const i of [1, 5, 9, 13].filter((k) => k < n - 1)) for (const j of [1, 5, 9, 13].filter((k) => k < n - 1)) {
            const info = await (await fetch('/api/hover?' + q + '&i=' + i + '&j=' + j)).json();
            if (!best || info.contact_sequence.length > best.contact_sequence.length) best = info;
        }
        return best;
    }""", [n, urlparse(page.url).query])
    assert len(best["contact_sequence"]) > 40, best["contact_sequence"]
    box = page.locator("#mapbox").bounding_box()
    at = (box["x"] + box["width"] * best["i"] / (n - 1), box["y"] + box["height"] * (1 - best["j"] / (n - 1)))
    page.mouse.move(*at)
    page.wait_for_function("document.getElementById('hover').textContent.startsWith('hover')", timeout=30_000)
    assert best["contact_sequence"] in page.inner_text("#hover").replace("\n", "")
    page.mouse.click(*at)
    page.wait_for_function("document.getElementById('info').dataset.throws", timeout=60_000)
    picked = page.evaluate("JSON.parse(document.getElementById('info').dataset.throws)[0]")
    assert (picked["i"], picked["j"]) == (best["i"], best["j"])
    # a second throw: the divergence line too
    shift_click(page, box, 0.3, 0.3)
    text = page.inner_text("#info")
    assert best["contact_sequence"] in text.replace("\n", "") and "Lz=" in text and "divergence" in text
    for panel in ("info", "hover"):
        sizes = page.evaluate("""(id) => { const el = document.getElementById(id), r = el.getBoundingClientRect();
            const v = document.getElementById('viewerbox').getBoundingClientRect();
            return {scroll: el.scrollWidth, client: el.clientWidth, box: [r.left, r.right, r.top, r.bottom],
                    viewer: [v.left, v.right, v.top, v.bottom]}; }""", panel)
        assert sizes["scroll"] <= sizes["client"], f"#{panel} clips its lines ({sizes['scroll']} px of text in {sizes['client']} px)"
        # every line of the text lies inside the panel
        inside = page.evaluate("""(id) => { const el = document.getElementById(id), r = el.getBoundingClientRect();
            const range = document.createRange(); range.selectNodeContents(el);
            return Array.from(range.getClientRects()).every((q) => q.right <= r.right + 0.5 && q.left >= r.left - 0.5); }""",
                               panel)
        assert inside, panel
    # the picks' details above the viewer, as wide as it; the hover under the map, left of the viewer
    (il, ir, it, ib), (vl, vr, vt, vb) = sizes["box"], sizes["viewer"]
    info = page.locator("#info").bounding_box()
    assert abs(info["x"] - vl) <= 1 and abs(info["x"] + info["width"] - vr) <= 1 and info["y"] + info["height"] <= vt
    assert ir <= vl


@pytest.mark.parametrize("stored", [None, "(app_options:(show_metrics:false,check_for_updates_on_startup:true))"],
                         ids=["fresh", "viewer-settings-stored"])
@pytest.mark.long
def test_the_page_and_its_viewer_request_nothing_beyond_the_local_server(browser, explorer, stored):
    """Issue 35 item 11: every request of the page, Rerun's web viewer included, goes to 127.0.0.1 (Rerun's viewer
    asks api.github.com for its latest release unless told not to), and the page's connect-src policy blocked none;
    also where a viewer on this origin stored its settings (update check on) before."""
    page = browser.new_page(viewport={"width": 1300, "height": 900})
    urls, missing = [], []
    page.on("request", lambda r: urls.append(r.url))
    page.on("response", lambda r: r.status == 404 and missing.append(r.url))
    page.goto(explorer.url)
    wait_ready(page)
    if stored:
        page.evaluate("(s) => localStorage.setItem('app', s)", stored)
    box = page.locator("#mapbox").bounding_box()
    page.mouse.click(box["x"] + box["width"] * 0.4, box["y"] + box["height"] * 0.6)
    page.wait_for_selector("#viewerbox canvas", timeout=120_000)
    for _ in range(1200):  # the viewer is up when it fetches the throw
        if any("/api/throw.rrd" in u for u in urls):
            break
        page.wait_for_timeout(100)
    assert any("/api/throw.rrd" in u for u in urls), "the viewer did not open the throw"
    page.wait_for_timeout(5000)  # the viewer's start-up requests (its update check came before the throw)
    far = [u for u in urls if urlparse(u).scheme not in ("data", "blob") and urlparse(u).hostname != "127.0.0.1"]
    assert not far, f"requests beyond 127.0.0.1: {far}"
    assert not page.evaluate("document.body.dataset.blocked || ''"), "the page's policy had to block a request"
    assert not missing, f"answered 404: {missing}"  # issue 46 item 13: no /favicon.ico 404 either
    state = page.evaluate("localStorage.getItem('app')")
    assert state.count("check_for_updates_on_startup:false") == 1 and "check_for_updates_on_startup:true" not in state


@pytest.mark.long
def test_shift_click_gives_the_viewer_both_throws_in_one_recording(browser, explorer, tmp_path):
    """Issue 35 item 9: after a shift-click the viewer is given one compare recording holding both throws (each
    die, and their divergence), as `dicetrace record --ic A --ic B` makes it, in place of the first throw's."""
    from dicetrace.sinks.rerun import read_rrd

    page = browser.new_page(viewport={"width": 1300, "height": 900})
    urls = []
    page.on("request", lambda r: urls.append(r.url))
    page.goto(explorer.url)
    wait_ready(page)
    box = page.locator("#mapbox").bounding_box()
    with page.expect_response(lambda r: "/api/throw.rrd" in r.url, timeout=120_000):
        page.mouse.click(box["x"] + box["width"] * 0.4, box["y"] + box["height"] * 0.6)
    # The bytes the viewer is given, as the server sent them: the viewer stops reading once it has decoded the
    # recording's end, which can abort the request before the browser counts it finished (under load it does),
    # so they are taken on their way to the viewer rather than from a finished request.
    given = []

    def pass_on(route):
        r = route.fetch()
        given.append((route.request.url, r.status, r.body()))
        route.fulfill(response=r)

    page.route("**/api/compare.rrd*", pass_on)
    page.keyboard.down("Shift")
    with page.expect_request(lambda r: "/api/compare.rrd" in r.url, timeout=120_000) as asked:
        page.mouse.click(box["x"] + box["width"] * 0.7, box["y"] + box["height"] * 0.3)
    page.keyboard.up("Shift")
    for _ in range(1200):  # the route's handler runs while the page is waited on
        if given:
            break
        page.wait_for_timeout(100)
    url, status, body = given[0]
    assert url == asked.value.url and status == 200
    two = page.evaluate("JSON.parse(document.getElementById('info').dataset.throws)")
    assert len(two) == 2 and two[0]["ic"] != two[1]["ic"]
    assert page.evaluate("document.getElementById('info').dataset.viewer") == url
    # the viewer's recording frames its camera for the viewer's 3-D view (aspect); the download is record's own
    base, aspect = url.split("&aspect=")
    assert 0.2 <= float(aspect) <= 5 and page.get_attribute("#download", "href") == base + "&download=1"
    path = tmp_path / "viewer.rrd"
    path.write_bytes(body)
    temporal, static = read_rrd(path), read_rrd(path, static=True)
    # issue 46 item 7: one numbering, from 1, in the page and its viewer: the page's throw k is the recording's
    for k in (1, 2):
        assert any(e.startswith(f"/throws/{k}/") for e in temporal), sorted(temporal)
        assert static[f"/throws/{k}/body"].column("Boxes3D:labels").to_pylist()[0] == [f"throw {k}"]
    assert "/throws/0/body" not in static
    assert "/divergence/log10/2" in temporal and "/divergence/distance/2" in temporal
    assert static["/divergence/log10/2"].column("SeriesLines:names").to_pylist()[0] == ["log10 distance, throw 2 vs 1"]
    summary = str(static["/summary"].to_pydict())
    text = page.inner_text("#info")
    for k, info in enumerate(two, start=1):
        where = f"x = {info['coords']['x']!r}, y = {info['coords']['y']!r}"
        assert f"| {k} | seed slice at {where}" in summary and f"throw {k}: {where}" in text
        assert info["contact_sequence"] in summary
    assert "throw 0" not in summary and "throw 0" not in text
    # only the viewer asked for it (once); the single throw's recording was not asked for again
    assert sum("/api/compare.rrd" in u for u in urls) == 1 and sum("/api/throw.rrd" in u for u in urls) == 1
    # the viewer shows the comparison: its events name that recording as the one on screen, and still do later
    from rerun.chunk import RrdReader

    rid = RrdReader(str(path)).recordings()[0].recording_id
    page.wait_for_function(f"document.body.dataset.viewerRecording === {rid!r}", timeout=120_000)
    page.wait_for_timeout(6000)  # the viewer draws the comparison
    assert page.evaluate("document.body.dataset.viewerRecording") == rid
    from PIL import Image
    import io

    img = np.asarray(Image.open(io.BytesIO(page.locator("#viewerbox").screenshot())).convert("RGB")).astype(float)
    assert img.std() > 10, "the embedded Rerun viewer is blank"
    # the compare blueprint's 3-D view (background 250,250,250, above the ground it frames) is the viewer's layout
    share = (img[:, : img.shape[1] // 2] == 250).all(axis=-1).mean()
    assert share > 0.1, f"the compare blueprint is not the viewer's layout ({share:.3f} of the left half is its 3-D view)"


@pytest.mark.long  # the CI tier keeps one full-page browser test (test_page_map_zoom_and_throw)
def test_the_viewer_takes_the_room_beside_the_map(browser, explorer):
    """Issue 35 item 12, the page's part: Rerun's viewer takes the page's width beside the map, 8:7 (the framing
    camera's room across) as tall as the page allows, and follows the window when it is resized, so the die is
    drawn as large as the page allows."""
    page = browser.new_page(viewport={"width": 1600, "height": 1000})
    page.goto(explorer.url)
    wait_ready(page)
    box = page.locator("#mapbox").bounding_box()
    page.mouse.click(box["x"] + box["width"] * 0.4, box["y"] + box["height"] * 0.6)
    page.wait_for_selector("#viewerbox canvas", timeout=120_000)

    def sizes():
        return page.evaluate("""() => { const b = document.getElementById('viewerbox'), c = b.querySelector('canvas');
            const r = c.getBoundingClientRect(), q = b.getBoundingClientRect();
            return {box: [q.left, q.right, q.top, q.bottom], canvas: [r.left, r.right, r.top, r.bottom],
                    inner: [b.clientWidth, b.clientHeight], page: [innerWidth, innerHeight]}; }""")

    for width, height in ((1600, 1000), (1400, 900)):
        page.set_viewport_size({"width": width, "height": height})
        page.wait_for_timeout(500)
        s = sizes()
        left, right, top, bottom = s["box"]
        assert right >= width - 20, s  # to the page's right edge
        w, h = s["inner"]
        # 8:7, within the window below its top (under the picked throw's details)
        assert abs((bottom - top) - max(420, min((right - left) * 7 / 8, height - 8 - top))) <= 3, s
        assert bottom <= height, s
        assert left <= box["x"] + box["width"] + 90, s  # beside the map
        cl, cr, ct, cb = s["canvas"]
        assert abs((cr - cl) - s["inner"][0]) <= 2 and abs((cb - ct) - s["inner"][1]) <= 2, s  # the canvas fills it


# -- issue 46 items 6, 8, 9 ---------------------------------------------------------------------------------------------


@pytest.mark.long  # 11 s; the CI tier keeps one browser test of the page (test_page_map_zoom_and_throw)
def test_the_download_link_waits_for_a_pick_and_the_empty_viewer_says_what_to_do(browser, explorer):
    """Issue 46 item 8: "download this throw (.rrd)" was live before any pick and downloaded the page itself as
    download.html.  Before a pick it is hidden and the viewer's box says to click a point on the map; after a pick
    it downloads that throw's recording, as record writes it."""
    page = browser.new_page(viewport={"width": 1300, "height": 900})
    page.goto(explorer.url)
    wait_ready(page)
    assert not page.is_visible("#download")
    assert "click a point on the map" in page.inner_text("#viewerbox")
    assert page.inner_text("#info") == "" and not page.is_visible("#info")  # no details before a pick
    box = page.locator("#mapbox").bounding_box()
    page.mouse.click(box["x"] + box["width"] * 0.4, box["y"] + box["height"] * 0.6)
    page.wait_for_function("document.getElementById('info').dataset.throws", timeout=60_000)
    assert page.is_visible("#download") and page.inner_text("#download") == "download this throw (.rrd)"
    info = page.evaluate("JSON.parse(document.getElementById('info').dataset.throws)[0]")
    with page.expect_download(timeout=120_000) as dl:
        page.click("#download")
    name = dl.value.suggested_filename
    assert name.endswith(".rrd") and name.startswith("seed_x"), name
    from dicetrace.sinks.rerun import read_rrd_metadata

    meta = read_rrd_metadata(dl.value.path())
    assert (meta["outcome"], meta["steps"], meta["contact_sequence"]) == (info["outcome"], info["steps"],
                                                                        info["contact_sequence"])
    page.wait_for_selector("#viewerbox canvas", timeout=120_000)
    assert "click a point" not in page.inner_text("#viewerbox")  # the viewer took the box


@pytest.mark.long
def test_at_1280_by_720_the_picks_details_show_without_scrolling(browser, explorer):
    """Issue 46 item 9: at 1280×720 the info panel started at y = 636, the throw's details below the fold.  The
    picked throw's details are beside the map, above the viewer: every line of them inside the window, unscrolled,
    with the mouse still hovering the map (the hover has its own panel)."""
    page = browser.new_page(viewport={"width": 1280, "height": 720})
    page.goto(explorer.url)
    wait_ready(page)
    box = page.locator("#mapbox").bounding_box()
    at = (box["x"] + box["width"] * 0.4, box["y"] + box["height"] * 0.6)
    page.mouse.move(*at)
    page.wait_for_function("document.getElementById('hover').textContent.startsWith('hover')", timeout=30_000)
    page.mouse.click(*at)
    page.wait_for_function("document.getElementById('info').dataset.throws", timeout=60_000)
    page.mouse.move(at[0] + 20, at[1] + 20)  # still over the map: hovers go on
    page.wait_for_timeout(1000)
    info = page.evaluate("JSON.parse(document.getElementById('info').dataset.throws)[0]")
    text = page.inner_text("#info")
    assert text.startswith("throw 1: ") and info["contact_sequence"] in text.replace("\n", "")
    assert f"outcome {info['outcome']}" in text and "IC: vx=" in text
    seen = page.evaluate("""() => { const el = document.getElementById('info'), r = el.getBoundingClientRect();
        const range = document.createRange(); range.selectNodeContents(el);
        const lines = Array.from(range.getClientRects());
        return {scrollY: scrollY, top: r.top, bottom: r.bottom, scrolled: el.scrollTop, overflow: el.scrollHeight - el.clientHeight,
                lines: lines.length, last: Math.max(...lines.map((q) => q.bottom)), first: Math.min(...lines.map((q) => q.top))}; }""")
    assert seen["scrollY"] == 0 and seen["scrolled"] == 0 and seen["overflow"] <= 0, seen
    assert seen["lines"] >= 4 and 0 <= seen["first"] and seen["last"] <= 720 and seen["bottom"] <= 720, seen


#: Two grid points of the tests' 16×16 window whose dice rest 14 cm apart (about six sides): a wide frame.
APART = ((1, 1), (10, 1))


def _click_pixel(page, i: int, j: int, shift: bool = False) -> None:
    page.locator("#mapbox").scroll_into_view_if_needed()  # a screenshot of the viewer below it scrolled the page
    box = page.locator("#mapbox").bounding_box()
    x, y = box["x"] + box["width"] * i / (RES - 1), box["y"] + box["height"] * (1 - j / (RES - 1))
    if shift:
        page.keyboard.down("Shift")
    page.mouse.click(x, y)
    if shift:
        page.keyboard.up("Shift")


def _viewer_dice(page, colours: dict, what: str, timeout_s: int = 180):
    """The viewer box's screenshot once every die of ``colours`` is drawn and the picture holds still (the
    recording loads progressively, its time following the end); then each die is checked inside the 3-D view.
    Returns (image, what :func:`viewer_shot.assert_dice_inside` found)."""
    import io

    from PIL import Image
    from viewer_shot import assert_dice_inside, dice_in_view

    last = None
    for _ in range(timeout_s):
        img = np.asarray(Image.open(io.BytesIO(page.locator("#viewerbox").screenshot())).convert("RGB")).astype(int)
        right = int(0.59 * img.shape[1])  # the 3-D view: the layout's left 3/5
        boxes = [b for _, b, _ in dice_in_view(img, colours, right).values()]
        if all(b is not None for b in boxes) and boxes == last:
            return img, assert_dice_inside(img, colours, right, what)
        last = boxes
        page.wait_for_timeout(1000)
    raise AssertionError(f"{what}: the dice never showed still in the viewer: {dice_in_view(img, colours, right)}")


@pytest.mark.parametrize("viewport", [(1920, 1080), (1100, 900), (760, 1200)], ids=["wide", "narrow", "portrait"])
@pytest.mark.long
def test_every_resting_die_is_inside_the_viewers_3d_view_at_any_window_shape(browser, explorer, viewport):
    """Issue 46 item 6: the die was cut at the right edge of the explorer's 3-D view (one throw, and the second die
    of a comparison half outside at 1400×900 and 1920×1080): the camera framed a square, and the 3-D view is
    narrower than it is tall.  The page gives the viewer's recording the aspect of its 3-D view, and the camera
    frames for it.  On screenshots at a wide, a narrow and a portrait window (the viewer below the map there),
    both dice of a comparison resting far apart (their rims) are whole inside the 3-D view, with room to its
    edges; in the narrow one, one throw's die (its face plates) first."""
    from viewer_shot import view3d_rect

    from dicetrace.sinks.rerun import FACE_COLORS
    from dicetrace.sinks.rerun_compare import throw_color

    w, h = viewport
    page = browser.new_page(viewport={"width": w, "height": h})
    page.goto(explorer.url)
    wait_ready(page)
    _click_pixel(page, *APART[0])
    page.wait_for_function("document.getElementById('info').dataset.throws", timeout=60_000)
    one = page.evaluate("JSON.parse(document.getElementById('info').dataset.throws)")
    assert [(t["i"], t["j"]) for t in one] == [APART[0]]
    if w < h:  # the viewer below the map
        assert page.locator("#viewerbox").bounding_box()["y"] > page.locator("#mapbox").bounding_box()["y"] + 512
    first = None
    if viewport == (1100, 900):
        page.wait_for_selector("#viewerbox canvas", timeout=120_000)
        _viewer_dice(page, {"the die": FACE_COLORS.tolist()}, f"one throw at {w}×{h}")
        first = page.evaluate("document.body.dataset.viewerRecording")
    _click_pixel(page, *APART[1], shift=True)
    page.wait_for_function("JSON.parse(document.getElementById('info').dataset.throws).length === 2", timeout=60_000)
    page.wait_for_function(f"document.body.dataset.viewerRecording && document.body.dataset.viewerRecording !== {json.dumps(first)}"
                           " && document.getElementById('info').dataset.viewer.includes('compare.rrd')", timeout=120_000)
    img, _ = _viewer_dice(page, {"throw 1": throw_color(0), "throw 2": throw_color(1)}, f"two throws at {w}×{h}")
    # the aspect the page asked the camera to frame for is its 3-D view's, as drawn
    top, bottom, left, right = view3d_rect(img, int(0.59 * img.shape[1]))
    asked = float(page.evaluate("document.getElementById('info').dataset.viewer").split("&aspect=")[1])
    assert (right - left + 1) / (bottom - top + 1) == pytest.approx(asked, rel=0.08)
