"""``Explorer(...)`` in a real Jupyter kernel (ipykernel through jupyter_client): the cell's output is the explorer.

The kernel runs the cell ``Explorer(...)`` as a notebook does; its rich output
(``text/html``) is then shown in headless chromium, as a notebook frontend
shows it, and the explorer inside has to draw the map that ``dicetrace scan``
computes.  ``ex.stop()`` in the kernel frees the port.
"""

from __future__ import annotations

import html
import re
import socket
import urllib.request

import numpy as np
import pytest

from explore_helpers import RES, WINDOW, page_outcomes, png_outcomes, scan_outcomes, wait_ready

pytestmark = pytest.mark.slow

#: Longest wait for one cell, s (the first map may load numba's cache).
CELL_TIMEOUT_S = 180


def run_cell(kc, code: str) -> list[dict]:
    """Execute ``code`` in the kernel; its outputs (execute_result, display_data, stream, error messages' content)."""
    msg_id = kc.execute(code)
    outputs = []
    while True:
        msg = kc.get_iopub_msg(timeout=CELL_TIMEOUT_S)
        if msg["parent_header"].get("msg_id") != msg_id:
            continue
        kind = msg["msg_type"]
        if kind == "status" and msg["content"]["execution_state"] == "idle":
            return outputs
        if kind in ("execute_result", "display_data", "stream", "error"):
            outputs.append({"type": kind, **msg["content"]})


@pytest.fixture
def kernel(tmp_path):
    manager = pytest.importorskip("jupyter_client.manager", reason="jupyter_client is not installed")
    pytest.importorskip("ipykernel", reason="ipykernel is not installed")
    km, kc = manager.start_new_kernel(kernel_name="python3", cwd=str(tmp_path), startup_timeout=120)
    try:
        yield kc
    finally:
        kc.stop_channels()
        km.shutdown_kernel(now=True)


@pytest.mark.long  # 10 s with its kernel; the CI tier keeps the widget's round trip with the page
def test_explorer_is_the_cells_output_in_a_kernel_and_works_in_a_browser(kernel, browser, tmp_path):
    out = run_cell(kernel, f"from dicetrace.explore import Explorer\nex = Explorer(window={WINDOW!r}, res={RES})\nex")
    assert not [o for o in out if o["type"] == "error"], out
    (result,) = [o for o in out if o["type"] == "execute_result"]
    shown = result["data"]["text/html"]
    assert shown.startswith("<iframe") and 'title="dicetrace explore"' in shown
    url = html.unescape(re.search(r'src="([^"]+)"', shown).group(1))
    assert url.startswith("http://127.0.0.1:")
    port = int(url.split(":")[2].split("/")[0])

    # the kernel serves the explorer: its map is the scan's
    base = f"http://127.0.0.1:{port}"
    with urllib.request.urlopen(f"{base}/api/map.png?window={WINDOW}&res={RES}", timeout=CELL_TIMEOUT_S) as r:
        expected = scan_outcomes(tmp_path, WINDOW, RES)
        np.testing.assert_array_equal(png_outcomes(r.read()), expected)

    # the cell's output, shown by a browser as a notebook shows it: the explorer in its frame draws that map
    page = browser.new_page(viewport={"width": 1400, "height": 1000})
    page.set_content(f"<html><body><h3>notebook cell output</h3>{shown}</body></html>")
    frame = page.wait_for_selector("iframe", timeout=60_000).content_frame()
    frame.wait_for_load_state()
    wait_ready(frame)
    np.testing.assert_array_equal(page_outcomes(frame), expected)

    # the widget form displays as a Jupyter widget of the same page
    out = run_cell(kernel, "w = ex.widget()\nprint(w.url == ex.url)\nw")
    assert [o.get("text", "").strip() for o in out if o["type"] == "stream"] == ["True"]
    (result,) = [o for o in out if o["type"] == "execute_result"]
    assert "application/vnd.jupyter.widget-view+json" in result["data"], result["data"].keys()

    out = run_cell(kernel, "ex.stop()\nprint(ex.running)")
    assert [o.get("text", "").strip() for o in out if o["type"] == "stream"] == ["False"]
    with socket.socket() as s:
        s.settimeout(1)
        assert s.connect_ex(("127.0.0.1", port)) != 0, "the port is still open after ex.stop()"


def test_widget_sends_the_pages_picks_and_view_back(browser, tmp_path):
    """The widget's front end (its ESM, under a stand-in for Jupyter's widget model) passes the page's
    view and picked throws to the synced traits; set on the Python widget as Jupyter would, they call on_pick."""
    import json as _json

    from dicetrace.explore import Explorer
    from dicetrace.explore.widget import ESM

    with Explorer(window=WINDOW, res=RES) as ex:
        picked = []
        w = ex.widget(on_pick=picked.append)
        assert w.url == ex.url and w.height == ex.height
        page = browser.new_page(viewport={"width": 1400, "height": 1000})
        page.set_content("<html><body><div id='cell'></div></body></html>")
        page.evaluate("""async ([esm, url, height]) => {
            const mod = await import(URL.createObjectURL(new Blob([esm], {type: "text/javascript"})));
            const state = {url, height, throws: [], view: {}};
            window.synced = [];
            const model = {get: (k) => state[k], set: (k, v) => { state[k] = v; },
                           save_changes: () => window.synced.push(JSON.parse(JSON.stringify(state)))};
            mod.default.render({model, el: document.getElementById("cell")});
        }""", [ESM, w.url, w.height])
        frame = page.wait_for_selector("iframe", timeout=60_000).content_frame()
        wait_ready(frame)
        assert page.evaluate("window.synced.at(-1).view") == ex.view.to_query()

        box = frame.locator("#mapbox").bounding_box()
        page.mouse.click(box["x"] + box["width"] * 0.35, box["y"] + box["height"] * 0.65)
        page.wait_for_function("window.synced.some((s) => s.throws.length === 1)", timeout=60_000)
        throws = page.evaluate("window.synced.at(-1).throws")
        info = throws[0]
        with urllib.request.urlopen(f"http://127.0.0.1:{ex.port}/api/hover?window={WINDOW}&res={RES}"
                                    f"&i={info['i']}&j={info['j']}", timeout=CELL_TIMEOUT_S) as r:
            assert info == _json.loads(r.read())  # the throw at that pixel, as hover tells it
        assert (info["i"], info["j"]) == (round(0.35 * (RES - 1)), round(0.35 * (RES - 1)))  # y up

        w.set_state({"throws": throws})  # what ipywidgets does with the front end's update
        assert picked == [info]
